#pragma once

/// @file
/// Geo-tagged sources (panoramas and plain photos) and the views the database is made of.
///
/// A SOURCE is one geo-tagged image file: an equirectangular panorama (cut into
/// kViewsPerPanorama views, view k looking along heading + k * 45 deg) or a plain photo (one
/// view, its own intrinsics). A VIEW carries its source's geo-tag (position) and its own optical
/// axis heading; its pose in W is that of a level camera at the geo-tag position
/// (view_pose_world()).
///
/// Geo-tag CSV (read_geotag_csv()): a header row, then one row per source. Columns, by name, in
/// any order (aliases in brackets):
///   file [image]                      image path, relative to the CSV's folder or absolute;
///                                     also looked up in <folder>/panoramas/ and <folder>/images/
///   latitude [latitude_deg], longitude [longitude_deg]   WGS84 degrees
///   height [altitude_m]               metres; `height` is ellipsoidal (DESIGN.md); altitude_m
///                                     (a phone's GPS altitude) is taken as given
///   heading_deg [true_heading_deg]    true heading of the panorama's centre column or of the
///                                     photo's optical axis, degrees clockwise from north
///   An EMPTY latitude, longitude, height or heading_deg cell is read from the image's EXIF
///   (read_exif(): GPSLatitude, GPSLongitude, GPSAltitude taken as given like altitude_m, and a
///   TRUE GPSImgDirection; a magnetic one is not used). A needed value the EXIF lacks is an
///   error, except the heading of a photo: it then stays unknown (NaN; retrieval, matching and
///   localization do not use it, view_pose_world() refuses it). A panorama needs a heading.
///   id (optional)                     geo-tag id (default: row number from 0)
///   kind (optional)                   "panorama" or "photo"; when absent, a 2:1 image is a
///                                     panorama, anything else a photo
///   fx, fy, cx, cy (optional)         photo intrinsics in pixels of the image as OpenCV
///                                     decodes it (EXIF orientation applied when OpenCV sees it;
///                                     such photos are decoded once to get their size);
///                                     otherwise from GeoSourceOptions::photo_hfov_deg, else from
///                                     the EXIF FocalLengthIn35mmFilm f35: fx = fy = f35 *
///                                     (image diagonal in px) / 43.27 mm (the 35 mm-equivalent
///                                     definition, focal_px_from_35mm()), cx, cy at the centre
///   frame (optional)                  nearest video frame (the renderer writes it; evaluation)
/// The renderer's geotags.csv (`id,file,latitude,longitude,height,heading_deg,x,y,z,frame`) is
/// read as is; extra columns are ignored.

#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/map/camera.hpp"
#include "geodrift/map/geotag.hpp"

namespace geodrift::geotag {

enum class SourceKind { kPanorama, kPhoto };

/// One geo-tagged image file.
struct GeoSource {
  map::GeoTag tag;   ///< position; tag.heading = centre-column / optical-axis heading (rad; NaN =
                     ///< unknown, photos only)
  std::string path;  ///< absolute path of the image
  SourceKind kind = SourceKind::kPanorama;
  map::Camera photo_camera;  ///< photos only: intrinsics of the file (width/height filled on load)
  int frame = -1;            ///< nearest video frame if the CSV gives it, else -1
};

/// Options of read_geotag_csv().
struct GeoSourceOptions {
  /// Horizontal field of view (deg) assumed for photos whose row has no fx..cy; NaN = such a row
  /// is an error (a focal length is needed to localize a photo).
  double photo_hfov_deg = std::numeric_limits<double>::quiet_NaN();
};

/// Reads a geo-tag CSV (file comment). Checks every row (finite, in range, image file exists)
/// and reads each image's header size to classify it.
/// @throws InvalidArgument "<path>:<line>: <what>" for a malformed row, a missing column, an
///         unknown kind, a missing or unreadable image; Error if the file cannot be opened or
///         has no rows.
std::vector<GeoSource> read_geotag_csv(const std::string& csv_path,
                                       const GeoSourceOptions& options = {});

/// The sources of a folder of geo-tagged JPEG photos that has no geotags.csv: every *.jpg /
/// *.jpeg (any case), sorted by name, with EXIF GPS latitude, longitude and altitude becomes a
/// source (id = its rank among the usable files, frame -1). Its heading is the EXIF true
/// GPSImgDirection, NaN if absent. A 2:1 image is a panorama (and needs that heading), any other
/// a photo with intrinsics from options.photo_hfov_deg if given, else from
/// FocalLengthIn35mmFilm (as read_geotag_csv()). Files that cannot be used (no EXIF GPS
/// position or altitude, no focal length, a panorama without true heading, unreadable) are
/// SKIPPED, each listed as "<path>: <reason>" in *skipped for the caller to report.
/// @throws Error if `dir` is not a folder or holds no JPEG; InvalidArgument listing every
///         reason if no file is usable.
std::vector<GeoSource> read_geotag_jpeg_folder(const std::string& dir,
                                               const GeoSourceOptions& options = {},
                                               std::vector<std::string>* skipped = nullptr);

/// What `--geotags PATH` names: a geo-tag CSV file, a folder holding geotags.csv (read as a CSV),
/// or a folder of geo-tagged JPEGs (read_geotag_jpeg_folder(), whose skipped files are returned
/// in *skipped; cleared otherwise).
/// @throws Error if PATH does not exist; as the readers otherwise.
std::vector<GeoSource> read_geotag_sources(const std::string& path,
                                           const GeoSourceOptions& options = {},
                                           std::vector<std::string>* skipped = nullptr);

/// One view of the database.
struct GeoView {
  int id = 0;          ///< index in the database
  int source = 0;      ///< index of its GeoSource
  map::GeoTag tag;     ///< the source's geo-tag (tag.heading = the SOURCE's heading)
  double heading = 0;  ///< true heading of this view's optical axis (rad, [0, 2 pi)); NaN: unknown
  int direction = -1;  ///< panorama cut k in [0, 8) (heading = tag.heading + k * 45 deg); -1: photo
  map::Camera camera;  ///< intrinsics of the view image
  int frame = -1;      ///< the source's nearest video frame, -1 if unknown
};

/// The views of a set of sources: 8 per panorama (with the video camera's intrinsics `video`),
/// one per photo (its own intrinsics). View ids are 0..n-1 in order.
std::vector<GeoView> make_views(const std::vector<GeoSource>& sources, const map::Camera& video);

/// The geo-tag position in W.
Eigen::Vector3d view_position_world(const GeoView& view, const geo::LocalFrame& frame);

/// The view's pose in W as a world -> camera transform T_cw (camera x right, y down, z forward):
/// a level camera at the geo-tag position whose optical axis has the view's true heading, turned
/// into grid yaw with the meridian convergence (geo::LocalFrame::grid_yaw_from_heading()).
/// @throws InvalidArgument if the view's heading is unknown (NaN: a photo without heading).
lie::SE3d view_pose_world(const GeoView& view, const geo::LocalFrame& frame);

}  // namespace geodrift::geotag
