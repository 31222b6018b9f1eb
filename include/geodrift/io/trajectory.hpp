#pragma once

/// @file
/// Trajectory files: KITTI and TUM, read by content or by a forced format, written with a
/// header comment stating frame, units and the geodrift version (evo skips '#' lines).
///
/// File formats (both store camera -> world poses T_wc; geodrift keeps T_cw = T_wc⁻¹ in memory,
/// DESIGN.md, and converts here, at the edge):
///   KITTI  r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz      (the 3x4 [R | t] row-major)
///          optionally preceded by a 13th leading column: an integer frame index when it is an
///          integer on every line, else a timestamp in seconds (the "poses with times" variant
///          that prepends KITTI's times.txt);
///   TUM    timestamp tx ty tz qx qy qz qw                    (seconds, metres, unit quaternion)
/// Blank lines and lines starting with '#' are skipped. Every data line must have the same
/// number of fields.
///
/// Validation (InvalidArgument "<path>:<line>: <what>"): a field that is not a number or not
/// finite, a wrong field count, a KITTI rotation block that is not a rotation (max |RᵀR − I| >
/// 1e-3 or det ≤ 0; within tolerance it is re-orthonormalised), a TUM quaternion whose norm is
/// not 1 within 1e-3 (normalised otherwise), frame indices or timestamps that do not strictly
/// increase, a file without poses. A missing file throws Error naming the path.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <cmath>
#include <limits>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/detail/text_io.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/version.hpp"

namespace geodrift::io {

/// Trajectory file format. kAuto detects it from the first data line's field count
/// (12 or 13: KITTI, 8: TUM).
enum class TrajectoryFormat { kAuto, kKitti, kTum };

/// "auto", "kitti", "tum".
inline const char* to_string(TrajectoryFormat f) {
  switch (f) {
    case TrajectoryFormat::kKitti:
      return "kitti";
    case TrajectoryFormat::kTum:
      return "tum";
    default:
      return "auto";
  }
}

/// Parses "auto" / "kitti" / "tum" (as given to --format).
/// @throws InvalidArgument naming the string otherwise.
inline TrajectoryFormat parse_trajectory_format(const std::string& s) {
  if (s == "auto") return TrajectoryFormat::kAuto;
  if (s == "kitti") return TrajectoryFormat::kKitti;
  if (s == "tum") return TrajectoryFormat::kTum;
  ::geodrift::detail::throw_invalid_argument("trajectory format '" + s +
                                             "' is not one of auto, kitti, tum");
}

/// One pose of a trajectory.
struct TrajectoryPose {
  /// Frame index: the leading index of a 13-field KITTI line, else the 0-based data-line order.
  int frame = 0;
  /// Seconds (TUM, KITTI with a time column); NaN when the file has no timestamps.
  double timestamp = std::numeric_limits<double>::quiet_NaN();
  /// World -> camera (DESIGN.md), in the file's world frame and units.
  lie::SE3d T_cw;
  /// 1-based line in the file it came from (0 when built in memory).
  int line = 0;
};

/// A trajectory as read from (or to be written to) a file.
struct Trajectory {
  TrajectoryFormat format = TrajectoryFormat::kAuto;  ///< format the file was read as
  bool has_frame_index = false;  ///< KITTI file carried an explicit leading frame index
  bool has_timestamps = false;   ///< TUM file, or KITTI with a leading time column
  std::vector<TrajectoryPose> poses;
};

namespace detail {

/// Checks a 3x3 block read from a file is a rotation within 1e-3 and returns it as SO3.
inline lie::SO3d rotation_from_file(const Eigen::Matrix3d& R, const std::string& path, int line) {
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = R.determinant();
  if (!(orth <= 1e-3) || !(det > 0.0)) {
    std::ostringstream os;
    os << "rotation block is not a rotation (max |R^T R - I| = " << orth << ", det = " << det
       << "; tolerance 1e-3)";
    parse_error(path, line, os.str());
  }
  return lie::SO3d(R);
}

}  // namespace detail

/// Reads a KITTI or TUM trajectory.
/// @param path   file to read.
/// @param format kAuto (detect from the field count), kKitti or kTum.
/// @return poses as T_cw (world -> camera) in the file's world frame, in file order.
/// @throws Error if the file cannot be opened; InvalidArgument "<path>:<line>: <what>" on any
///         malformed content (see the file comment), including an empty trajectory.
inline Trajectory read_trajectory(const std::string& path,
                                  TrajectoryFormat format = TrajectoryFormat::kAuto) {
  detail::LineReader reader(path);
  Trajectory traj;
  traj.format = format;
  // Pass 1: the data lines (the leading column of a 13-field KITTI file is a frame index only if
  // it is an integer on every line, which needs the whole file).
  std::vector<std::pair<int, std::vector<std::string>>> data;
  std::string raw;
  while (reader.next(&raw)) {
    const std::string text = detail::trim(raw);
    if (text.empty() || text[0] == '#') continue;
    data.emplace_back(reader.line(), detail::split_ws(text));
  }
  bool leading_is_integer = true;
  for (const auto& d : data) {
    if (d.second.size() != 13) continue;
    const std::string& f = d.second[0];
    const std::size_t b = (!f.empty() && (f[0] == '-' || f[0] == '+')) ? 1 : 0;
    leading_is_integer = leading_is_integer && f.size() > b &&
                         f.find_first_not_of("0123456789", b) == std::string::npos;
  }
  std::size_t expected_fields = 0;
  for (const auto& [line, tok] : data) {
    if (expected_fields == 0) {
      // The first data line fixes the format (auto) and the field count.
      if (traj.format == TrajectoryFormat::kAuto) {
        if (tok.size() == 12 || tok.size() == 13) {
          traj.format = TrajectoryFormat::kKitti;
        } else if (tok.size() == 8) {
          traj.format = TrajectoryFormat::kTum;
        } else {
          detail::parse_error(path, line,
                              "cannot detect the trajectory format from " +
                                  std::to_string(tok.size()) +
                                  " fields (KITTI has 12, or 13 with a frame index; TUM has 8)");
        }
      }
      if (traj.format == TrajectoryFormat::kKitti && tok.size() != 12 && tok.size() != 13) {
        detail::parse_error(path, line,
                            "KITTI line has " + std::to_string(tok.size()) +
                                " fields, expected 12 (or 13 with a leading frame index)");
      }
      if (traj.format == TrajectoryFormat::kTum && tok.size() != 8) {
        detail::parse_error(path, line,
                            "TUM line has " + std::to_string(tok.size()) +
                                " fields, expected 8 (timestamp tx ty tz qx qy qz qw)");
      }
      expected_fields = tok.size();
      const bool kitti13 = traj.format == TrajectoryFormat::kKitti && tok.size() == 13;
      traj.has_frame_index = kitti13 && leading_is_integer;
      traj.has_timestamps =
          traj.format == TrajectoryFormat::kTum || (kitti13 && !leading_is_integer);
    } else if (tok.size() != expected_fields) {
      detail::parse_error(path, line,
                          std::string(to_string(traj.format)) + " line has " +
                              std::to_string(tok.size()) + " fields, expected " +
                              std::to_string(expected_fields) + " like the first data line");
    }

    TrajectoryPose pose;
    pose.line = line;
    pose.frame = static_cast<int>(traj.poses.size());
    Eigen::Matrix3d R_wc;
    Eigen::Vector3d t_wc;
    lie::SO3d rot;
    if (traj.format == TrajectoryFormat::kKitti) {
      std::size_t k = 0;
      if (traj.has_frame_index) {
        pose.frame = static_cast<int>(detail::parse_int(tok[0], path, line, "frame index", 0));
        k = 1;
      } else if (traj.has_timestamps) {
        pose.timestamp = detail::parse_double(tok[0], path, line, "timestamp");
        k = 1;
      }
      static const char* kNames[12] = {"r11", "r12", "r13", "tx",  "r21", "r22",
                                       "r23", "ty",  "r31", "r32", "r33", "tz"};
      double v[12];
      for (int m = 0; m < 12; ++m) v[m] = detail::parse_double(tok[k + m], path, line, kNames[m]);
      R_wc << v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10];
      t_wc << v[3], v[7], v[11];
      rot = detail::rotation_from_file(R_wc, path, line);
    } else {
      static const char* kNames[8] = {"timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"};
      double v[8];
      for (int m = 0; m < 8; ++m) v[m] = detail::parse_double(tok[m], path, line, kNames[m]);
      pose.timestamp = v[0];
      t_wc << v[1], v[2], v[3];
      const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
      const double n = q.norm();
      if (!(std::abs(n - 1.0) <= 1e-3)) {
        std::ostringstream os;
        os << "quaternion (qx qy qz qw) = (" << v[4] << " " << v[5] << " " << v[6] << " " << v[7]
           << ") has norm " << n << ", expected 1 (tolerance 1e-3)";
        detail::parse_error(path, line, os.str());
      }
      rot = lie::SO3d(q);
    }
    if (!traj.poses.empty()) {
      const TrajectoryPose& prev = traj.poses.back();
      if (traj.has_frame_index && !(pose.frame > prev.frame)) {
        detail::parse_error(path, line,
                            "frame index " + std::to_string(pose.frame) +
                                " does not increase (previous " + std::to_string(prev.frame) +
                                " on line " + std::to_string(prev.line) + ")");
      }
      if (traj.has_timestamps && !(pose.timestamp > prev.timestamp)) {
        std::ostringstream os;
        os << std::setprecision(17) << "timestamp " << pose.timestamp
           << " does not increase (previous " << prev.timestamp << " on line " << prev.line << ")";
        detail::parse_error(path, line, os.str());
      }
    }
    pose.T_cw = lie::SE3d(rot, t_wc).inverse();
    traj.poses.push_back(pose);
  }
  if (traj.poses.empty()) detail::parse_error(path, reader.line(), "no poses in trajectory file");
  return traj;
}

/// Writes a KITTI trajectory: one line of 12 numbers per pose (camera -> world [R | t] row-major,
/// shortest round-trip digits), optionally preceded by the frame index, after a '#' header line
/// stating the world frame, units and geodrift version.
/// @param path             output file, written atomically (temp file + rename).
/// @param traj             poses (T_cw in W).
/// @param frame_note       description of the world frame, e.g. "W = UTM 32N shifted to ...".
/// @param write_frame_index prefix each line with TrajectoryPose::frame (13 fields; evo reads
///                          only the 12-field form, so the default is false).
/// @param units            length unit stated in the header: "metres" in W; a VO or simulated
///                          map frame M passes kMapUnits.
/// @throws Error on I/O failure; InvalidArgument if a pose is not finite.
inline void write_trajectory_kitti(const std::string& path, const Trajectory& traj,
                                   const std::string& frame_note, bool write_frame_index = false,
                                   const std::string& units = "metres") {
  for (std::size_t i = 0; i < traj.poses.size(); ++i)
    GEODRIFT_CHECK(traj.poses[i].T_cw.matrix().allFinite(),
                   "write_trajectory_kitti: pose " << i << " is not finite");
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "# geodrift " << kVersion << " KITTI trajectory: camera-to-world poses T_wc as 3x4 [R|t] "
       << "row-major" << (write_frame_index ? " after a frame index" : "")
       << "; world frame: " << frame_note << "; units: " << units << "\n";
    for (const TrajectoryPose& p : traj.poses) {
      const Eigen::Matrix4d T = p.T_cw.inverse().matrix();
      if (write_frame_index) os << p.frame << ' ';
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 4; ++c) {
          os << detail::fmt(T(r, c));
          if (r != 2 || c != 3) os << ' ';
        }
      }
      os << '\n';
    }
  });
}

/// Writes a TUM trajectory "timestamp tx ty tz qx qy qz qw" (camera -> world, shortest exact
/// digits) after a '#' header line stating frame, units and version. When any timestamp is NaN
/// (a KITTI source), every pose's frame index is written as its timestamp and the header says so.
/// @throws Error on I/O failure; InvalidArgument if a pose is not finite.
inline void write_trajectory_tum(const std::string& path, const Trajectory& traj,
                                 const std::string& frame_note,
                                 const std::string& units = "metres") {
  bool all_timestamps = true;
  for (std::size_t i = 0; i < traj.poses.size(); ++i) {
    GEODRIFT_CHECK(traj.poses[i].T_cw.matrix().allFinite(),
                   "write_trajectory_tum: pose " << i << " is not finite");
    all_timestamps = all_timestamps && std::isfinite(traj.poses[i].timestamp);
  }
  detail::write_atomically(path, [&](std::ostream& os) {
    os << "# geodrift " << kVersion
       << " TUM trajectory: timestamp tx ty tz qx qy qz qw, camera-to-world poses T_wc; "
       << "world frame: " << frame_note << "; units: seconds, " << units
       << (all_timestamps ? "" : "; timestamps are frame indices (source had no timestamps)")
       << "\n";
    for (const TrajectoryPose& p : traj.poses) {
      const lie::SE3d T_wc = p.T_cw.inverse();
      const Eigen::Quaterniond& q = T_wc.rotation().quaternion();
      const Eigen::Vector3d& t = T_wc.translation();
      os << (all_timestamps ? detail::fmt(p.timestamp) : std::to_string(p.frame)) << ' '
         << detail::fmt(t.x()) << ' ' << detail::fmt(t.y()) << ' ' << detail::fmt(t.z()) << ' '
         << detail::fmt(q.x()) << ' ' << detail::fmt(q.y()) << ' ' << detail::fmt(q.z()) << ' '
         << detail::fmt(q.w()) << '\n';
    }
  });
}

}  // namespace geodrift::io
