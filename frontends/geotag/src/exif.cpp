// EXIF geo-tag reader written from the EXIF 2.3 (CIPA DC-008) and TIFF 6.0 layouts; see
// exif.hpp for the tags read and the robustness rules.
#include "geodrift/geotag/exif.hpp"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::geotag {

namespace {

constexpr double kNaN = ExifGeotag::kNaN;

/// TIFF field types and their element sizes (0: unknown type).
std::size_t type_size(std::uint16_t type) {
  switch (type) {
    case 1:  // BYTE
    case 2:  // ASCII
    case 6:  // SBYTE
    case 7:  // UNDEFINED
      return 1;
    case 3:  // SHORT
    case 8:  // SSHORT
      return 2;
    case 4:   // LONG
    case 9:   // SLONG
    case 11:  // FLOAT
    case 13:  // IFD (an offset, TIFF technote 1)
      return 4;
    case 5:   // RATIONAL
    case 10:  // SRATIONAL
    case 12:  // DOUBLE
      return 8;
    default:
      return 0;
  }
}

/// A bounds-checked view of the TIFF block.
class Tiff {
 public:
  Tiff(const std::uint8_t* data, std::size_t size) : d_(data), n_(size) {}

  /// Reads the header; false if it is not a TIFF header.
  bool header(std::uint32_t* ifd0) {
    if (n_ < 8) return false;
    if (d_[0] == 'I' && d_[1] == 'I')
      little_ = true;
    else if (d_[0] == 'M' && d_[1] == 'M')
      little_ = false;
    else
      return false;
    if (u16(2) != 42) return false;
    *ifd0 = u32(4);
    return true;
  }

  std::uint16_t u16(std::size_t o) const {
    return little_ ? std::uint16_t(d_[o] | (d_[o + 1] << 8))
                   : std::uint16_t((d_[o] << 8) | d_[o + 1]);
  }
  std::uint32_t u32(std::size_t o) const {
    const std::uint32_t a = d_[o], b = d_[o + 1], c = d_[o + 2], e = d_[o + 3];
    return little_ ? (a | (b << 8) | (c << 16) | (e << 24))
                   : ((a << 24) | (b << 16) | (c << 8) | e);
  }

  /// One IFD entry, its value located and checked to lie inside the block.
  struct Entry {
    std::uint16_t type = 0;
    std::uint32_t count = 0;
    std::size_t value = 0;  ///< offset of the first value byte in the block
    bool valid = false;
  };

  /// Looks `tag` up in the IFD at `ifd`; an invalid Entry if the IFD, the entry or its value
  /// is not inside the block.
  Entry find(std::uint32_t ifd, std::uint16_t tag) const {
    Entry e;
    if (ifd == 0 || std::uint64_t(ifd) + 2 > n_) return e;
    const std::uint64_t listed = u16(ifd);
    const std::uint64_t fit = (n_ - ifd - 2) / 12;  // entries that lie inside the block
    const std::uint64_t count = listed < fit ? listed : fit;
    for (std::uint64_t i = 0; i < count; ++i) {
      const std::size_t at = static_cast<std::size_t>(ifd + 2 + 12 * i);
      if (u16(at) != tag) continue;
      e.type = u16(at + 2);
      e.count = u32(at + 4);
      const std::uint64_t bytes = std::uint64_t(type_size(e.type)) * e.count;
      if (bytes == 0) return e;
      const std::uint64_t off = bytes <= 4 ? at + 8 : u32(at + 8);
      if (off + bytes > n_) return e;
      e.value = static_cast<std::size_t>(off);
      e.valid = true;
      return e;
    }
    return e;
  }

  /// Element i of a numeric entry as a double (NaN if not numeric, out of range or a zero
  /// denominator).
  double number(const Entry& e, std::uint32_t i) const {
    if (!e.valid || i >= e.count) return kNaN;
    const std::size_t o = e.value + i * type_size(e.type);
    switch (e.type) {
      case 1:
      case 7:
        return d_[o];
      case 6:
        return static_cast<std::int8_t>(d_[o]);
      case 3:
        return u16(o);
      case 8:
        return static_cast<std::int16_t>(u16(o));
      case 4:
      case 13:
        return u32(o);
      case 9:
        return static_cast<std::int32_t>(u32(o));
      case 5: {
        const std::uint32_t den = u32(o + 4);
        return den == 0 ? kNaN : double(u32(o)) / double(den);
      }
      case 10: {
        const auto den = static_cast<std::int32_t>(u32(o + 4));
        return den == 0 ? kNaN : double(static_cast<std::int32_t>(u32(o))) / double(den);
      }
      case 11: {
        const std::uint32_t bits = u32(o);
        float f;
        std::memcpy(&f, &bits, sizeof f);
        return f;
      }
      case 12: {
        const std::uint64_t hi = u32(little_ ? o + 4 : o), lo = u32(little_ ? o : o + 4);
        const std::uint64_t bits = (hi << 32) | lo;
        double v;
        std::memcpy(&v, &bits, sizeof v);
        return v;
      }
      default:
        return kNaN;
    }
  }

  /// First character of an ASCII (or BYTE/UNDEFINED) entry; 0 if none.
  char letter(const Entry& e) const {
    if (!e.valid || e.count < 1 || type_size(e.type) != 1) return 0;
    return static_cast<char>(d_[e.value]);
  }

  /// An IFD pointer (LONG, SHORT, or the IFD type 13 some writers use); 0 if none.
  std::uint32_t pointer(std::uint32_t ifd, std::uint16_t tag) const {
    const Entry e = find(ifd, tag);
    const double v = number(e, 0);
    return (e.type == 3 || e.type == 4 || e.type == 13) && std::isfinite(v)
               ? static_cast<std::uint32_t>(v)
               : 0;
  }

 private:
  const std::uint8_t* d_;
  std::size_t n_;
  bool little_ = true;
};

/// Degrees + minutes / 60 + seconds / 3600 of a GPS coordinate entry; NaN unless the three
/// (or, from lax writers, one or two) values are finite and non-negative.
double dms(const Tiff& t, const Tiff::Entry& e) {
  if (!e.valid || e.count < 1) return kNaN;
  double v = 0.0, scale = 1.0;
  for (std::uint32_t i = 0; i < 3 && i < e.count; ++i, scale *= 60.0) {
    const double x = t.number(e, i);
    if (!std::isfinite(x) || x < 0) return kNaN;
    v += x / scale;
  }
  return v;
}

double wrap_deg(double d) {
  if (!std::isfinite(d)) return kNaN;
  if (d >= 0.0 && d < 360.0) return d;
  const double w = std::fmod(std::fmod(d, 360.0) + 360.0, 360.0);
  return w >= 360.0 ? 0.0 : w;
}

}  // namespace

ExifGeotag parse_exif_app1(const std::uint8_t* data, std::size_t size) {
  ExifGeotag g;
  static const std::uint8_t kExif[6] = {'E', 'x', 'i', 'f', 0, 0};
  if (data == nullptr || size < 6 || std::memcmp(data, kExif, 6) != 0) return g;
  Tiff t(data + 6, size - 6);
  std::uint32_t ifd0 = 0;
  if (!t.header(&ifd0)) return g;
  g.has_exif = true;

  const double orient = t.number(t.find(ifd0, 0x0112), 0);
  if (orient >= 1 && orient <= 8) g.orientation = static_cast<int>(orient);

  if (const std::uint32_t gps = t.pointer(ifd0, 0x8825)) {
    const char lat_ref = t.letter(t.find(gps, 0x0001));
    const double lat = dms(t, t.find(gps, 0x0002));
    if ((lat_ref == 'N' || lat_ref == 'S') && lat <= 90.0)
      g.latitude_deg = lat_ref == 'S' ? -lat : lat;
    const char lon_ref = t.letter(t.find(gps, 0x0003));
    const double lon = dms(t, t.find(gps, 0x0004));
    if ((lon_ref == 'E' || lon_ref == 'W') && lon <= 180.0)
      g.longitude_deg = lon_ref == 'W' ? -lon : lon;

    const Tiff::Entry alt_ref_e = t.find(gps, 0x0005);
    const double alt_ref = alt_ref_e.valid ? t.number(alt_ref_e, 0) : 0.0;  // EXIF default 0
    const double alt = t.number(t.find(gps, 0x0006), 0);
    if (std::isfinite(alt) && alt >= 0 && (alt_ref == 0.0 || alt_ref == 1.0))
      g.altitude_m = alt_ref == 1.0 ? -alt : alt;

    const Tiff::Entry dir_ref_e = t.find(gps, 0x0010);
    const char dir_ref = dir_ref_e.valid ? t.letter(dir_ref_e) : 'T';  // EXIF default 'T'
    const double dir = wrap_deg(t.number(t.find(gps, 0x0011), 0));
    if (dir_ref == 'T')
      g.true_heading_deg = dir;
    else if (dir_ref == 'M')
      g.magnetic_heading_deg = dir;
  }

  if (const std::uint32_t exif = t.pointer(ifd0, 0x8769)) {
    const double f = t.number(t.find(exif, 0x920A), 0);
    if (f > 0 && std::isfinite(f)) g.focal_length_mm = f;
    const double f35 = t.number(t.find(exif, 0xA405), 0);
    if (f35 > 0 && std::isfinite(f35)) g.focal_length_35mm = f35;
    const double w = t.number(t.find(exif, 0xA002), 0);
    const double h = t.number(t.find(exif, 0xA003), 0);
    if (w > 0 && std::isfinite(w)) g.pixel_width = w;
    if (h > 0 && std::isfinite(h)) g.pixel_height = h;
  }
  return g;
}

ExifGeotag read_exif(const std::string& jpeg_path) {
  std::error_code ec;
  if (std::filesystem::is_directory(jpeg_path, ec))
    throw Error("cannot read EXIF of '" + jpeg_path + "': it is a directory");
  std::ifstream in(jpeg_path, std::ios::binary);
  if (!in) throw Error("cannot open image '" + jpeg_path + "' to read its EXIF");
  const auto get = [&](std::uint8_t* b, std::size_t n) {
    in.read(reinterpret_cast<char*>(b), static_cast<std::streamsize>(n));
    return static_cast<std::size_t>(in.gcount());
  };
  std::uint8_t b[4];
  if (get(b, 2) != 2 || b[0] != 0xFF || b[1] != 0xD8) {
    if (in.bad()) throw Error("cannot read image '" + jpeg_path + "'");
    return {};  // not a JPEG: no EXIF
  }
  // Segments up to the scan: FF <marker> <16-bit length incl. itself> <payload>. Each step
  // consumes at least 2 bytes and stops at the end of the file, so this terminates; the guard
  // bounds pathological files made of fill bytes.
  for (int guard = 0; guard < 4096; ++guard) {
    if (get(b, 1) != 1) break;
    if (b[0] != 0xFF) break;  // not a marker: corrupt
    std::uint8_t marker = 0xFF;
    while (marker == 0xFF)  // fill bytes
      if (get(&marker, 1) != 1) return {};
    if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;
    if (marker == 0xDA || marker == 0xD9) break;  // start of scan / end of image
    if (get(b, 2) != 2) break;
    const std::size_t len = (std::size_t(b[0]) << 8) | b[1];
    if (len < 2) break;
    if (marker == 0xE1 && len >= 2 + 6) {
      std::vector<std::uint8_t> payload(len - 2);
      const std::size_t got = get(payload.data(), payload.size());  // short if truncated
      const ExifGeotag g = parse_exif_app1(payload.data(), got);
      if (g.has_exif) return g;
      if (got < payload.size()) break;
      continue;  // another APP1 (e.g. XMP): keep looking
    }
    in.seekg(static_cast<std::streamoff>(len - 2), std::ios::cur);
    if (!in) break;
  }
  if (in.bad()) throw Error("cannot read image '" + jpeg_path + "'");
  return {};
}

double focal_px_from_35mm(double focal_length_35mm, int width, int height) {
  if (!(focal_length_35mm > 0) || !std::isfinite(focal_length_35mm) || width <= 0 || height <= 0)
    return kNaN;
  const double diag_35mm = std::hypot(36.0, 24.0);  // 43.27 mm
  return focal_length_35mm * std::hypot(double(width), double(height)) / diag_35mm;
}

}  // namespace geodrift::geotag
