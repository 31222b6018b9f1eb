#pragma once

/// @file
/// The monocular-drift simulator (issue 4, DESIGN.md "KITTI protocol"): from a KITTI ground-truth
/// path it produces what a monocular ORB-SLAM would hand to the Corrector — keyframes, map
/// points on building facades and the road, their observations (covisibility follows from
/// them) — all in a drifting map frame M, plus the geo views (right camera at its true pose)
/// localised in that drifted map by PnP + LM, as map::Correspondence.
///
/// Drift model. Every keyframe k has a similarity S_k : KITTI world (metres) -> M, the map's
/// local "view" of the world at that keyframe:
///
///     S_k = T^M_wc(k) ∘ Scale(s_k) ∘ T_k⁻¹        (T_k: true cam0 -> KITTI world)
///
/// where the drifted keyframe poses are chained from the true relative motions with a scale
/// and a rotation error, as a monocular SLAM chains them:
///
///     T^M_wc(k+1) = T^M_wc(k) · [ Exp(δω_k)·R_rel,k | s_{k+1}·t_rel,k ],    T^M_wc(0) = I,
///     log s_k = log s_0 + β·w_k + o_k,     δω_k = γ·(q ⊙ √Δd_k·n_k + c·θ_k·n'_k).
///
/// w is a random walk in log-scale (per √metre travelled), o an Ornstein–Uhlenbeck process
/// (stationary SD, correlation length in metres) giving the window-to-window roughness a real
/// monocular VO shows, δω_k a rotation error made of a random walk increment (q per √metre,
/// about the camera's x = pitch, y = yaw, z = roll axes; Δd_k the true step length) and a part
/// proportional to the true rotation θ_k of the step (c = turn_rotation_error: monocular VO
/// loses heading mostly in turns); n, n' standard normal. Drift accrues per metre, so a stopped
/// vehicle does not drift (nor make keyframes). The amplitudes β (scale walk) and γ (rotation walk)
/// are 1 unless calibration targets are set (the KITTI defaults set both), in which case, for the
/// drawn realisation, bisection finds
///   1. β so that the normalised 50-frame-window scale SD equals target_window_scale_sd
///      (rotation does not change distances, so this is independent of γ), then
///   2. γ so that the uncorrected path's global Sim(3) error (DESIGN.md) equals
///      target_global_sim3_error_m; if the scale drift alone already exceeds it, γ = 0 and β is
///      lowered to meet it instead (stated in SimulatedSequence::message).
/// This calibrates the drift against the paper's ORB-SLAM figures and a real monocular VO's
/// roughness, i.e. against the UNCORRECTED path only, never against correction accuracy.
///
/// Map consistency. A map point is created by (and referenced to) the first keyframe r that
/// sees it. It is placed at the mean of S_k(X) over the keyframes k that see it (as a local BA
/// triangulates it from its whole track; with S_k constant along the track this is S_r(X)).
/// A keyframe k observes it when it is within range and in view both in reality and in the
/// drifted map; the pixel is the projection of X_M in the drifted keyframe plus pixel noise, so
/// the map is self-consistent the way a converged local BA leaves it (reprojection errors at
/// the noise level) while the path drifts.
///
/// Geo views (KITTI protocol). The geo-tagged image of frame f is the RIGHT camera (cam0
/// shifted by the calibrated baseline along +x) at its true pose. It is matched to the keyframe
/// nearest in time; the map points that keyframe observes and the right camera really sees are
/// projected with the TRUE geometry plus pixel noise, and the view pose in M is solved by LM on
/// the reprojection error against the DRIFTED map points (the paper's PnP + LM), starting from
/// the keyframe's pose, with inlier selection as RANSAC would do it (gate: max(2.45 σ_px,
/// 3 × median error)). The view therefore inherits the local scale and inconsistency of the
/// map: its centre lies typically 0.15-0.4 m (in metres of the drifted frame) from where the
/// keyframe's own drift would put it, more in sharp turns. Its geo-tag is the true
/// right-camera centre in W plus geo-tag noise (RTK: 5 cm).
///
/// Scene. Points on facades (blocks of 15-45 m, 4-16 m off the path, ground to 9 m, both
/// sides, some gaps), on the road (±8 m) and scattered between (trees, cars); a keyframe that
/// would see fewer than min_points_per_keyframe of them (path ends, a road climbing out of the
/// field of view at the start of 08) gets extra points in its own view.
///
/// Everything is deterministic for a seed; independent streams are used for the drift, the
/// scene, the keyframe pixel noise and each geo view (seeded by its frame), so a geo view at
/// frame f is the same whatever the anchor schedule.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "geodrift/correction/pose_refinement.hpp"
#include "geodrift/error.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/eval/scale_factor.hpp"
#include "geodrift/geo/kitti.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/so3.hpp"
#include "geodrift/map/map.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

namespace geodrift::sim {

/// How the simulated monocular SLAM drifts. The defaults are the committed calibration (see
/// the file comment and the sim tests, which print the resulting statistics); they were fixed
/// from the uncorrected-path targets only (global Sim(3) error and window-scale roughness).
struct DriftParams {
  /// Random walk of the log-scale, per √metre travelled (before the amplitude β).
  double scale_random_walk = 2.5e-3;
  /// Stationary SD of the fast (Ornstein–Uhlenbeck) log-scale fluctuation (not calibrated).
  double scale_fluctuation_sd = 0.08;
  /// Correlation length of that fluctuation, metres travelled.
  double scale_fluctuation_length_m = 25.0;
  /// Rotation random walk per √metre (rad/√m) about cam x (pitch), y (yaw), z (roll), before γ.
  Eigen::Vector3d rotation_random_walk = Eigen::Vector3d(2.0e-4, 5.0e-4, 2.0e-4);
  /// Rotation error proportional to the true rotation between consecutive keyframes (SD as a
  /// fraction of its angle, per axis, before γ): monocular VO loses heading mostly in turns.
  double turn_rotation_error = 0.05;
  /// If > 0: β is solved so that the normalised scale of the uncorrected path over 50-frame
  /// windows has this SD (eval::windowed_scale_statistics). If <= 0: β = 1.
  double target_window_scale_sd = 0.0;
  /// If > 0: γ is solved so that the uncorrected keyframes' global Sim(3) error (mean 2D error
  /// after Umeyama Sim(3) alignment to ground truth) equals this many metres. If <= 0: γ = 1.
  double target_global_sim3_error_m = 0.0;
  /// Map units per metre at keyframe 0 (a monocular map's arbitrary initial scale; ORB-SLAM
  /// normalises the median scene depth to 1, i.e. about 1/10 on KITTI).
  double initial_map_scale = 0.1;

  /// No drift at all: the map is the true world scaled by initial_map_scale.
  static DriftParams none() {
    DriftParams p;
    p.scale_random_walk = 0.0;
    p.scale_fluctuation_sd = 0.0;
    p.rotation_random_walk.setZero();
    p.turn_rotation_error = 0.0;
    p.target_global_sim3_error_m = 0.0;
    p.target_window_scale_sd = 0.0;
    return p;
  }
  /// @throws InvalidArgument naming the first bad field.
  void validate() const {
    GEODRIFT_CHECK(scale_random_walk >= 0 && std::isfinite(scale_random_walk),
                   "DriftParams::scale_random_walk " << scale_random_walk << " must be >= 0");
    GEODRIFT_CHECK(scale_fluctuation_sd >= 0 && std::isfinite(scale_fluctuation_sd),
                   "DriftParams::scale_fluctuation_sd " << scale_fluctuation_sd << " must be >= 0");
    GEODRIFT_CHECK(scale_fluctuation_length_m > 0, "DriftParams::scale_fluctuation_length_m "
                                                       << scale_fluctuation_length_m
                                                       << " must be > 0");
    GEODRIFT_CHECK(rotation_random_walk.allFinite() && rotation_random_walk.minCoeff() >= 0,
                   "DriftParams::rotation_random_walk (" << rotation_random_walk.transpose()
                                                         << ") must be >= 0");
    GEODRIFT_CHECK(turn_rotation_error >= 0 && std::isfinite(turn_rotation_error),
                   "DriftParams::turn_rotation_error " << turn_rotation_error << " must be >= 0");
    GEODRIFT_CHECK(std::isfinite(target_global_sim3_error_m),
                   "DriftParams::target_global_sim3_error_m must be finite");
    GEODRIFT_CHECK(initial_map_scale > 0 && std::isfinite(initial_map_scale),
                   "DriftParams::initial_map_scale " << initial_map_scale << " must be > 0");
  }
};

/// The street scene and the SLAM's keyframe / visibility behaviour.
struct SceneParams {
  double facade_points_per_metre = 3.5;  ///< per side of the road, per metre of path
  double facade_min_offset_m = 4.0;      ///< lateral distance of a facade from the camera path
  double facade_max_offset_m = 16.0;
  double facade_block_min_m = 15.0;  ///< buildings come in blocks of this length range ...
  double facade_block_max_m = 45.0;
  double facade_gap_probability = 0.2;  ///< ... and a block is empty (gap) with this probability
  double facade_height_m = 9.0;         ///< facade points from the ground up to this height
  double facade_depth_jitter_m = 0.3;   ///< SD of point offsets normal to the facade
  double ground_points_per_metre = 2.0;
  /// Scattered points (trees, cars, poles) between road and facades, both sides.
  double clutter_points_per_metre = 1.5;
  double clutter_max_offset_m = 25.0;
  double clutter_height_m = 4.0;
  double ground_half_width_m = 8.0;    ///< road/pavement points within this lateral distance
  double camera_height_m = 1.65;       ///< KITTI cam0 above the ground
  double min_depth_m = 1.0;            ///< observed when depth >= this ...
  double max_range_m = 30.0;           ///< ... and distance <= this
  int min_observations = 2;            ///< points seen by fewer keyframes are culled (as ORB-SLAM)
  int min_points_per_keyframe = 80;    ///< fewer visible scene points: extra ones are added
  int keyframe_min_gap = 2;            ///< frames between keyframes, uniform in [min, max] ...
  int keyframe_max_gap = 4;            ///< ("about one frame in three")
  double keyframe_min_motion_m = 0.3;  ///< ... and no keyframe until the camera moved this much

  /// @throws InvalidArgument naming the first bad field.
  void validate() const {
    GEODRIFT_CHECK(facade_points_per_metre >= 0 && ground_points_per_metre >= 0 &&
                       clutter_points_per_metre >= 0 && clutter_max_offset_m > 3.0,
                   "SceneParams: point densities must be >= 0");
    GEODRIFT_CHECK(facade_min_offset_m > 0 && facade_max_offset_m >= facade_min_offset_m,
                   "SceneParams: facade offsets [" << facade_min_offset_m << ", "
                                                   << facade_max_offset_m << "] invalid");
    GEODRIFT_CHECK(facade_block_min_m > 0 && facade_block_max_m >= facade_block_min_m,
                   "SceneParams: facade block lengths invalid");
    GEODRIFT_CHECK(
        facade_gap_probability >= 0 && facade_gap_probability < 1,
        "SceneParams::facade_gap_probability " << facade_gap_probability << " outside [0, 1)");
    GEODRIFT_CHECK(min_depth_m > 0 && max_range_m > min_depth_m,
                   "SceneParams: range [" << min_depth_m << ", " << max_range_m << "] invalid");
    GEODRIFT_CHECK(keyframe_min_gap >= 1 && keyframe_max_gap >= keyframe_min_gap,
                   "SceneParams: keyframe gaps [" << keyframe_min_gap << ", " << keyframe_max_gap
                                                  << "] invalid");
    GEODRIFT_CHECK(min_observations >= 1,
                   "SceneParams::min_observations " << min_observations << " must be >= 1");
  }
};

/// SD of the normalised 50-frame-window scale of a real monocular VO on KITTI (issue 4).
inline constexpr double kKittiWindowScaleSd = 0.08;

/// All simulator settings.
struct SimOptions {
  DriftParams drift;
  SceneParams scene;
  double pixel_noise_px = 1.0;   ///< SD of keyframe and geo-view pixel noise (per axis)
  double geotag_noise_m = 0.05;  ///< SD of geo-tag positions (per axis; RTK as in the paper)
  int min_geo_view_points = 12;  ///< a geo view with fewer matched points is not localised
  unsigned seed = 1;
  int first_frame = 0;  ///< simulate frames [first_frame, last_frame) (a stretch of the path)
  int last_frame = std::numeric_limits<int>::max();

  /// The committed KITTI defaults for sequence `seq`: drift calibrated to the paper's ORB-SLAM
  /// global Sim(3) error of that sequence (20.15 m on 02, 25.12 m on 08; γ = 1 elsewhere)
  /// and to the roughness of a real monocular VO on KITTI (window scale SD 0.08).
  /// elsewhere).
  static SimOptions kitti(const std::string& seq, unsigned seed) {
    SimOptions o;
    o.seed = seed;
    const double target = paper_global_sim3_error_m(seq);
    o.drift.target_global_sim3_error_m = std::isfinite(target) ? target : 0.0;
    o.drift.target_window_scale_sd = kKittiWindowScaleSd;
    return o;
  }
  /// No drift and no noise (keyframe pixels, geo-view pixels, geo-tags): the map is an exact
  /// similarity of the world.
  static SimOptions noise_free(unsigned seed = 1) {
    SimOptions o;
    o.seed = seed;
    o.drift = DriftParams::none();
    o.pixel_noise_px = 0.0;
    o.geotag_noise_m = 0.0;
    return o;
  }
};

/// A similarity p -> s·R·p + t.
struct Similarity {
  double s = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return s * (R * p) + t; }
};

/// The simulator's output: the drifted reconstruction plus everything needed to evaluate it.
struct SimulatedSequence {
  /// The monocular SLAM output in M: camera 0 (KITTI intrinsics), keyframes (ids 0..n-1 in time
  /// order), points (ids 0..m-1, reference keyframe = creator), observations.
  map::Map map;
  std::vector<Eigen::Vector3d> gt_center_w;    ///< true cam0 centre of each keyframe in W
  std::vector<Eigen::Isometry3d> gt_T_K_c;     ///< true pose of each keyframe (cam0 -> KITTI)
  std::vector<Similarity> warp;                ///< S_k (KITTI world -> M) of each keyframe
  std::vector<Eigen::Vector3d> point_truth_K;  ///< true position of each map point (KITTI)
  double scale_drift_amplitude = 1.0;     ///< β actually used (multiplies the scale random walk)
  double rotation_drift_amplitude = 1.0;  ///< γ actually used (multiplies the rotation walk)
  bool calibrated = true;  ///< false when a calibration target could not be reached (message)
  std::string message;
  KittiSequence sequence;  ///< the input (all frames), for geo views and evaluation
  SimOptions options;

  /// Uncorrected keyframe centres in M, keyframe order.
  std::vector<Eigen::Vector3d> keyframe_centers_m() const {
    std::vector<Eigen::Vector3d> c;
    c.reserve(map.keyframes.size());
    for (const auto& k : map.keyframes) c.push_back(k.center());
    return c;
  }
  /// Frame index of each keyframe.
  std::vector<int> keyframe_frames() const {
    std::vector<int> f;
    f.reserve(map.keyframes.size());
    for (const auto& k : map.keyframes) f.push_back(k.frame_index);
    return f;
  }
  /// Index of the keyframe nearest in frame index to `frame` (ties -> the earlier one).
  int nearest_keyframe(int frame) const {
    const auto& kfs = map.keyframes;
    GEODRIFT_CHECK(!kfs.empty(), "nearest_keyframe: no keyframes");
    auto it = std::lower_bound(kfs.begin(), kfs.end(), frame,
                               [](const map::Keyframe& k, int f) { return k.frame_index < f; });
    if (it == kfs.end()) return static_cast<int>(kfs.size()) - 1;
    int i = static_cast<int>(it - kfs.begin());
    if (i > 0 && frame - kfs[i - 1].frame_index <= kfs[i].frame_index - frame) --i;
    return i;
  }
};

/// One geo view of the KITTI protocol and how its localisation went.
struct GeoView {
  int frame = -1;          ///< video frame of the geo-tagged (right-camera) image
  bool localized = false;  ///< false: too few matched points (see `failure`)
  std::string failure;
  map::Correspondence correspondence;  ///< valid when localized
  lie::SE3d T_vw;                      ///< solved view pose in M (M -> right camera)
  Eigen::Vector3d center_true_w = Eigen::Vector3d::Zero();  ///< true right-camera centre, W
  /// |c_solved − S_K(c_true)| / s_K: the localisation error in the drifted frame, in metres,
  /// where S_K is the warp of the keyframe it was localised against.
  double position_error_m = std::numeric_limits<double>::quiet_NaN();
  int points = 0;  ///< matched map points (before inlier selection)
};

namespace detail {

inline lie::SE3d to_se3(const Eigen::Isometry3d& T) {
  return lie::SE3d(lie::SO3d(Eigen::Matrix3d(T.linear())), T.translation());
}

inline Eigen::Matrix3d exp_so3(const Eigen::Vector3d& w) {
  const double a = w.norm();
  return a > 0 ? Eigen::AngleAxisd(a, w / a).toRotationMatrix() : Eigen::Matrix3d::Identity();
}

/// Per-keyframe-step random draws of the drift, so the chain can be rebuilt for any β, γ.
struct DriftDraws {
  std::vector<double> rw;               ///< log-scale random walk w_k (β = 1)
  std::vector<double> ou;               ///< fluctuation o_k
  std::vector<Eigen::Vector3d> domega;  ///< δω_k for step k -> k+1 (γ = 1)
};

inline DriftDraws draw_drift(const std::vector<Eigen::Isometry3d>& T, const DriftParams& p,
                             unsigned seed) {
  std::seed_seq sq{seed, 11u};
  std::mt19937 rng(sq);
  std::normal_distribution<double> n01(0.0, 1.0);
  const std::size_t n = T.size();
  DriftDraws d;
  d.rw.assign(n, 0.0);
  d.ou.assign(n, 0.0);
  d.domega.assign(n, Eigen::Vector3d::Zero());
  if (n == 0) return d;
  d.ou[0] = p.scale_fluctuation_sd * n01(rng);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const double dd = (T[k + 1].translation() - T[k].translation()).norm();
    d.rw[k + 1] = d.rw[k] + p.scale_random_walk * std::sqrt(dd) * n01(rng);
    const double a = std::exp(-dd / p.scale_fluctuation_length_m);
    d.ou[k + 1] = a * d.ou[k] + p.scale_fluctuation_sd * std::sqrt(1.0 - a * a) * n01(rng);
    const double turn = Eigen::AngleAxisd(T[k].linear().transpose() * T[k + 1].linear()).angle();
    for (int i = 0; i < 3; ++i)
      d.domega[k](i) = p.rotation_random_walk(i) * std::sqrt(dd) * n01(rng) +
                       p.turn_rotation_error * turn * n01(rng);
  }
  return d;
}

/// Drifted poses T^M_wc(k) and map scales s_k for amplitudes β (scale), γ (rotation).
inline void chain_drift(const std::vector<Eigen::Isometry3d>& T, const DriftDraws& d,
                        const DriftParams& p, double beta, double gamma,
                        std::vector<Eigen::Isometry3d>* Tm, std::vector<double>* s) {
  const std::size_t n = T.size();
  Tm->assign(n, Eigen::Isometry3d::Identity());
  s->assign(n, p.initial_map_scale);
  for (std::size_t k = 0; k < n; ++k)
    (*s)[k] = p.initial_map_scale * std::exp(beta * d.rw[k] + d.ou[k]);
  for (std::size_t k = 0; k + 1 < n; ++k) {
    const Eigen::Isometry3d rel = T[k].inverse() * T[k + 1];
    Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
    step.linear() = exp_so3(gamma * d.domega[k]) * rel.linear();
    step.translation() = (*s)[k + 1] * rel.translation();
    (*Tm)[k + 1] = (*Tm)[k] * step;
    // Keep the chained rotation orthonormal over thousands of products.
    const Eigen::Quaterniond q((*Tm)[k + 1].linear());
    (*Tm)[k + 1].linear() = q.normalized().toRotationMatrix();
  }
}

/// Smallest-bracket bisection for x >= 0 with f(x) = target, f roughly increasing, f(0) < target.
/// Returns -1 when f(0) >= target or no bracket is found up to x = 2^30.
template <class F>
double solve_increasing(const F& f, double target) {
  if (f(0.0) >= target) return -1.0;
  double lo = 0.0, hi = 1.0;
  int expand = 0;
  while (f(hi) < target) {
    lo = hi;
    hi *= 2.0;
    if (++expand > 30) return -1.0;
  }
  for (int it = 0; it < 60; ++it) {
    const double mid = 0.5 * (lo + hi);
    const double fm = f(mid);
    if (std::abs(fm - target) < 1e-4 * target) return mid;
    (fm < target ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

inline double global_error_of(const std::vector<Eigen::Isometry3d>& Tm,
                              const std::vector<Eigen::Vector3d>& gt_w) {
  std::vector<Eigen::Vector3d> c(Tm.size());
  for (std::size_t k = 0; k < Tm.size(); ++k) c[k] = Tm[k].translation();
  const eval::GlobalSim3Error g = eval::global_sim3_error(c, gt_w);
  return g.alignment.ok() ? g.errors.all.mean : 0.0;
}

/// A landmark before it is observed.
struct Landmark {
  double arclength = 0.0;
  Eigen::Vector3d X = Eigen::Vector3d::Zero();  ///< KITTI world
};

inline std::vector<Landmark> make_scene(const std::vector<Eigen::Isometry3d>& frames,
                                        const SceneParams& p, unsigned seed) {
  std::seed_seq sq{seed, 22u};
  std::mt19937 rng(sq);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  const std::size_t n = frames.size();
  std::vector<double> acc(n, 0.0);
  for (std::size_t i = 1; i < n; ++i)
    acc[i] = acc[i - 1] + (frames[i].translation() - frames[i - 1].translation()).norm();
  const double total = n ? acc.back() : 0.0;
  // Position, right and up directions of the path at arclength a.
  const auto at = [&](double a, Eigen::Vector3d* pos, Eigen::Vector3d* right, Eigen::Vector3d* up) {
    std::size_t i =
        static_cast<std::size_t>(std::upper_bound(acc.begin(), acc.end(), a) - acc.begin());
    i = i == 0 ? 0 : i - 1;
    if (i + 1 >= n) i = n >= 2 ? n - 2 : 0;
    const double seg = n >= 2 ? acc[i + 1] - acc[i] : 0.0;
    const double f = seg > 1e-9 ? std::clamp((a - acc[i]) / seg, 0.0, 1.0) : 0.0;
    *pos = (1 - f) * frames[i].translation() + f * frames[std::min(i + 1, n - 1)].translation();
    *up = -frames[i].linear().col(1);
    *right = frames[i].linear().col(0);
  };
  std::vector<Landmark> out;
  Eigen::Vector3d pos, right, up;
  for (int side = -1; side <= 1; side += 2) {
    double a = 0.0;
    while (a < total) {
      const double len =
          p.facade_block_min_m + (p.facade_block_max_m - p.facade_block_min_m) * u01(rng);
      const bool gap = u01(rng) < p.facade_gap_probability;
      const double offset =
          p.facade_min_offset_m + (p.facade_max_offset_m - p.facade_min_offset_m) * u01(rng);
      const int count = static_cast<int>(std::lround(p.facade_points_per_metre * len));
      for (int j = 0; j < count && !gap; ++j) {
        const double aj = a + len * u01(rng);
        if (aj >= total) continue;
        at(aj, &pos, &right, &up);
        const double lat = offset + p.facade_depth_jitter_m * n01(rng);
        const double h = -p.camera_height_m + p.facade_height_m * u01(rng);
        out.push_back({aj, pos + side * lat * right + h * up});
      }
      a += len;
    }
  }
  const int ground = static_cast<int>(std::lround(p.ground_points_per_metre * total));
  for (int j = 0; j < ground; ++j) {
    const double aj = total * u01(rng);
    at(aj, &pos, &right, &up);
    const double lat = p.ground_half_width_m * (2.0 * u01(rng) - 1.0);
    out.push_back({aj, pos + lat * right - p.camera_height_m * up});
  }
  const int clutter = static_cast<int>(std::lround(p.clutter_points_per_metre * total));
  for (int j = 0; j < clutter; ++j) {
    const double aj = total * u01(rng);
    at(aj, &pos, &right, &up);
    const double side = u01(rng) < 0.5 ? -1.0 : 1.0;
    const double lat = 3.0 + (p.clutter_max_offset_m - 3.0) * u01(rng);
    const double h = -p.camera_height_m + p.clutter_height_m * u01(rng);
    out.push_back({aj, pos + side * lat * right + h * up});
  }
  std::sort(out.begin(), out.end(),
            [](const Landmark& x, const Landmark& y) { return x.arclength < y.arclength; });
  return out;
}

inline bool sees(const map::Camera& cam, const Eigen::Vector3d& p_c, double min_depth,
                 double max_range, Eigen::Vector2d* uv) {
  if (p_c.z() < min_depth || p_c.squaredNorm() > max_range * max_range) return false;
  *uv = cam.project(p_c);
  return cam.in_image(*uv);
}

}  // namespace detail

/// Simulates monocular SLAM output over `seq` (see the file comment for the model).
/// Runtime: about 0.1-0.2 s for a whole KITTI sequence (4661 frames) in Release.
/// @throws InvalidArgument on invalid options or a frame range with fewer than 10 frames.
inline SimulatedSequence simulate(const KittiSequence& seq, const SimOptions& opt) {
  opt.drift.validate();
  opt.scene.validate();
  GEODRIFT_CHECK(opt.pixel_noise_px >= 0 && opt.geotag_noise_m >= 0,
                 "SimOptions: noise levels must be >= 0");
  const int f0 = std::max(0, opt.first_frame);
  const int f1 = std::min(seq.num_frames(), opt.last_frame);
  GEODRIFT_CHECK(f1 - f0 >= 10,
                 "simulate: frame range [" << f0 << ", " << f1 << ") has fewer than 10 frames");
  SimulatedSequence out;
  out.sequence = seq;
  out.options = opt;
  out.map.cameras.push_back(seq.camera);
  const map::Camera& cam = seq.camera;

  // ---- keyframe selection on the true path ----------------------------------------------
  std::vector<int> kf_frames;
  {
    std::seed_seq sq{opt.seed, 33u};
    std::mt19937 rng(sq);
    std::uniform_int_distribution<int> gap(opt.scene.keyframe_min_gap, opt.scene.keyframe_max_gap);
    int f = f0;
    kf_frames.push_back(f);
    while (true) {
      int next = kf_frames.back() + gap(rng);
      const Eigen::Vector3d c_last = seq.T_K_c[kf_frames.back()].translation();
      while (next < f1 &&
             (seq.T_K_c[next].translation() - c_last).norm() < opt.scene.keyframe_min_motion_m)
        ++next;
      if (next >= f1) break;
      kf_frames.push_back(next);
    }
  }
  const std::size_t n = kf_frames.size();
  std::vector<Eigen::Isometry3d> T(n);
  for (std::size_t k = 0; k < n; ++k) T[k] = seq.T_K_c[kf_frames[k]];
  out.gt_T_K_c = T;
  out.gt_center_w.resize(n);
  for (std::size_t k = 0; k < n; ++k)
    out.gt_center_w[k] = geo::kitti_point_to_world(T[k].translation());

  // ---- drift, with its amplitudes calibrated to the targets -----------------------------
  const detail::DriftDraws draws = detail::draw_drift(T, opt.drift, opt.seed);
  std::vector<Eigen::Isometry3d> Tm;
  std::vector<double> s;
  std::vector<int> kf_frame_vec(kf_frames.begin(), kf_frames.end());
  const auto centers = [&]() {
    std::vector<Eigen::Vector3d> c(Tm.size());
    for (std::size_t k = 0; k < Tm.size(); ++k) c[k] = Tm[k].translation();
    return c;
  };
  const auto window_sd = [&](double beta) {
    detail::chain_drift(T, draws, opt.drift, beta, 0.0, &Tm, &s);
    const std::vector<Eigen::Vector3d> c = centers();
    try {
      return eval::windowed_scale_statistics(c, out.gt_center_w, kf_frame_vec, 50).sd;
    } catch (const InvalidArgument&) {
      return 0.0;  // a path too short for two windows: nothing to calibrate against
    }
  };
  const auto global_error = [&](double beta, double gamma) {
    detail::chain_drift(T, draws, opt.drift, beta, gamma, &Tm, &s);
    return detail::global_error_of(Tm, out.gt_center_w);
  };
  double beta = 1.0, gamma = 1.0;
  const double target_sd = opt.drift.target_window_scale_sd;
  const double target_err = opt.drift.target_global_sim3_error_m;
  if (target_sd > 0 && opt.drift.scale_random_walk > 0) {
    beta = detail::solve_increasing([&](double b) { return window_sd(b); }, target_sd);
    if (beta < 0) {
      beta = 0.0;
      out.calibrated = false;
      out.message += "window scale SD target not reachable; ";
    }
  }
  if (target_err > 0) {
    const bool has_rotation =
        opt.drift.rotation_random_walk.maxCoeff() > 0 || opt.drift.turn_rotation_error > 0;
    if (has_rotation && global_error(beta, 0.0) < target_err) {
      gamma = detail::solve_increasing([&](double g) { return global_error(beta, g); }, target_err);
    } else {
      // The scale drift alone already exceeds the target: reduce it, no rotation drift.
      gamma = 0.0;
      beta = detail::solve_increasing([&](double b) { return global_error(b, 0.0); }, target_err);
      out.message += "scale drift alone reaches the target global error; rotation drift off; ";
    }
    if (gamma < 0 || beta < 0) {
      out.calibrated = false;
      out.message += "target global Sim3 error not reachable; ";
      gamma = std::max(gamma, 0.0);
      beta = std::max(beta, 0.0);
    }
  }
  detail::chain_drift(T, draws, opt.drift, beta, gamma, &Tm, &s);
  out.scale_drift_amplitude = beta;
  out.rotation_drift_amplitude = gamma;
  out.warp.resize(n);
  for (std::size_t k = 0; k < n; ++k) {
    Similarity& S = out.warp[k];
    const Eigen::Matrix3d Rt = T[k].linear().transpose();
    S.s = s[k];
    S.R = Tm[k].linear() * Rt;
    S.t = Tm[k].translation() - s[k] * (S.R * T[k].translation());
  }
  out.map.keyframes.resize(n);
  std::vector<Eigen::Isometry3d> Tm_cw(n), T_cw(n);
  for (std::size_t k = 0; k < n; ++k) {
    map::Keyframe& kf = out.map.keyframes[k];
    kf.id = static_cast<int>(k);
    kf.frame_index = kf_frames[k];
    kf.timestamp = seq.timestamps[kf_frames[k]];
    kf.camera_id = cam.id;
    Tm_cw[k] = Tm[k].inverse();
    T_cw[k] = T[k].inverse();
    kf.T_cw = detail::to_se3(Tm_cw[k]);
  }

  // ---- scene and observations ----------------------------------------------------------
  std::vector<Eigen::Isometry3d> frames(seq.T_K_c.begin() + f0, seq.T_K_c.begin() + f1);
  std::vector<detail::Landmark> lms = detail::make_scene(frames, opt.scene, opt.seed);
  std::vector<double> kf_arc(n, 0.0);
  {
    double a = 0.0;
    int k = 0;
    for (int f = f0; f < f1 && k < static_cast<int>(n); ++f) {
      if (f > f0) a += (seq.T_K_c[f].translation() - seq.T_K_c[f - 1].translation()).norm();
      if (f == kf_frames[k]) kf_arc[k++] = a;
    }
  }
  const double range = opt.scene.max_range_m;
  const auto candidates = [&](std::size_t k) {
    const auto lo =
        std::lower_bound(lms.begin(), lms.end(), kf_arc[k] - 10.0,
                         [](const detail::Landmark& l, double a) { return l.arclength < a; });
    const auto hi =
        std::upper_bound(lo, lms.end(), kf_arc[k] + range + 5.0,
                         [](double a, const detail::Landmark& l) { return a < l.arclength; });
    return std::make_pair(lo, hi);
  };
  // Texture everywhere: a keyframe that sees too few scene points (the path's ends, a road
  // climbing out of the field of view, an empty street) gets extra points in its own view, as
  // a real image always offers some features to track.
  {
    std::seed_seq sq{opt.seed, 66u};
    std::mt19937 rng(sq);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::vector<detail::Landmark> extra;
    for (std::size_t k = 0; k < n; ++k) {
      int visible = 0;
      const auto [lo, hi] = candidates(k);
      Eigen::Vector2d uv;
      for (auto it = lo; it != hi; ++it)
        visible += detail::sees(cam, T_cw[k] * it->X, opt.scene.min_depth_m, range, &uv);
      for (int i = visible; i < opt.scene.min_points_per_keyframe; ++i) {
        const Eigen::Vector3d ray((cam.width * u01(rng) - cam.cx) / cam.fx,
                                  (cam.height * u01(rng) - cam.cy) / cam.fy, 1.0);
        const double z_max = 0.8 * range / ray.norm();
        const double z = std::min(5.0, z_max) + (z_max - std::min(5.0, z_max)) * u01(rng);
        extra.push_back({kf_arc[k] + z, T[k] * (z * ray)});
      }
    }
    if (!extra.empty()) {
      lms.insert(lms.end(), extra.begin(), extra.end());
      std::stable_sort(lms.begin(), lms.end(),
                       [](const detail::Landmark& x, const detail::Landmark& y) {
                         return x.arclength < y.arclength;
                       });
    }
  }
  std::seed_seq sq_pix{opt.seed, 44u};
  std::mt19937 rng_pix(sq_pix);
  std::normal_distribution<double> npx(0.0, 1.0);
  std::vector<int> ref(lms.size(), -1);
  std::vector<Eigen::Vector3d> X_m(lms.size(), Eigen::Vector3d::Zero());
  std::vector<int> n_seen(lms.size(), 0);
  std::vector<std::pair<int, int>> truly_seen;  // (keyframe, landmark), keyframe order
  truly_seen.reserve(lms.size() * 8);
  for (std::size_t k = 0; k < n; ++k) {
    const auto [lo, hi] = candidates(k);
    for (auto it = lo; it != hi; ++it) {
      const std::size_t j = static_cast<std::size_t>(it - lms.begin());
      Eigen::Vector2d uv_true;
      if (!detail::sees(cam, T_cw[k] * it->X, opt.scene.min_depth_m, range, &uv_true)) continue;
      if (ref[j] < 0) ref[j] = static_cast<int>(k);
      // A point is triangulated from all keyframes that see it (local BA): place it at the
      // mean of their views of it, so its inconsistency is spread over its whole track.
      X_m[j] += out.warp[k].apply(it->X);
      ++n_seen[j];
      truly_seen.push_back({static_cast<int>(k), static_cast<int>(j)});
    }
  }
  for (std::size_t j = 0; j < lms.size(); ++j)
    if (n_seen[j] > 0) X_m[j] /= n_seen[j];
  std::vector<map::Observation> obs;
  obs.reserve(truly_seen.size());
  {
    for (const auto& [kk, jj] : truly_seen) {
      const std::size_t k = static_cast<std::size_t>(kk), j = static_cast<std::size_t>(jj);
      const Eigen::Vector3d p_m = Tm_cw[k] * X_m[j];
      if (p_m.z() <= 1e-9 * std::abs(p_m.norm())) continue;
      Eigen::Vector2d uv = cam.project(p_m);
      if (!cam.in_image(uv)) continue;
      uv += opt.pixel_noise_px * Eigen::Vector2d(npx(rng_pix), npx(rng_pix));
      obs.push_back({static_cast<int>(k), static_cast<int>(j), uv});
    }
  }
  // The reference keyframe is the first one that actually observes the point (observations
  // are in keyframe order). Cull points with too few observations; renumber points 0..m-1 in
  // creation order.
  std::vector<int> count(lms.size(), 0);
  std::fill(ref.begin(), ref.end(), -1);
  for (const auto& o : obs) {
    if (count[o.point]++ == 0) ref[o.point] = o.keyframe;
  }
  std::vector<int> new_id(lms.size(), -1);
  std::vector<std::size_t> order;
  for (std::size_t j = 0; j < lms.size(); ++j)
    if (ref[j] >= 0 && count[j] >= opt.scene.min_observations) order.push_back(j);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return ref[a] < ref[b]; });
  out.map.points.reserve(order.size());
  out.point_truth_K.reserve(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) {
    const std::size_t j = order[i];
    new_id[j] = static_cast<int>(i);
    out.map.points.push_back({static_cast<int>(i), X_m[j], ref[j]});
    out.point_truth_K.push_back(lms[j].X);
  }
  out.map.observations.reserve(obs.size());
  for (const auto& o : obs)
    if (new_id[o.point] >= 0)
      out.map.observations.push_back({o.keyframe, new_id[o.point], o.pixel});
  return out;
}

/// Localises the geo views of `frames` (right camera at its true pose) in the drifted map as
/// described in the file comment, with the noise levels and seed of sim.options.
/// Frames outside the simulated range, or with fewer than min_geo_view_points matched points,
/// come back with localized = false and a reason.
inline std::vector<GeoView> localize_geo_views(const SimulatedSequence& sim,
                                               const std::vector<int>& frames) {
  const SimOptions& opt = sim.options;
  const map::Camera& cam = sim.sequence.camera;
  // Observations per keyframe index.
  std::vector<std::vector<int>> seen(sim.map.keyframes.size());
  for (const auto& o : sim.map.observations) seen[o.keyframe].push_back(o.point);
  std::vector<GeoView> views;
  int next_id = 0;
  for (int f : frames) {
    GeoView v;
    v.frame = f;
    const int first = sim.map.keyframes.front().frame_index;
    const int last = sim.map.keyframes.back().frame_index;
    if (f < first || f > last) {
      v.failure = "frame " + std::to_string(f) + " outside the simulated keyframes [" +
                  std::to_string(first) + ", " + std::to_string(last) + "]";
      views.push_back(v);
      continue;
    }
    std::seed_seq sq{opt.seed, 55u, static_cast<unsigned>(f)};
    std::mt19937 rng(sq);
    std::normal_distribution<double> n01(0.0, 1.0);
    // Right camera: cam0 shifted by the baseline along its +x axis.
    Eigen::Isometry3d T_K_r = sim.sequence.T_K_c[f];
    T_K_r.translation() += T_K_r.linear().col(0) * sim.sequence.baseline_m;
    const Eigen::Isometry3d T_r_K = T_K_r.inverse();
    const int K = sim.nearest_keyframe(f);
    std::vector<Eigen::Vector3d> X;
    std::vector<Eigen::Vector2d> u;
    for (int pid : seen[K]) {
      Eigen::Vector2d uv;
      if (!detail::sees(cam, T_r_K * sim.point_truth_K[pid], opt.scene.min_depth_m,
                        opt.scene.max_range_m, &uv))
        continue;
      X.push_back(sim.map.points[pid].position);
      u.push_back(uv + opt.pixel_noise_px * Eigen::Vector2d(n01(rng), n01(rng)));
    }
    v.points = static_cast<int>(X.size());
    v.center_true_w = geo::kitti_point_to_world(T_K_r.translation());
    if (v.points < opt.min_geo_view_points) {
      v.failure = "geo view at frame " + std::to_string(f) + " matched " +
                  std::to_string(v.points) + " map points, fewer than " +
                  std::to_string(opt.min_geo_view_points);
      views.push_back(v);
      continue;
    }
    // Initial guess: the keyframe's drifted pose (what a PnP on its matches starts near).
    const map::Keyframe& kf = sim.map.keyframes[K];
    // PnP + LM with inlier selection (what RANSAC + LM does in the real pipeline): solve on the
    // current inliers, keep the points whose reprojection error is below the chi-square(2 dof,
    // 95 %) gate for the pixel noise (floor 1 px) or below 3x the median error, whichever is
    // larger: the drifted map is locally inconsistent by a few pixels (its scale is rough), so
    // a fixed gate would reject the whole view rather than the gross misfits.
    const double gate = 2.45 * std::max(opt.pixel_noise_px, 1.0);
    std::vector<Eigen::Vector3d> Xi = X;
    std::vector<Eigen::Vector2d> ui = u;
    correction::PnpResult pnp = correction::refine_pose_lm(Xi, ui, cam, kf.T_cw, 50);
    for (int round = 0; round < 5; ++round) {
      std::vector<double> r(X.size());
      for (std::size_t i = 0; i < X.size(); ++i) {
        const Eigen::Vector3d p = pnp.T_cw.act(X[i]);
        r[i] = p.z() > 0 ? (cam.project(p) - u[i]).norm() : std::numeric_limits<double>::max();
      }
      std::vector<double> sorted = r;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double thr = std::max(gate, 3.0 * sorted[sorted.size() / 2]);
      std::vector<Eigen::Vector3d> Xn;
      std::vector<Eigen::Vector2d> un;
      for (std::size_t i = 0; i < X.size(); ++i)
        if (r[i] < thr) {
          Xn.push_back(X[i]);
          un.push_back(u[i]);
        }
      if (Xn.size() == Xi.size() && round > 0) break;
      Xi.swap(Xn);
      ui.swap(un);
      if (static_cast<int>(Xi.size()) < opt.min_geo_view_points) break;
      pnp = correction::refine_pose_lm(Xi, ui, cam, pnp.T_cw, 50);
    }
    if (static_cast<int>(Xi.size()) < opt.min_geo_view_points) {
      v.failure = "geo view at frame " + std::to_string(f) + ": " + std::to_string(Xi.size()) +
                  " of " + std::to_string(X.size()) +
                  " matched points are PnP inliers, fewer than " +
                  std::to_string(opt.min_geo_view_points);
      views.push_back(v);
      continue;
    }
    v.T_vw = pnp.T_cw;
    const Eigen::Vector3d c_solved = pnp.T_cw.inverse().translation();
    const Similarity& S = sim.warp[K];
    v.position_error_m = (c_solved - S.apply(T_K_r.translation())).norm() / S.s;
    map::Correspondence& c = v.correspondence;
    c.id = next_id++;
    c.keyframe = kf.id;
    c.T_vk = pnp.T_cw * kf.T_cw.inverse();
    c.y_w = v.center_true_w + opt.geotag_noise_m * Eigen::Vector3d(n01(rng), n01(rng), n01(rng));
    c.sigma_m = opt.geotag_noise_m > 0 ? opt.geotag_noise_m : 0.05;
    c.geotag_id = f;
    c.inliers = static_cast<int>(Xi.size());
    c.reprojection_rms = pnp.rms_px;
    if (pnp.covariance.ok) c.pose_cov = pnp.covariance.pose;
    v.localized = true;
    views.push_back(v);
  }
  return views;
}

/// The KITTI protocol's correspondences for geo-tag interval N: geo views at
/// kitti_anchor_frames(num_frames, N), localised; those that fail are left out (and listed in
/// `views` when given).
inline std::vector<map::Correspondence> kitti_correspondences(
    const SimulatedSequence& sim, int interval, std::vector<GeoView>* views = nullptr) {
  const int last = sim.map.keyframes.back().frame_index + 1;
  std::vector<GeoView> v = localize_geo_views(sim, kitti_anchor_frames(last, interval));
  std::vector<map::Correspondence> out;
  for (const auto& g : v)
    if (g.localized) {
      out.push_back(g.correspondence);
      out.back().id = static_cast<int>(out.size()) - 1;
    }
  if (views) *views = std::move(v);
  return out;
}

/// Statistics of the uncorrected drift (the calibration targets).
struct DriftStatistics {
  eval::GlobalSim3Error global;  ///< Umeyama Sim3 of uncorrected keyframe centres, 2D error
  eval::WindowScaleStats scale;  ///< 50-frame windows, normalised
  double scale_drift_amplitude = 1.0;
  double rotation_drift_amplitude = 1.0;
};

/// Computes DriftStatistics for a simulation (window_frames = 50 as in the issue).
inline DriftStatistics drift_statistics(const SimulatedSequence& sim, int window_frames = 50) {
  DriftStatistics d;
  const auto c = sim.keyframe_centers_m();
  d.global = eval::global_sim3_error(c, sim.gt_center_w);
  d.scale =
      eval::windowed_scale_statistics(c, sim.gt_center_w, sim.keyframe_frames(), window_frames);
  d.scale_drift_amplitude = sim.scale_drift_amplitude;
  d.rotation_drift_amplitude = sim.rotation_drift_amplitude;
  return d;
}

}  // namespace geodrift::sim
