#pragma once

/// @file
/// COLMAP text model (`--map DIR`): cameras.txt, images.txt, points3D.txt, the sparse-model
/// export most SfM tools write (https://colmap.github.io/format.html).
///
///   cameras.txt   CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]
///                 PINHOLE fx fy cx cy | SIMPLE_PINHOLE f cx cy |
///                 OPENCV fx fy cx cy k1 k2 p1 p2 | SIMPLE_RADIAL f cx cy k | RADIAL f cx cy k1 k2
///                 (distortion terms must be exactly 0: geodrift's core takes undistorted
///                 pinhole cameras, DESIGN.md; undistort first, e.g. `colmap image_undistorter`)
///   images.txt    two lines per image:
///                 IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME      (world -> camera, = T_cw)
///                 POINTS2D[] as (X Y POINT3D_ID) triples, POINT3D_ID -1 when untriangulated
///                 (the second line may be empty)
///   points3D.txt  POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID POINT2D_IDX) pairs
/// Lines starting with '#' are comments (except the POINTS2D line, which is always read).
///
/// Mapping to map::Map (M = the model's frame and scale):
///   - each camera -> map::Camera (id = CAMERA_ID);
///   - each image -> map::Keyframe, id = IMAGE_ID, T_cw from the quaternion and translation,
///     in the order of `frame_index`. frame_index and timestamp come from the image NAME's stem:
///     a stem that is a decimal number with a fractional part ("1305031102.175304") is a TUM-style
///     timestamp (frame_index = rank in time); otherwise the last run of digits in the stem
///     ("000123", "frame_42") is the frame index and timestamp is NaN; names without digits get
///     their rank by IMAGE_ID;
///   - each POINTS2D entry with POINT3D_ID ≠ -1 -> map::Observation (pixel in COLMAP's image
///     coordinates; cameras.txt's principal point uses the same convention, so projections are
///     consistent without any half-pixel shift);
///   - each 3D point -> map::MapPoint; its reference keyframe is the keyframe of its track with
///     the smallest frame_index (the earliest view, as ORB-SLAM's creating keyframe).
///
/// Errors: InvalidArgument "<path>:<line>: <what>" (unknown or distorted camera model, wrong
/// field count, non-number or non-finite value, a quaternion of norm far from 1, duplicated ids,
/// an image naming an unknown camera, an observation naming an unknown point, a track naming an
/// unknown image or a POINT2D_IDX that does not point back at this point); Error for a missing
/// file.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/map/map.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// A COLMAP model read into geodrift's data model, with what the Map does not hold.
struct ColmapModel {
  map::Map map;  ///< cameras, keyframes (sorted by frame_index), points, observations
  /// Image NAME per keyframe (same order as map.keyframes).
  std::vector<std::string> image_names;
  /// RGB colour and mean reprojection ERROR per point (same order as map.points).
  std::vector<std::array<std::uint8_t, 3>> point_colors;
  std::vector<double> point_errors;
};

namespace detail {

/// frame_index / timestamp from an image name (see the file comment): sets *timestamp for a
/// "digits.digits" stem, else *frame from the last run of digits (-1 when there is none).
inline void frame_from_image_name(const std::string& name, long long* frame, double* timestamp) {
  std::string stem = name;
  const std::size_t slash = stem.find_last_of("/\\");
  if (slash != std::string::npos) stem = stem.substr(slash + 1);
  const std::size_t dot = stem.find_last_of('.');
  // Strip a file extension (letters after the last dot), keep "123.456" whole.
  if (dot != std::string::npos && dot + 1 < stem.size() &&
      std::isalpha(static_cast<unsigned char>(stem[dot + 1])))
    stem = stem.substr(0, dot);
  *frame = -1;
  *timestamp = std::numeric_limits<double>::quiet_NaN();
  // TUM-style "digits.digits".
  const std::size_t p = stem.find('.');
  const auto digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
  if (p != std::string::npos && p > 0 && p + 1 < stem.size() &&
      std::all_of(stem.begin(), stem.begin() + p, digit) &&
      std::all_of(stem.begin() + p + 1, stem.end(), digit)) {
    *timestamp = std::strtod(stem.c_str(), nullptr);
    return;
  }
  // Last run of digits.
  std::size_t e = stem.size();
  while (e > 0 && !std::isdigit(static_cast<unsigned char>(stem[e - 1]))) --e;
  std::size_t b = e;
  while (b > 0 && std::isdigit(static_cast<unsigned char>(stem[b - 1]))) --b;
  if (e > b && e - b <= 9) *frame = std::stoll(stem.substr(b, e - b));
}

}  // namespace detail

/// Reads a COLMAP text model from a directory (cameras.txt, images.txt, points3D.txt).
/// @throws Error if a file is missing; InvalidArgument "<path>:<line>: <what>" for bad content
///         (see the file comment).
inline ColmapModel read_colmap_text(const std::string& dir) {
  const std::string cameras_path = dir + "/cameras.txt";
  const std::string images_path = dir + "/images.txt";
  const std::string points_path = dir + "/points3D.txt";
  ColmapModel model;
  std::string raw;

  // ---- cameras.txt
  {
    detail::LineReader r(cameras_path);
    while (r.next(&raw)) {
      const std::string text = detail::trim(raw);
      if (text.empty() || text[0] == '#') continue;
      const int line = r.line();
      const std::vector<std::string> t = detail::split_ws(text);
      if (t.size() < 4)
        detail::parse_error(cameras_path, line,
                            "camera line has " + std::to_string(t.size()) +
                                " fields, expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...");
      map::Camera c;
      c.id = static_cast<int>(detail::parse_int(t[0], cameras_path, line, "CAMERA_ID", 0));
      const std::string& m = t[1];
      c.width = static_cast<int>(detail::parse_int(t[2], cameras_path, line, "WIDTH", 1));
      c.height = static_cast<int>(detail::parse_int(t[3], cameras_path, line, "HEIGHT", 1));
      std::size_t n_expected = 0, n_distortion = 0;
      if (m == "PINHOLE") {
        n_expected = 4;
      } else if (m == "SIMPLE_PINHOLE") {
        n_expected = 3;
      } else if (m == "OPENCV") {
        n_expected = 8, n_distortion = 4;
      } else if (m == "SIMPLE_RADIAL") {
        n_expected = 4, n_distortion = 1;
      } else if (m == "RADIAL") {
        n_expected = 5, n_distortion = 2;
      } else {
        detail::parse_error(cameras_path, line,
                            "camera model '" + m +
                                "' is not supported (PINHOLE, SIMPLE_PINHOLE, or OPENCV / "
                                "SIMPLE_RADIAL / RADIAL with zero distortion); undistort first");
      }
      if (t.size() != 4 + n_expected)
        detail::parse_error(cameras_path, line,
                            m + " camera has " + std::to_string(t.size() - 4) +
                                " parameters, expected " + std::to_string(n_expected));
      std::vector<double> p;
      for (std::size_t i = 4; i < t.size(); ++i)
        p.push_back(
            detail::parse_double(t[i], cameras_path, line, "parameter " + std::to_string(i - 4)));
      const std::size_t n_focal = (m == "PINHOLE" || m == "OPENCV") ? 2 : 1;
      for (std::size_t i = n_expected - n_distortion; i < n_expected; ++i)
        if (p[i] != 0.0)
          detail::parse_error(cameras_path, line,
                              m + " camera has non-zero distortion parameter " + detail::fmt(p[i]) +
                                  ": geodrift needs undistorted images (PINHOLE); undistort first");
      c.fx = p[0];
      c.fy = n_focal == 2 ? p[1] : p[0];
      c.cx = p[n_focal];
      c.cy = p[n_focal + 1];
      try {
        c.validate();
      } catch (const InvalidArgument& e) {
        detail::parse_error(cameras_path, line, e.what());
      }
      for (const map::Camera& o : model.map.cameras)
        if (o.id == c.id)
          detail::parse_error(cameras_path, line,
                              "CAMERA_ID " + std::to_string(c.id) + " appears twice");
      model.map.cameras.push_back(c);
    }
  }

  // ---- images.txt
  struct Image {
    map::Keyframe kf;
    std::string name;
    long long name_frame = -1;
    double name_time = std::numeric_limits<double>::quiet_NaN();
    std::vector<std::pair<Eigen::Vector2d, long long>> points2d;  // pixel, POINT3D_ID
    int line = 0;
  };
  std::vector<Image> images;
  std::unordered_map<int, std::size_t> image_index;
  {
    detail::LineReader r(images_path);
    while (r.next(&raw)) {
      const std::string text = detail::trim(raw);
      if (text.empty() || text[0] == '#') continue;
      const int line = r.line();
      const std::vector<std::string> t = detail::split_ws(text);
      if (t.size() < 10)
        detail::parse_error(images_path, line,
                            "image line has " + std::to_string(t.size()) +
                                " fields, expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
      Image im;
      im.line = line;
      im.kf.id = static_cast<int>(detail::parse_int(t[0], images_path, line, "IMAGE_ID", 0));
      static const char* kNames[7] = {"QW", "QX", "QY", "QZ", "TX", "TY", "TZ"};
      double v[7];
      for (int k = 0; k < 7; ++k)
        v[k] = detail::parse_double(t[1 + k], images_path, line, kNames[k]);
      const Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
      if (!(std::abs(q.norm() - 1.0) <= 1e-3))
        detail::parse_error(images_path, line,
                            "quaternion (QW QX QY QZ) has norm " + detail::fmt(q.norm()) +
                                ", expected 1 (tolerance 1e-3)");
      im.kf.T_cw = lie::SE3d(lie::SO3d(q), Eigen::Vector3d(v[4], v[5], v[6]));
      im.kf.camera_id =
          static_cast<int>(detail::parse_int(t[8], images_path, line, "CAMERA_ID", 0));
      bool camera_known = false;
      for (const map::Camera& c : model.map.cameras)
        camera_known = camera_known || c.id == im.kf.camera_id;
      if (!camera_known)
        detail::parse_error(images_path, line,
                            "image " + std::to_string(im.kf.id) + " names unknown CAMERA_ID " +
                                std::to_string(im.kf.camera_id));
      // NAME may contain spaces: everything after the 9th field. The fields are separated by the
      // same whitespace as split_ws() (isspace: a form feed or vertical tab separates too), so
      // the 10 fields found above guarantee a position here.
      {
        const char* kWs = " \t\n\v\f\r";
        std::size_t pos = 0;
        for (int k = 0; k < 9 && pos != std::string::npos; ++k) {
          pos = text.find_first_not_of(kWs, pos);
          pos = text.find_first_of(kWs, pos);
        }
        if (pos == std::string::npos)
          detail::parse_error(images_path, line, "image line has no NAME after CAMERA_ID");
        im.name = detail::trim(text.substr(pos));
      }
      detail::frame_from_image_name(im.name, &im.name_frame, &im.name_time);
      if (image_index.count(im.kf.id))
        detail::parse_error(images_path, line,
                            "IMAGE_ID " + std::to_string(im.kf.id) + " appears twice");
      // The POINTS2D line: always the next line, even when empty.
      std::string pts;
      if (!r.next(&pts))
        detail::parse_error(images_path, line,
                            "image " + std::to_string(im.kf.id) +
                                " has no POINTS2D line (images.txt has two lines per image)");
      const int pline = r.line();
      const std::vector<std::string> pt = detail::split_ws(pts);
      if (pt.size() % 3 != 0)
        detail::parse_error(images_path, pline,
                            "POINTS2D line has " + std::to_string(pt.size()) +
                                " fields, not a multiple of 3 (X Y POINT3D_ID)");
      for (std::size_t k = 0; k < pt.size(); k += 3) {
        const double x = detail::parse_double(pt[k], images_path, pline, "POINTS2D X");
        const double y = detail::parse_double(pt[k + 1], images_path, pline, "POINTS2D Y");
        const long long id = detail::parse_int(pt[k + 2], images_path, pline, "POINT3D_ID", -1);
        im.points2d.push_back({Eigen::Vector2d(x, y), id});
      }
      image_index[im.kf.id] = images.size();
      images.push_back(std::move(im));
    }
  }

  // ---- points3D.txt
  std::unordered_map<long long, std::size_t> point_index;
  std::vector<std::vector<std::pair<int, long long>>> tracks;
  std::vector<int> point_lines;
  {
    detail::LineReader r(points_path);
    while (r.next(&raw)) {
      const std::string text = detail::trim(raw);
      if (text.empty() || text[0] == '#') continue;
      const int line = r.line();
      const std::vector<std::string> t = detail::split_ws(text);
      if (t.size() < 8 || (t.size() - 8) % 2 != 0)
        detail::parse_error(points_path, line,
                            "point line has " + std::to_string(t.size()) +
                                " fields, expected POINT3D_ID X Y Z R G B ERROR then "
                                "(IMAGE_ID POINT2D_IDX) pairs");
      const long long id = detail::parse_int(t[0], points_path, line, "POINT3D_ID", 0,
                                             std::numeric_limits<int>::max());
      map::MapPoint p;
      p.id = static_cast<int>(id);
      p.position = Eigen::Vector3d(detail::parse_double(t[1], points_path, line, "X"),
                                   detail::parse_double(t[2], points_path, line, "Y"),
                                   detail::parse_double(t[3], points_path, line, "Z"));
      std::array<std::uint8_t, 3> rgb{};
      for (int k = 0; k < 3; ++k)
        rgb[k] = static_cast<std::uint8_t>(detail::parse_int(
            t[4 + k], points_path, line, k == 0 ? "R" : (k == 1 ? "G" : "B"), 0, 255));
      const double err = detail::parse_double(t[7], points_path, line, "ERROR");
      std::vector<std::pair<int, long long>> track;
      for (std::size_t k = 8; k < t.size(); k += 2) {
        const int img =
            static_cast<int>(detail::parse_int(t[k], points_path, line, "track IMAGE_ID", 0));
        const long long idx =
            detail::parse_int(t[k + 1], points_path, line, "track POINT2D_IDX", 0);
        const auto it = image_index.find(img);
        if (it == image_index.end())
          detail::parse_error(points_path, line,
                              "point " + std::to_string(id) + " track names unknown IMAGE_ID " +
                                  std::to_string(img));
        const Image& im = images[it->second];
        if (idx >= static_cast<long long>(im.points2d.size()) || im.points2d[idx].second != id)
          detail::parse_error(points_path, line,
                              "point " + std::to_string(id) + " track entry (" +
                                  std::to_string(img) + ", " + std::to_string(idx) +
                                  ") does not point back at this point in images.txt");
        track.push_back({img, idx});
      }
      if (point_index.count(id))
        detail::parse_error(points_path, line,
                            "POINT3D_ID " + std::to_string(id) + " appears twice");
      point_index[id] = model.map.points.size();
      model.map.points.push_back(p);
      model.point_colors.push_back(rgb);
      model.point_errors.push_back(err);
      tracks.push_back(std::move(track));
      point_lines.push_back(line);
    }
  }

  // ---- frame indices and timestamps from the names; keyframes in frame order.
  bool all_times = !images.empty(), all_frames = !images.empty();
  for (const Image& im : images) {
    all_times = all_times && std::isfinite(im.name_time);
    all_frames = all_frames && im.name_frame >= 0;
  }
  std::vector<std::size_t> order(images.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    if (all_times) return images[a].name_time < images[b].name_time;
    if (all_frames) return images[a].name_frame < images[b].name_frame;
    return images[a].kf.id < images[b].kf.id;
  });
  for (std::size_t rank = 0; rank < order.size(); ++rank) {
    Image& im = images[order[rank]];
    im.kf.frame_index =
        all_frames && !all_times ? static_cast<int>(im.name_frame) : static_cast<int>(rank);
    im.kf.timestamp = all_times ? im.name_time : std::numeric_limits<double>::quiet_NaN();
    if (rank > 0) {
      const Image& prev = images[order[rank - 1]];
      if (all_frames && !all_times && prev.name_frame == im.name_frame)
        detail::parse_error(images_path, im.line,
                            "image name '" + im.name + "' gives frame index " +
                                std::to_string(im.name_frame) + ", already used by '" + prev.name +
                                "'");
    }
    model.map.keyframes.push_back(im.kf);
    model.image_names.push_back(im.name);
  }

  // ---- observations, and every observed point must exist.
  for (std::size_t rank = 0; rank < order.size(); ++rank) {
    const Image& im = images[order[rank]];
    for (const auto& [pixel, id] : im.points2d) {
      if (id < 0) continue;
      if (!point_index.count(id))
        detail::parse_error(images_path, im.line + 1,
                            "image " + std::to_string(im.kf.id) + " observes unknown POINT3D_ID " +
                                std::to_string(id));
      map::Observation o;
      o.keyframe = im.kf.id;
      o.point = static_cast<int>(id);
      o.pixel = pixel;
      model.map.observations.push_back(o);
    }
  }
  // ---- reference keyframe: the earliest keyframe in the point's track.
  for (std::size_t i = 0; i < model.map.points.size(); ++i) {
    int best = -1, best_frame = std::numeric_limits<int>::max();
    for (const auto& [img, idx] : tracks[i]) {
      (void)idx;
      const map::Keyframe& kf = images[image_index.at(img)].kf;
      if (kf.frame_index < best_frame) best = kf.id, best_frame = kf.frame_index;
    }
    model.map.points[i].reference_keyframe = best;
  }
  (void)point_lines;
  return model;
}

/// Writes a COLMAP text model (cameras.txt as PINHOLE, images.txt, points3D.txt) into an existing
/// directory, each file atomically, with '#' header lines stating geodrift's version, the frame
/// (`frame_note`, e.g. "W = UTM 32N ..."), units and COLMAP's column descriptions. Image names are
/// `image_names` when given (same order as keyframes), else "<frame_index>.png" with 6 digits.
/// Point colours/errors default to grey and 0 when not given. `units`: the length unit stated
/// ("metres" in W, kMapUnits in a monocular map frame M).
/// @throws InvalidArgument for an observation naming an unknown keyframe/point or sizes that do
///         not match; Error on I/O failure.
inline void write_colmap_text(const std::string& dir, const map::Map& m,
                              const std::string& frame_note,
                              const std::vector<std::string>& image_names = {},
                              const std::vector<std::array<std::uint8_t, 3>>& point_colors = {},
                              const std::vector<double>& point_errors = {},
                              const std::string& units = "metres") {
  GEODRIFT_CHECK(image_names.empty() || image_names.size() == m.keyframes.size(),
                 "write_colmap_text: " << image_names.size() << " image names for "
                                       << m.keyframes.size() << " keyframes");
  GEODRIFT_CHECK(point_colors.empty() || point_colors.size() == m.points.size(),
                 "write_colmap_text: " << point_colors.size() << " colours for " << m.points.size()
                                       << " points");
  GEODRIFT_CHECK(point_errors.empty() || point_errors.size() == m.points.size(),
                 "write_colmap_text: " << point_errors.size() << " errors for " << m.points.size()
                                       << " points");
  m.validate();
  // POINT2D_IDX of each observation within its keyframe, for the tracks.
  std::unordered_map<int, std::vector<const map::Observation*>> obs_of_kf;
  for (const map::Observation& o : m.observations) obs_of_kf[o.keyframe].push_back(&o);
  std::unordered_map<int, std::vector<std::pair<int, std::size_t>>> track_of_point;
  for (const map::Keyframe& k : m.keyframes) {
    const auto it = obs_of_kf.find(k.id);
    if (it == obs_of_kf.end()) continue;
    for (std::size_t i = 0; i < it->second.size(); ++i)
      track_of_point[it->second[i]->point].push_back({k.id, i});
  }
  const std::string head = std::string("# geodrift ") + kVersion +
                           " COLMAP text model; frame: " + frame_note + "; units: " + units +
                           ", pixels\n";

  detail::write_atomically(dir + "/cameras.txt", [&](std::ostream& os) {
    os << head << "# Camera list with one line of data per camera:\n"
       << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
       << "# Number of cameras: " << m.cameras.size() << "\n";
    for (const map::Camera& c : m.cameras)
      os << c.id << " PINHOLE " << c.width << ' ' << c.height << ' ' << detail::fmt(c.fx) << ' '
         << detail::fmt(c.fy) << ' ' << detail::fmt(c.cx) << ' ' << detail::fmt(c.cy) << '\n';
  });
  detail::write_atomically(dir + "/images.txt", [&](std::ostream& os) {
    os << head << "# Image list with two lines of data per image:\n"
       << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
       << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
       << "# Number of images: " << m.keyframes.size() << "\n";
    for (std::size_t i = 0; i < m.keyframes.size(); ++i) {
      const map::Keyframe& k = m.keyframes[i];
      const Eigen::Quaterniond& q = k.T_cw.rotation().quaternion();
      const Eigen::Vector3d& t = k.T_cw.translation();
      std::string name;
      if (!image_names.empty()) {
        name = image_names[i];
      } else {
        char buf[32];
        std::snprintf(buf, sizeof(buf), "%06d.png", k.frame_index);
        name = buf;
      }
      os << k.id << ' ' << detail::fmt(q.w()) << ' ' << detail::fmt(q.x()) << ' '
         << detail::fmt(q.y()) << ' ' << detail::fmt(q.z()) << ' ' << detail::fmt(t.x()) << ' '
         << detail::fmt(t.y()) << ' ' << detail::fmt(t.z()) << ' ' << k.camera_id << ' ' << name
         << '\n';
      const auto it = obs_of_kf.find(k.id);
      if (it != obs_of_kf.end()) {
        for (std::size_t j = 0; j < it->second.size(); ++j) {
          const map::Observation& o = *it->second[j];
          if (j) os << ' ';
          os << detail::fmt(o.pixel.x()) << ' ' << detail::fmt(o.pixel.y()) << ' ' << o.point;
        }
      }
      os << '\n';
    }
  });
  detail::write_atomically(dir + "/points3D.txt", [&](std::ostream& os) {
    os << head << "# 3D point list with one line of data per point:\n"
       << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
       << "# Number of points: " << m.points.size() << "\n";
    for (std::size_t i = 0; i < m.points.size(); ++i) {
      const map::MapPoint& p = m.points[i];
      const std::array<std::uint8_t, 3> rgb =
          point_colors.empty() ? std::array<std::uint8_t, 3>{128, 128, 128} : point_colors[i];
      os << p.id << ' ' << detail::fmt(p.position.x()) << ' ' << detail::fmt(p.position.y()) << ' '
         << detail::fmt(p.position.z()) << ' ' << int(rgb[0]) << ' ' << int(rgb[1]) << ' '
         << int(rgb[2]) << ' ' << detail::fmt(point_errors.empty() ? 0.0 : point_errors[i]);
      const auto it = track_of_point.find(p.id);
      if (it != track_of_point.end())
        for (const auto& [img, idx] : it->second) os << ' ' << img << ' ' << idx;
      os << '\n';
    }
  });
}

}  // namespace geodrift::io
