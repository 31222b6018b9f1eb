#pragma once

/// @file
/// A rendered dataset folder (what `geodrift render` writes). FIXED INTERFACE: the VO and the
/// geo-tag pipeline read it.
///
///   calib.txt        KITTI odometry format, two lines
///                      P0: fx 0 cx 0 0 fy cy 0 0 0 1 0
///                      P1: fx 0 cx -fx·b 0 fy cy 0 0 0 1 0      (b = 0.54 m stereo baseline)
///                    numbers as in KITTI (%.12e); the intrinsics are P0 of the input calib.
///   times.txt        one time in seconds per frame: KITTI's times of the chosen frames when
///                    --times was given (not re-based), else 0.1 s · sequence frame index.
///   poses.txt        ground truth T_wc (cam0 -> KITTI world of the SEQUENCE, i.e. KITTI's own
///                    frame: cam0 of the sequence's frame 0), 12 numbers per line, KITTI format:
///                    the rows of the chosen frames copied from the input pose file (re-written
///                    with shortest round-trip digits after re-orthonormalisation by
///                    io::read_trajectory), after one '#' header line.
///   image_0/NNNNNN.png  frame i of the sub-route (sequence frame first + i), 6 digits from
///                    000000, 8-bit grey, 1241 × 376 (the calib's camera).
///   panoramas/pano_NNNNNN.png  equirectangular RGB panoramas, 2048 × 1024 (default), id from 0,
///                    street-view appearance (render.hpp's pixel convention).
///   geotags.csv      header `id,file,latitude,longitude,height,heading_deg,x,y,z,frame`
///                    (after '#' comment lines stating frame, units, version and the geo-origin
///                    assumption): file relative to the dataset folder (panoramas/pano_...png);
///                    latitude/longitude (deg, WGS84) and ellipsoidal height (m) of the
///                    panorama centre through the ASSUMED KITTI geo origin
///                    (geo::kitti_local_frame()); heading_deg = true bearing of the panorama's
///                    CENTRE column (the route's direction of travel there); x, y, z = panorama
///                    centre in W (metres, E/N/Up of KITTI cam0 at sequence frame 0); frame =
///                    index of the nearest video frame IN THE DATASET (image_0 numbering).
///   dataset.json     seed, sequence, frame range, settings (appearances, spacing, antialias,
///                    layout), geo origin, renderer version.
///
/// Panorama pixel convention: level; column u ↦ bearing β = heading_deg + 360·((u+0.5)/W − 0.5)
/// degrees clockwise from true north; row v ↦ elevation 90 − 180·(v+0.5)/H degrees.
/// Panorama centres: every `panorama_spacing_m` of route arclength from the first frame's
/// position to the last frame's, 2.5 m above the ground at that route point (0.85 m above the
/// video camera path), with lateral offset `panorama_lateral_offset_m` (default 0: on the route;
/// positive = right of travel).

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "geodrift/render/render.hpp"
#include "geodrift/render/world.hpp"

namespace geodrift::render {

/// Version of the renderer's world and images (changes whenever images change).
inline constexpr const char* kRendererVersion = "1";

/// One panorama site.
struct PanoramaSite {
  int id = 0;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  ///< W (m)
  double heading = 0;  ///< true bearing of the centre column (rad, [0, 2π))
  double s = 0;        ///< route arclength (m)
  int frame = 0;       ///< nearest video frame, dataset numbering (sequence frame − first)
};

/// Panorama sites every `spacing_m` along the route from sequence frame `first` to `last`
/// (inclusive) of the world, at `height_m` above the ground, `lateral_offset_m` right of the
/// route. @throws InvalidArgument for spacing <= 0 or a bad range.
std::vector<PanoramaSite> panorama_sites(const World& world, int first, int last, double spacing_m,
                                         double height_m = 2.5, double lateral_offset_m = 0.0);

/// What to render.
struct DatasetOptions {
  std::string poses_path;  ///< KITTI pose file of the sequence (required)
  std::string calib_path;  ///< KITTI calib.txt (required; P0, P1)
  std::string times_path;  ///< KITTI times.txt (optional)
  std::string sequence;    ///< name for dataset.json (default: the pose file's stem)
  int first = 0;           ///< first sequence frame (inclusive)
  int last = -1;           ///< last sequence frame (inclusive; -1 = last pose)
  std::uint64_t seed = 1;
  double panorama_spacing_m = 5.0;  ///< <= 0: no panoramas
  double panorama_height_m = 2.5;
  double panorama_lateral_offset_m = 0.0;
  int panorama_width = 2048, panorama_height = 1024;
  RenderOptions frame_render{};  ///< grey, quincunx
  int threads = 0;               ///< 0 = hardware concurrency
};

/// Progress callback: (stage "frames" or "panoramas", done, total).
using ProgressFn = std::function<void(const char* stage, int done, int total)>;

/// Summary of a written dataset.
struct DatasetSummary {
  int frames = 0, panoramas = 0;
  double frame_seconds = 0, panorama_seconds = 0;  ///< wall time of the two stages
  std::string world_summary;
};

/// Reads the inputs, builds the world and writes the dataset into the EXISTING directory `dir`
/// (the caller stages it; files are created there).
/// @throws Error for unreadable files or failed writes; InvalidArgument for malformed inputs or
///         options (bad range, malformed calib, non-finite numbers, ...), naming the problem.
DatasetSummary write_dataset(const DatasetOptions& options, const std::string& dir,
                             const ProgressFn& progress = {});

}  // namespace geodrift::render
