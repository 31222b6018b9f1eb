#pragma once

/// @file
/// How a monocular VO errs between two keyframes, as the information of the Sim(3) pose-graph
/// edges (the Corrector's e1 keyframe–keyframe and e2 keyframe–geo-view edges). The derivation
/// and the meaning of every number are in docs/correction_model.md.
///
/// An edge's residual r = log(ΔS_ij · S_i · S_j⁻¹) ∈ sim(3) has the tangent order (ω, σ, ν)
/// (DESIGN.md): ω rotation (rad), σ log-scale (dimensionless), ν translation in MAP units (the
/// front end's arbitrary unit, s map units per metre). Every standard deviation below is
/// physical — radians, a relative scale error, metres — and is converted to map units with the
/// edge's own length measured in the map, so the information, and with it the corrected path,
/// does not depend on the map's unit, origin or orientation (issue 24, DESIGN.md
/// "Correction" 5). The paper's weighting (λ1 = λ2 = 1e5 on all seven components, in map units)
/// weighs a map unit of translation against a radian and a unit of log-scale, so its result
/// changes with the map's unit; it stays available as CorrectorOptions::EdgeWeights::kPaper
/// (kPaperMetric, the default, keeps λ on rotation and log-scale and gives e1's translation
/// this model's direction error, direction_sd_rad · d).

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <string>

namespace geodrift::correction {

/// A monocular VO's relative-pose uncertainty between two keyframes d metres apart that turned
/// by θ radians:
///
///     var(ω_x) = var(ω_y) = var(ω_z) = q_r²·d + (f_r·θ)²        (rad²)
///     var(σ)                         = q_s²·d + (f_s·θ)²        (log-scale²)
///     var(ν_x) = var(ν_y) = var(ν_z) = (a_t·d)²                 (metres², then map units²)
///
/// with d ≥ min_distance_m. The random-walk terms grow with the distance travelled (a VO adds
/// an independent rotation and scale error at each keyframe it triangulates from, so errors add
/// in variance along the path); the turn terms are what a monocular VO loses in turns, where
/// new points are triangulated from a short baseline against a large rotation (scale) and the
/// rotation itself is estimated from few tracked points; the translation term is the error of
/// the direction of motion, a fixed angle a_t of the step.
struct DriftModel {
  /// q_s: log-scale random walk per √metre. 0.01/√m: a VO re-scales at every keyframe it
  /// triangulates new points from (about every 3 m on a car), each with a ~1.5 % depth error,
  /// so q_s² ≈ 0.015²/3 m; the same as a real KITTI monocular VO's window-to-window scale
  /// roughness (SD 0.07 between 50-frame, ~50 m windows: 0.07/√50 = 0.0099).
  double scale_walk_per_sqrt_m = 0.01;
  /// q_r: rotation random walk per √metre, per axis (rad/√m). 1e-3: about 0.06° per 3 m
  /// keyframe step, 0.6° over 100 m of straight road.
  double rotation_walk_per_sqrt_m = 1e-3;
  /// f_r: rotation error as a fraction of the turn angle (2 %: 1.8° in a 90° turn).
  double turn_rotation_fraction = 0.02;
  /// f_s: log-scale error per radian turned (0.1: a 90° turn re-scales the map by ~16 %, 1 SD).
  double turn_scale_per_rad = 0.1;
  /// a_t: error of the direction of motion (rad); lateral SD a_t·d of a step of d metres.
  double direction_sd_rad = 0.01;
  /// Floor of d (metres): a stationary pair still has the VO's per-keyframe noise.
  double min_distance_m = 0.1;

  bool validate(std::string* why) const {
    auto bad = [](double v) { return !(v >= 0 && std::isfinite(v)); };
    const char* what = nullptr;
    if (bad(scale_walk_per_sqrt_m)) what = "scale_walk_per_sqrt_m";
    if (bad(rotation_walk_per_sqrt_m)) what = "rotation_walk_per_sqrt_m";
    if (bad(turn_rotation_fraction)) what = "turn_rotation_fraction";
    if (bad(turn_scale_per_rad)) what = "turn_scale_per_rad";
    if (bad(direction_sd_rad) || direction_sd_rad == 0) what = "direction_sd_rad (> 0)";
    if (bad(min_distance_m) || min_distance_m == 0) what = "min_distance_m (> 0)";
    if (!what && !(rotation_walk_per_sqrt_m > 0 || turn_rotation_fraction > 0))
      what = "rotation_walk_per_sqrt_m or turn_rotation_fraction (one must be > 0)";
    if (!what && !(scale_walk_per_sqrt_m > 0 || turn_scale_per_rad > 0))
      what = "scale_walk_per_sqrt_m or turn_scale_per_rad (one must be > 0)";
    if (what && why) *why = std::string("DriftModel::") + what + " must be finite and >= 0";
    return what == nullptr;
  }

  /// Standard deviations (ω, σ, ν) of an edge between keyframes `length_map` map units apart
  /// that turned by `turn_rad`, at `map_per_metre` map units per metre (the current estimate of
  /// the local scale). ν's SD is in map units.
  Eigen::Matrix<double, 7, 1> sd(double length_map, double turn_rad, double map_per_metre) const {
    const double d = std::max(length_map / map_per_metre, min_distance_m);
    const double r = std::sqrt(rotation_walk_per_sqrt_m * rotation_walk_per_sqrt_m * d +
                               std::pow(turn_rotation_fraction * turn_rad, 2));
    const double s = std::sqrt(scale_walk_per_sqrt_m * scale_walk_per_sqrt_m * d +
                               std::pow(turn_scale_per_rad * turn_rad, 2));
    const double t = direction_sd_rad * d * map_per_metre;
    Eigen::Matrix<double, 7, 1> out;
    out << r, r, r, s, t, t, t;
    return out;
  }

  /// The edge's information matrix (diagonal, 1/sd²), in the residual's (ω, σ, ν) order.
  Eigen::Matrix<double, 7, 7> information(double length_map, double turn_rad,
                                          double map_per_metre) const {
    const Eigen::Matrix<double, 7, 1> v = sd(length_map, turn_rad, map_per_metre);
    return v.array().square().inverse().matrix().asDiagonal();
  }
};

}  // namespace geodrift::correction
