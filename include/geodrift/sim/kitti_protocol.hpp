#pragma once

/// @file
/// The paper's KITTI protocol (Sec. 4.3, DESIGN.md "Evaluation"): the ground-truth path and
/// calibration of a KITTI odometry sequence, the anchor (geo-tagged image) schedule and the
/// paper's reference numbers. The simulator (drift_simulator.hpp) turns a KittiSequence into
/// what a monocular SLAM would output.
///
/// Conventions: KITTI poses are kept as read, T_K_c (cam0 -> KITTI world = cam0 of frame 0,
/// OpenCV camera axes, metres); geo/kitti.hpp maps them into W (E = x, N = z, U = −y). Times in
/// seconds; anchors are given by frame index.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/map/camera.hpp"

namespace geodrift::sim {

/// A KITTI odometry sequence's ground truth: per frame the time and the left grey camera (cam0)
/// pose T_K_c (camera -> KITTI world = cam0 of frame 0; x right, y down, z forward; metres), the
/// rectified camera (from P0) and the stereo baseline (from P1: b = −P1[0,3] / P1[0,0]).
struct KittiSequence {
  std::string name;                      ///< e.g. "02"
  std::vector<double> timestamps;        ///< seconds, one per frame
  std::vector<Eigen::Isometry3d> T_K_c;  ///< cam0 -> KITTI world, one per frame
  map::Camera camera;                    ///< id 0, 1241 x 376
  double baseline_m = 0.0;               ///< cam0 -> cam1 (right) distance along +x of cam0

  int num_frames() const { return static_cast<int>(T_K_c.size()); }
};

namespace detail {
inline std::vector<double> parse_numbers(const std::string& line, const std::string& path,
                                         int line_no) {
  std::istringstream is(line);
  std::vector<double> v;
  std::string tok;
  while (is >> tok) {
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || !std::isfinite(x))
      throw InvalidArgument(path + ":" + std::to_string(line_no) + ": '" + tok +
                            "' is not a finite number");
    v.push_back(x);
  }
  return v;
}
}  // namespace detail

/// Reads a KITTI sequence.
/// @param poses_path KITTI poses file, read by io::read_trajectory (kKitti): 12 numbers per line
///        (row-major [R|t] of cam0 -> KITTI world), or 13 with the frame time first (the egusa
///        "poses_with_times" layout) or an integer frame index first.
/// @param calib_path KITTI calib.txt (lines "P0: ..." and "P1: ..."; 12 numbers each).
/// @param times_path KITTI times.txt (one time per line); optional when the poses carry times;
///        without either, timestamps are frame · 0.1 s (KITTI's nominal 10 Hz; frame = the
///        leading frame index when the poses carry one, else the line order).
/// @throws Error if a file cannot be opened; InvalidArgument (with path:line) on malformed
///        content, a non-rotation block, times or frame indices that do not increase, or
///        mismatched counts.
inline KittiSequence load_kitti_sequence(const std::string& poses_path,
                                         const std::string& calib_path,
                                         const std::string& times_path = "",
                                         const std::string& name = "") {
  KittiSequence seq;
  seq.name = name;
  // Poses (and the time column, when present) through the project's one KITTI reader; it
  // re-orthonormalises the 7-digit rotations, so later inversions are exact.
  const io::Trajectory traj = io::read_trajectory(poses_path, io::TrajectoryFormat::kKitti);
  for (const io::TrajectoryPose& p : traj.poses) {
    seq.T_K_c.emplace_back(p.T_cw.inverse().matrix());
    if (traj.has_timestamps) seq.timestamps.push_back(p.timestamp);
  }
  if (!times_path.empty()) {
    std::ifstream in(times_path);
    if (!in) throw Error("cannot open KITTI times file " + times_path);
    seq.timestamps.clear();
    std::string line;
    int line_no = 0;
    while (std::getline(in, line)) {
      ++line_no;
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      const std::vector<double> v = detail::parse_numbers(line, times_path, line_no);
      GEODRIFT_CHECK(v.size() == 1,
                     times_path << ":" << line_no << ": " << v.size() << " numbers, expected 1");
      seq.timestamps.push_back(v[0]);
    }
    GEODRIFT_CHECK(seq.timestamps.size() == seq.T_K_c.size(),
                   times_path << ": " << seq.timestamps.size() << " times for " << seq.T_K_c.size()
                              << " poses");
  }
  if (seq.timestamps.empty())
    for (const io::TrajectoryPose& p : traj.poses) seq.timestamps.push_back(0.1 * p.frame);

  std::ifstream in(calib_path);
  if (!in) throw Error("cannot open KITTI calibration file " + calib_path);
  std::vector<double> P0, P1;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = line.substr(0, colon);
    if (key != "P0" && key != "P1") continue;
    std::vector<double> v = detail::parse_numbers(line.substr(colon + 1), calib_path, line_no);
    GEODRIFT_CHECK(v.size() == 12, calib_path << ":" << line_no << ": " << key << " has "
                                              << v.size() << " numbers, expected 12");
    (key == "P0" ? P0 : P1) = std::move(v);
  }
  GEODRIFT_CHECK(!P0.empty() && !P1.empty(), calib_path << ": P0 or P1 missing");
  seq.camera.id = 0;
  seq.camera.fx = P0[0];
  seq.camera.fy = P0[5];
  seq.camera.cx = P0[2];
  seq.camera.cy = P0[6];
  seq.camera.width = 1241;
  seq.camera.height = 376;
  seq.camera.validate();
  seq.baseline_m = -P1[3] / P1[0];
  GEODRIFT_CHECK(seq.baseline_m > 0,
                 calib_path << ": baseline " << seq.baseline_m << " m from P1 is not positive");
  return seq;
}

/// Reads sequence `seq` ("02", "08", ...) from the folder layout of
/// ../shared/data/kitti_odometry_gt: egusa_poses_with_times/<seq>.txt (time + pose) and
/// calib_seq00-02.txt (sequences 00-02) or calib_seq04-12.txt (04-12).
/// @throws InvalidArgument for sequence 03 (own calibration, not shipped) or a bad number;
///         Error if a file is missing.
inline KittiSequence load_kitti_sequence_from_dir(const std::string& gt_dir,
                                                  const std::string& seq) {
  int n = -1;
  try {
    n = std::stoi(seq);
  } catch (const std::exception&) {
    n = -1;
  }
  GEODRIFT_CHECK(n >= 0 && n <= 12 && n != 3,
                 "KITTI sequence '" << seq << "': only 00-02 and 04-12 have a calibration here");
  const std::string calib = gt_dir + (n <= 2 ? "/calib_seq00-02.txt" : "/calib_seq04-12.txt");
  return load_kitti_sequence(gt_dir + "/egusa_poses_with_times/" + seq + ".txt", calib, "", seq);
}

/// Default first anchors of the protocol: "we set geo-tagged images in the interval of 50
/// frames from the first to the 200th frame" (no map exists at frame 0).
inline const std::vector<int>& kitti_init_anchor_frames() {
  static const std::vector<int> frames{50, 100, 150, 200};
  return frames;
}

/// The anchor (geo-tagged image) frames of the KITTI protocol: the INIT frames, then one every
/// `interval` frames from last INIT frame + interval (200 + N), sorted, duplicates merged,
/// frames >= num_frames dropped.
/// @throws InvalidArgument if interval < 1 or num_frames < 1.
inline std::vector<int> kitti_anchor_frames(
    int num_frames, int interval,
    const std::vector<int>& init_frames = kitti_init_anchor_frames()) {
  GEODRIFT_CHECK(interval >= 1, "kitti_anchor_frames: interval " << interval << " must be >= 1");
  GEODRIFT_CHECK(num_frames >= 1,
                 "kitti_anchor_frames: num_frames " << num_frames << " must be >= 1");
  std::vector<int> f;
  int last = 0;
  for (int x : init_frames) {
    if (x >= 0 && x < num_frames) f.push_back(x);
    last = std::max(last, x);
  }
  for (long x = static_cast<long>(last) + interval; x < num_frames; x += interval)
    f.push_back(static_cast<int>(x));
  std::sort(f.begin(), f.end());
  f.erase(std::unique(f.begin(), f.end()), f.end());
  return f;
}

/// The paper's global Sim(3) error of ORB-SLAM's keyframe path (Sec. 4.3): 20.15 m on 02,
/// 25.12 m on 08; NaN for other sequences.
inline double paper_global_sim3_error_m(const std::string& seq) {
  if (seq == "02") return 20.15;
  if (seq == "08") return 25.12;
  return std::numeric_limits<double>::quiet_NaN();
}

/// The paper's Table 2 ("Ours", mean 2D error in metres) for geo-tag intervals 100..500 on 02
/// and 08; empty for other sequences.
inline std::vector<double> paper_ours_2d_error_m(const std::string& seq) {
  if (seq == "02") return {2.27, 2.51, 4.87, 6.89, 12.35};
  if (seq == "08") return {0.50, 2.06, 2.84, 4.19, 6.38};
  return {};
}

}  // namespace geodrift::sim
