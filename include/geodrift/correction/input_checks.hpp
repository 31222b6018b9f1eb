#pragma once

/// @file
/// Plausibility of a correction's outcome, for input mistakes that no single file shows: each
/// file parses, every anchor lies inside the trajectory, and yet the two do not belong together
/// the way the user meant.
///
/// ## Anchors that are a mirror image of the path
/// Latitude and longitude swapped (GeoJSON's order is longitude, latitude), easting and
/// northing swapped, or x and y: the anchors are then the path's mirror image. A similarity
/// cannot mirror, but a Sim(3) pose graph can turn the path over (a plane mirrored in itself is
/// the plane rotated by 180° about an axis in it), so the correction fits such anchors and puts
/// every camera upside down. INIT levels the map with the cameras upright (their −y axis, the
/// image's up, towards W's up), so a result with the cameras upside down at most keyframes was
/// turned over by the anchors. A camera mounted upside down does the same with correct anchors
/// (rare; the CLI's --allow-upside-down). A trajectory in OpenGL's camera axes (y up, z
/// backwards) also reads as upside down, but it moves along −z, which a camera in OpenCV's
/// axes (x right, y down, z forward) driving forwards does not: only a path whose camera moves
/// forwards (+z) counts.
///
/// ## Drift no VO has
/// Two figures, both unit-free, each with an innocent explanation of its own, and only together
/// a sign that the path and the anchors do not belong together:
///   - k, the data's drift variance relative to the drift model, as the screening
///     (screening.hpp) estimates it from how well the anchors predict each other along the path.
///     The model's nominal figures are generous (a log-scale random walk of 0.01/√m: 10 % scale
///     SD over 100 m, drift_model.hpp): k stayed at or below 1.7 on our VO's stretches (with
///     30 % of the anchors 20–60 m off too) and 3–13 on the simulator's 02 and 08. But it also
///     grows with anchors worse than their sigma_m, or in another clock, where they are dense:
///     predicted from neighbours a few tens of metres away an anchor has a small SD. On a
///     driftless KITTI 02 path, anchors every second with 3 m of noise stated as 0.3 m gave
///     k = 8,534, a 0.7 s clock offset 161.
///   - the spread of the corrected keyframes' Sim(3) scales, their 95th percentile over their
///     5th: how much more the correction had to stretch the path in one place than in
///     another. A monocular VO's scale drifts by a factor of 2–3 over kilometres without loop
///     closure; our VO's stretches gave at most 1.46, the simulator 1.24–1.27, and noisy
///     anchors or an offset clock bend the path, not its scale (1.27 and 1.11 above).
/// Both above their bounds (k > 100: the path 10× less smooth, in SD, than the model's generous
/// nominal; spread > 10) say that the path's shape is not the anchors': world-to-camera poses
/// read as camera-to-world (the centres then trace −R·c, another curve: k = 460 and a spread of
/// 17.2 on KITTI 02, 1,385 and 68.8 on our VO's 02 stretch), anchors of another run or place,
/// poses out of order.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "geodrift/lie/se3.hpp"

namespace geodrift::correction {

/// Bounds of "Drift no VO has" (file comment): the drift variance factor (data / drift model)
/// and the spread (95th over 5th percentile) of the corrected keyframes' scales.
constexpr double kMaxPlausibleDriftFactor = 100.0;
constexpr double kMaxPlausibleScaleSpread = 10.0;

/// The 95th percentile of `scales` over their 5th (positive values; NaN for fewer than 2).
inline double scale_spread(std::vector<double> scales) {
  if (scales.size() < 2) return NAN;
  std::sort(scales.begin(), scales.end());
  const std::size_t n = scales.size() - 1;
  const double lo = scales[n * 5 / 100], hi = scales[n - n * 5 / 100];
  return lo > 0 ? hi / lo : NAN;
}

/// True when a drift variance factor `k` and a scale spread together exceed what a monocular
/// VO does (see the file comment); false when either is NaN.
inline bool implausible_drift(double k, double spread) {
  return k > kMaxPlausibleDriftFactor && spread > kMaxPlausibleScaleSpread;
}

/// How the cameras of a corrected path are oriented in W (z up).
struct CameraAttitude {
  int keyframes = 0;
  /// Keyframes whose image-down axis (camera +y) points up: more than 60° from W's down, on the
  /// upper side (its W z component > 0.5).
  int upside_down = 0;
  int moving = 0;   ///< steps to the next keyframe longer than 1e-9 of the path's extent
  int forward = 0;  ///< of those, steps within 60° of the camera's +z axis
  /// Most cameras upside down (> 80 %) while the camera moves forwards along +z (> 50 % of the
  /// steps): the signature of anchors mirrored against the path (see the file comment).
  bool turned_over() const {
    return keyframes > 0 && upside_down > 0.8 * keyframes && moving > 0 && forward > 0.5 * moving;
  }
};

/// The attitude of keyframe poses T_cw in W (camera from world, W z up), in path order.
inline CameraAttitude camera_attitude(const std::vector<lie::SE3d>& T_cw) {
  CameraAttitude out;
  out.keyframes = static_cast<int>(T_cw.size());
  std::vector<Eigen::Vector3d> c(T_cw.size());
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo;
  for (std::size_t i = 0; i < T_cw.size(); ++i) {
    c[i] = T_cw[i].inverse().translation();
    lo = lo.cwiseMin(c[i]);
    hi = hi.cwiseMax(c[i]);
  }
  const double extent = T_cw.empty() ? 0.0 : (hi - lo).norm();
  for (std::size_t i = 0; i < T_cw.size(); ++i) {
    const Eigen::Matrix3d R_cw = T_cw[i].rotation().matrix();
    // The camera's +y axis in W is the second row of R_cw.
    if (R_cw(1, 2) > 0.5) ++out.upside_down;
    if (i + 1 < T_cw.size()) {
      const Eigen::Vector3d d = c[i + 1] - c[i];
      if (d.norm() > 1e-9 * extent && d.norm() > 0) {
        ++out.moving;
        if ((R_cw * d).z() > 0.5 * d.norm()) ++out.forward;
      }
    }
  }
  return out;
}

}  // namespace geodrift::correction
