#pragma once

/// @file
/// Places where an input trajectory jumps: two consecutive poses whose camera centres are far
/// further apart than the path's own speed around them allows. A monocular SLAM that loses
/// tracking and starts a new map (ORB-SLAM's Atlas, a DSO reset, two COLMAP models written one
/// after the other) continues in a new frame with a new unit: its first pose lands near the new
/// map's origin, so the camera seems to leap across the old map. A Sim(3) pose graph across
/// such a step bends the whole path to absorb it (a 60 m reset in the middle of a 2 km
/// stretch of our own VO, anchors every 100 frames: 7.1 m mean and 62 m maximum 2D error
/// against 0.16 m without it, and a correct anchor blamed for it).
///
/// The test is unit-free: the speed of each step (camera-centre distance over the time between
/// the poses: seconds where the file has increasing timestamps, else frame numbers, else poses)
/// against the larger of the median speed of the steps around it and the median speed of the
/// whole path. A vehicle or a hand-held camera cannot change speed tenfold from one pose to the
/// next (KITTI 02 and 08 ground truth at 10 Hz, our VO's frames and keyframes on four rendered
/// stretches, a 1M-pose synthetic drive: at most 1.41×), while a gap in time (tracking lost,
/// then relocalized in the SAME map) divides a long step by a long time and is not a jump.
/// Between kSuspectJumpRatio and the jump ratio a step is suspect: worth a warning, not a
/// refusal. What it cannot see: a new map whose origin happens to lie within a few steps of the
/// old path (the unit and the frame change without a leap).

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/io/trajectory.hpp"
#include "geodrift/map/keyframe.hpp"

namespace geodrift::io {

/// One jump: from poses[index] to poses[index + 1].
struct TrajectoryJump {
  std::size_t index = 0;
  double step = 0.0;           ///< camera-centre distance (the file's units)
  double dt = 0.0;             ///< time between the poses (seconds, frames or poses: time_unit)
  double speed = 0.0;          ///< step / dt
  double typical_speed = 0.0;  ///< the larger of the local and the whole path's median speed
  double ratio = 0.0;          ///< speed / typical_speed
  const char* time_unit = "";  ///< dt's unit: trajectory_time_unit()
};

/// A step this many times faster than the path around it is suspect (`geodrift correct` warns):
/// 2.8× the largest ratio of the real paths above, and a 20 m leap in the middle of our 2 km
/// VO stretch (8.6×) is one.
inline constexpr double kSuspectJumpRatio = 4.0;

struct TrajectoryJumpOptions {
  int window = 25;          ///< steps on each side for the local median speed
  double max_ratio = 10.0;  ///< a step faster than this × the typical speed is a jump
};

/// The time base the jump test used: "s" (increasing timestamps), "frames" (increasing frame
/// numbers) or "poses" (neither).
inline const char* trajectory_time_unit(const Trajectory& t) {
  const auto increasing = [&](auto value) {
    for (std::size_t i = 1; i < t.poses.size(); ++i) {
      const double a = value(t.poses[i - 1]), b = value(t.poses[i]);
      if (!(std::isfinite(a) && std::isfinite(b) && b > a)) return false;
    }
    return true;
  };
  if (t.has_timestamps && increasing([](const TrajectoryPose& p) { return p.timestamp; }))
    return "s";
  if (increasing([](const TrajectoryPose& p) { return static_cast<double>(p.frame); }))
    return "frames";
  return "poses";
}

/// Every jump of `t` (see the file comment), in path order. O(n) plus a local median per step
/// that is faster than max_ratio × the whole path's median (the only ones that can be jumps).
/// A path whose median speed is zero (mostly standing still) reports none. Steps to or from a
/// camera centre beyond map::kMaxMapCoordinate are left out (not a jump: a value the
/// correction refuses by itself, naming it).
inline std::vector<TrajectoryJump> find_trajectory_jumps(const Trajectory& t,
                                                         const TrajectoryJumpOptions& o = {}) {
  std::vector<TrajectoryJump> jumps;
  const std::size_t n = t.poses.size();
  if (n < 3) return jumps;
  const char* unit = trajectory_time_unit(t);
  const bool seconds = unit[0] == 's', frames = unit[0] == 'f';
  // Each camera centre once (a step uses two); NaN where it is not representable.
  std::vector<Eigen::Vector3d> centre(n);
  for (std::size_t i = 0; i < n; ++i) {
    centre[i] = t.poses[i].T_cw.inverse().translation();
    if (!(centre[i].allFinite() && centre[i].cwiseAbs().maxCoeff() <= map::kMaxMapCoordinate))
      centre[i].setConstant(std::numeric_limits<double>::quiet_NaN());
  }
  const auto step = [&](std::size_t i) {  // poses i -> i + 1; NaN from a centre left out
    return (centre[i + 1] - centre[i]).norm();
  };
  const auto dt = [&](std::size_t i) {
    const TrajectoryPose &a = t.poses[i], &b = t.poses[i + 1];
    return seconds  ? b.timestamp - a.timestamp
           : frames ? static_cast<double>(b.frame - a.frame)
                    : 1.0;
  };
  std::vector<double> speed(n - 1), all;  // all: the finite speeds
  all.reserve(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    speed[i] = step(i) / dt(i);
    if (std::isfinite(speed[i])) all.push_back(speed[i]);
  }
  if (all.empty()) return jumps;
  const auto median = [](std::vector<double> v) {
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
  };
  const double global = median(std::move(all));
  if (!(global > 0.0)) return jumps;
  const std::size_t m = speed.size(), w = static_cast<std::size_t>(std::max(o.window, 1));
  std::vector<double> around;
  for (std::size_t i = 0; i < m; ++i) {
    if (!(speed[i] > o.max_ratio * global)) continue;
    around.clear();
    for (std::size_t k = i > w ? i - w : 0; k < std::min(m, i + w + 1); ++k)
      if (k != i && std::isfinite(speed[k])) around.push_back(speed[k]);
    const double typical = std::max(global, around.empty() ? 0.0 : median(around));
    if (speed[i] > o.max_ratio * typical)
      jumps.push_back({i, step(i), dt(i), speed[i], typical, speed[i] / typical, unit});
  }
  return jumps;
}

/// "between lines 321 and 322 (frames 1064 and 1065): 31.2 units in 1 frame(s), 212× the
/// path's speed around it"; lines are the file's when it was read from one.
inline std::string describe_jump(const Trajectory& t, const TrajectoryJump& j) {
  const TrajectoryPose &a = t.poses[j.index], &b = t.poses[j.index + 1];
  const std::string unit = j.time_unit;
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "between lines %d and %d (frames %d and %d): %.4g units in %.4g %s, %.3g x the "
                "path's speed around it",
                a.line, b.line, a.frame, b.frame, j.step, j.dt,
                unit == "s"        ? "s"
                : unit == "frames" ? "frame(s)"
                                   : "pose(s)",
                j.ratio);
  return buf;
}

}  // namespace geodrift::io
