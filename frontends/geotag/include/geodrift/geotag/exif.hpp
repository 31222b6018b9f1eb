#pragma once

/// @file
/// The geo-tag and focal length stored in a JPEG's EXIF block, read without any image library.
///
/// A JPEG carries EXIF in an APP1 segment (marker FF E1) whose payload starts with "Exif\0\0"
/// followed by a TIFF structure (EXIF 2.3 / CIPA DC-008, TIFF 6.0): a header giving the byte
/// order ("II" little-endian or "MM" big-endian), the magic 42 and the offset of IFD0. Every IFD
/// is a 16-bit entry count, then 12-byte entries (tag, type, count, value or offset; values of
/// at most 4 bytes are stored inline). Offsets count from the TIFF header. Read here:
///   IFD0      0x0112 Orientation, 0x8825 GPS IFD pointer, 0x8769 Exif IFD pointer
///   GPS IFD   0x0001/0x0002 GPSLatitudeRef/GPSLatitude, 0x0003/0x0004 GPSLongitudeRef/
///             GPSLongitude (3 rationals: degrees, minutes, seconds), 0x0005/0x0006
///             GPSAltitudeRef/GPSAltitude, 0x0010/0x0011 GPSImgDirectionRef/GPSImgDirection
///   Exif IFD  0x920A FocalLength, 0xA405 FocalLengthIn35mmFilm, 0xA002/0xA003
///             PixelXDimension/PixelYDimension
///
/// Robustness: only the first Exif APP1 segment before the image data (SOS) is read (at most
/// 64 KiB, the APP1 limit). IFD0, the GPS IFD and the Exif IFD are each visited once (no IFD
/// chains are followed, so a corrupt offset cannot make the reader loop); every entry and every
/// value is bounds-checked against the block, so a truncated or corrupt block never reads out
/// of bounds: whatever cannot be read (out of range, wrong type, zero denominator, missing or
/// invalid reference letter) is NaN.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>

namespace geodrift::geotag {

/// What read_exif() found. Every missing or unreadable field is NaN (orientation: 0).
struct ExifGeotag {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

  bool has_exif = false;  ///< an Exif APP1 block with a valid TIFF header was found
  /// WGS84 degrees, north positive (GPSLatitudeRef 'S' negates). NaN without a valid 'N'/'S'
  /// reference (the EXIF spec gives it no default), out of [-90, 90] or unreadable.
  double latitude_deg = kNaN;
  /// WGS84 degrees, east positive (GPSLongitudeRef 'W' negates); as latitude_deg otherwise.
  double longitude_deg = kNaN;
  /// GPSAltitude in metres as the receiver gives it (above sea level, NOT ellipsoidal);
  /// negative when GPSAltitudeRef is 1 (below sea level). An absent GPSAltitudeRef is 0, the
  /// EXIF default; any other reference value makes it NaN.
  double altitude_m = kNaN;
  /// GPSImgDirection in [0, 360) deg clockwise from TRUE north: set when GPSImgDirectionRef is
  /// 'T' or absent ('T' is the EXIF default). NaN for a magnetic direction.
  double true_heading_deg = kNaN;
  /// GPSImgDirection in [0, 360) deg clockwise from MAGNETIC north (GPSImgDirectionRef 'M').
  /// Reported apart and never turned into a true heading: the declination is not known here.
  double magnetic_heading_deg = kNaN;
  double focal_length_mm = kNaN;    ///< FocalLength (0x920A), millimetres of the real lens
  double focal_length_35mm = kNaN;  ///< FocalLengthIn35mmFilm (0xA405) in mm; 0 (unknown) = NaN
  double pixel_width = kNaN;        ///< PixelXDimension (0xA002)
  double pixel_height = kNaN;       ///< PixelYDimension (0xA003)
  /// TIFF Orientation 1..8 (0: absent or invalid). 5..8 mean the stored pixels are transposed
  /// (width and height swap when the image is shown upright; OpenCV's imread does so only when
  /// this block is the file's first APP1 segment).
  int orientation = 0;

  /// Latitude and longitude are both known.
  bool has_gps_position() const {
    return std::isfinite(latitude_deg) && std::isfinite(longitude_deg);
  }
};

/// Reads the EXIF geo-tag of a JPEG file (file comment). A readable file that is not a JPEG or
/// has no Exif APP1 block gives has_exif = false and all NaN.
/// @throws Error naming the file when it does not exist or cannot be read.
ExifGeotag read_exif(const std::string& jpeg_path);

/// Parses an APP1 payload (the bytes after the segment length: "Exif\0\0" + TIFF block) of
/// `size` bytes. Never reads outside [data, data + size).
ExifGeotag parse_exif_app1(const std::uint8_t* data, std::size_t size);

/// 35 mm-equivalent focal length -> focal length in pixels: f35 is defined on the 43.27 mm
/// diagonal of a 36 x 24 mm frame, so f_px = f35 * (image diagonal in px) / 43.27.
double focal_px_from_35mm(double focal_length_35mm, int width, int height);

}  // namespace geodrift::geotag
