#pragma once
/// @file
/// Fuzz entry points of every geodrift parser, shared by the libFuzzer mains (fuzz/fuzz_*.cpp,
/// built with GEODRIFT_FUZZ=ON by scripts/fuzz.sh) and the corpus replay test (tests/fuzz/).
///
/// Each entry writes the input to a file in a per-process scratch folder (under $TMPDIR, else
/// /dev/shm, else /tmp) and calls the reader a user reaches through the command line, with the
/// path. A geodrift::Error (InvalidArgument included) is the expected outcome of a malformed
/// input and is swallowed; anything else escapes and is a finding: another exception type
/// (std::out_of_range, std::bad_alloc, cv::Exception, ...), a crash, a hang or a sanitizer report.
///
/// The OpenCV-backed readers (geo-tag CSV, EXIF, calibration) are compiled only when
/// GEODRIFT_FUZZ_FRONTENDS is defined (the frontends are built).

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/anchors.hpp"
#include "geodrift/io/bal.hpp"
#include "geodrift/io/colmap_text.hpp"
#include "geodrift/io/g2o.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/io/vo_stereo.hpp"

#ifdef GEODRIFT_FUZZ_FRONTENDS
#include "geodrift/geotag/exif.hpp"
#include "geodrift/geotag/views.hpp"
#include "geodrift/vo/input.hpp"
#endif

namespace geodrift::fuzz {

namespace detail {

/// Removes the scratch folder at exit (registered once by scratch_dir()).
inline void remove_scratch_dir();

/// The per-process scratch folder, created on first use: "<tmp>/geodrift-fuzz-<pid>". The string
/// is never destroyed, so the exit handler that removes the folder can still read it.
inline const std::string& scratch_dir() {
  static const std::string* const dir = [] {
    namespace fs = std::filesystem;
    std::string base;
    if (const char* t = std::getenv("TMPDIR"); t && *t && fs::is_directory(t)) {
      base = t;
    } else if (fs::is_directory("/dev/shm")) {
      base = "/dev/shm";
    } else {
      base = "/tmp";
    }
    const std::string d = base + "/geodrift-fuzz-" + std::to_string(::getpid());
    fs::create_directories(d);
    std::atexit(remove_scratch_dir);
    return new std::string(d);
  }();
  return *dir;
}

inline void remove_scratch_dir() {
  std::error_code ec;
  std::filesystem::remove_all(scratch_dir(), ec);
}

/// Writes `size` bytes to <scratch>/<name> (replacing it) and returns the path.
inline std::string write_file(const std::string& name, const std::uint8_t* data, std::size_t size) {
  const std::string path = scratch_dir() + "/" + name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();  // the harness itself is broken (disk full): not a parser finding
  return path;
}

inline std::string write_file(const std::string& name, const std::string& text) {
  return write_file(name, reinterpret_cast<const std::uint8_t*>(text.data()), text.size());
}

/// Runs `f`; a geodrift::Error is the clean outcome, anything else propagates.
template <class F>
int expect_clean(F&& f) {
  try {
    f();
  } catch (const Error&) {
  }
  return 0;
}

/// The COLMAP folder: the fuzzed file `fuzzed` plus fixed, valid versions of the other two.
inline std::string colmap_dir(const char* fuzzed, const std::uint8_t* data, std::size_t size) {
  static const std::string kCameras =
      "# Camera list\n"
      "1 PINHOLE 640 480 500 500 320 240\n"
      "2 SIMPLE_PINHOLE 1241 376 718.856 607.19 185.22\n";
  static const std::string kImages =
      "# Image list\n"
      "1 1 0 0 0 0 0 0 1 000000.png\n"
      "100 200 1 0 300 400 5\n"
      "2 0.9998 0.02 0 0 -0.5 0 0.1 2 000001.png\n"
      "101 201 1 110 301 5 -1\n";
  static const std::string kPoints =
      "# 3D point list\n"
      "1 0.1 0.2 5 255 0 0 0.5 1 0 2 0\n"
      "5 -1 0.5 7 10 20 30 1.5 1 1\n";
  const std::string dir = scratch_dir() + "/colmap";
  std::filesystem::create_directories(dir);
  const std::string f = fuzzed;
  if (f == "cameras.txt") {
    write_file("colmap/cameras.txt", data, size);
  } else {
    write_file("colmap/cameras.txt", kCameras);
  }
  if (f == "images.txt") {
    write_file("colmap/images.txt", data, size);
  } else {
    write_file("colmap/images.txt", f == "cameras.txt" ? std::string() : kImages);
  }
  if (f == "points3D.txt") {
    write_file("colmap/points3D.txt", data, size);
  } else {
    write_file("colmap/points3D.txt", f == "images.txt" ? kPoints : std::string());
  }
  return dir;
}

}  // namespace detail

/// KITTI trajectory (12 fields, or 13 with a leading frame index or timestamp), read as KITTI and
/// with format detection.
inline int fuzz_trajectory_kitti(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("poses.txt", data, size);
  detail::expect_clean([&] { io::read_trajectory(path, io::TrajectoryFormat::kKitti); });
  return detail::expect_clean([&] { io::read_trajectory(path, io::TrajectoryFormat::kAuto); });
}

/// TUM trajectory (timestamp tx ty tz qx qy qz qw).
inline int fuzz_trajectory_tum(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("traj.tum", data, size);
  return detail::expect_clean([&] { io::read_trajectory(path, io::TrajectoryFormat::kTum); });
}

/// COLMAP cameras.txt (with empty images.txt and points3D.txt).
inline int fuzz_colmap_cameras(const std::uint8_t* data, std::size_t size) {
  const std::string dir = detail::colmap_dir("cameras.txt", data, size);
  return detail::expect_clean([&] { io::read_colmap_text(dir); });
}

/// COLMAP images.txt (with a fixed cameras.txt and points3D.txt).
inline int fuzz_colmap_images(const std::uint8_t* data, std::size_t size) {
  const std::string dir = detail::colmap_dir("images.txt", data, size);
  return detail::expect_clean([&] { io::read_colmap_text(dir); });
}

/// COLMAP points3D.txt (with a fixed cameras.txt and images.txt).
inline int fuzz_colmap_points3d(const std::uint8_t* data, std::size_t size) {
  const std::string dir = detail::colmap_dir("points3D.txt", data, size);
  return detail::expect_clean([&] { io::read_colmap_text(dir); });
}

/// Anchors CSV, read and converted to W as `geodrift correct --anchors` does (the local frame at
/// the first anchor).
inline int fuzz_anchors(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("anchors.csv", data, size);
  return detail::expect_clean([&] {
    const io::AnchorTable table = io::read_anchors_csv(path);
    io::anchors_in_world(table, io::local_frame_at_first_anchor(table));
  });
}

/// g2o 3D pose graph.
inline int fuzz_g2o(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("graph.g2o", data, size);
  return detail::expect_clean([&] { io::read_g2o_se3(path); });
}

/// Bundle Adjustment in the Large problem file.
inline int fuzz_bal(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("problem.txt", data, size);
  return detail::expect_clean([&] { io::read_bal(path); });
}

/// GTSAM stereo VO files: the same bytes read as calibration, camera poses and stereo factors.
inline int fuzz_vo_stereo(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("vo.txt", data, size);
  detail::expect_clean([&] { io::read_vo_calibration(path); });
  detail::expect_clean([&] { io::read_vo_camera_poses(path); });
  return detail::expect_clean([&] { io::read_vo_stereo_factors(path); });
}

#ifdef GEODRIFT_FUZZ_FRONTENDS

/// Geo-tag CSV, in a folder that holds a 2:1 PNG "pano.png" (header only), a 4:3 PNG
/// "photo.png" and a JPEG "photo.jpg" (SOF only, no EXIF), so rows can name existing images.
inline int fuzz_geotag_csv(const std::uint8_t* data, std::size_t size) {
  static const bool images_written = [] {
    const auto png = [](const char* name, unsigned w, unsigned h) {
      std::vector<std::uint8_t> b = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A,
                                     0,    0,   0,   13,  'I',  'H',  'D',  'R'};
      for (unsigned v : {w, h})
        for (int s = 24; s >= 0; s -= 8) b.push_back(static_cast<std::uint8_t>(v >> s));
      detail::write_file(name, b.data(), b.size());
    };
    png("pano.png", 200, 100);
    png("photo.png", 640, 480);
    const std::vector<std::uint8_t> jpg = {0xFF, 0xD8, 0xFF, 0xC0, 0x00, 0x11, 0x08, 0x01,
                                           0xE0, 0x02, 0x80, 0x03, 0x01, 0x22, 0x00, 0x02,
                                           0x11, 0x01, 0x03, 0x11, 0x01, 0xFF, 0xD9};
    detail::write_file("photo.jpg", jpg.data(), jpg.size());
    return true;
  }();
  (void)images_written;
  const std::string path = detail::write_file("geotags.csv", data, size);
  return detail::expect_clean([&] { geotag::read_geotag_csv(path); });
}

/// EXIF geo-tag of a JPEG file.
inline int fuzz_exif(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("image.jpg", data, size);
  return detail::expect_clean([&] { geotag::read_exif(path); });
}

/// Text calibration: KITTI calib.txt ("P0: ...") or "K: / D: / size:" (falls back to OpenCV
/// FileStorage, as for a user's calib.txt).
inline int fuzz_calib_text(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("calib.txt", data, size);
  return detail::expect_clean([&] { vo::load_calibration(path); });
}

/// OpenCV FileStorage YAML calibration (camera_matrix / K, distortion_coefficients / D).
inline int fuzz_calib_yaml(const std::uint8_t* data, std::size_t size) {
  const std::string path = detail::write_file("calib.yaml", data, size);
  return detail::expect_clean([&] { vo::load_calibration(path); });
}

#endif  // GEODRIFT_FUZZ_FRONTENDS

/// A fuzz target: its name (fuzz/fuzz_<name>.cpp, corpus tests/fuzz/<name>/) and entry.
struct Target {
  const char* name;
  int (*entry)(const std::uint8_t*, std::size_t);
  bool needs_frontends;
};

/// Every target, those of the frontends included (entry nullptr when they are not compiled).
inline const std::vector<Target>& targets() {
#ifdef GEODRIFT_FUZZ_FRONTENDS
#define GEODRIFT_FUZZ_FE(f) f
#else
#define GEODRIFT_FUZZ_FE(f) nullptr
#endif
  static const std::vector<Target> all = {
      {"trajectory_kitti", fuzz_trajectory_kitti, false},
      {"trajectory_tum", fuzz_trajectory_tum, false},
      {"colmap_cameras", fuzz_colmap_cameras, false},
      {"colmap_images", fuzz_colmap_images, false},
      {"colmap_points3d", fuzz_colmap_points3d, false},
      {"anchors", fuzz_anchors, false},
      {"g2o", fuzz_g2o, false},
      {"bal", fuzz_bal, false},
      {"vo_stereo", fuzz_vo_stereo, false},
      {"geotag_csv", GEODRIFT_FUZZ_FE(fuzz_geotag_csv), true},
      {"exif", GEODRIFT_FUZZ_FE(fuzz_exif), true},
      {"calib_text", GEODRIFT_FUZZ_FE(fuzz_calib_text), true},
      {"calib_yaml", GEODRIFT_FUZZ_FE(fuzz_calib_yaml), true},
  };
#undef GEODRIFT_FUZZ_FE
  return all;
}

}  // namespace geodrift::fuzz
