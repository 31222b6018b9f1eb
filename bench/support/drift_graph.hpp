#pragma once

/// @file
/// Seeded generator of the synthetic monocular-drift Sim(3) pose graph of issue 3.
///
/// Ground truth: a car-mounted camera (height 1.6 m, x right, y down, z forward) drives an
/// "urban" path in the W plane (z up): straight blocks of 60-240 m joined by ±90° turns on a
/// 12 m radius arc; a keyframe every 1.5 m. Poses are world -> camera S_cw (DESIGN.md).
///
/// Monocular VO: the keyframe-to-keyframe motion ΔT_k = T_{k+1}·T_k⁻¹ is measured with
///   rotation noise N(0, rot_noise²) per axis, translation noise N(0, trans_noise²) per axis,
///   and its translation scaled by λ_k, where log λ follows a random walk with standard deviation
///   scale_drift_per_100m per 100 m (the scale drift);
/// the VO poses are the chained measurements (scale 1 as Sim(3)), and they are the initial values.
///
/// Edges: each keyframe i to its next `neighbours` keyframes j: dS_ij = S_j^vo·(S_i^vo)⁻¹
/// perturbed by exp(n), n ~ N(0, diag(edge_rot², edge_sigma², edge_trans²)); residual
/// r = log(dS_ij·S_i·S_j⁻¹) (solver::RelativePoseResidual<lie::Sim3d>), weight edge_weight·I7
/// (the paper's λ1 = 1e5).
/// Priors: every `prior_every` keyframes (starting at 0), the camera centre c(S_i) = -(1/s)Rᵀt
/// is tied to its true position plus N(0, prior_sigma²) noise per axis, weight 1/prior_sigma²
/// (solver::CameraCentrePriorResidual, the paper's e3 with λ3 = 1 for 1 m).
/// No pose is held constant: the priors fix the 7-dof gauge.

#include <Eigen/Core>
#include <cmath>
#include <random>
#include <vector>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"

namespace geodrift::bench {

struct DriftGraphOptions {
  double keyframe_spacing = 1.5;               ///< metres between keyframes
  double block_min = 60.0, block_max = 240.0;  ///< straight block length [m]
  double turn_radius = 12.0;                   ///< [m]
  double camera_height = 1.6;                  ///< [m]
  double rot_noise = 5e-4;                     ///< VO rotation noise per keyframe per axis [rad]
  double trans_noise = 0.01;                   ///< VO translation noise per keyframe per axis [m]
  double scale_drift_per_100m = 0.03;          ///< std of log-scale random walk per 100 m
  int neighbours = 6;                          ///< edges from each keyframe to its next N
  double edge_rot = 2e-4, edge_sigma = 5e-4, edge_trans = 2e-3;  ///< edge noise
  double edge_weight = 1e5;  ///< scalar information of each edge
  int prior_every = 100;     ///< keyframes between position priors
  double prior_sigma = 1.0;  ///< [m]
};

struct DriftGraph {
  struct Edge {
    int i = 0, j = 0;
    lie::Sim3d dS_ij;
  };
  struct Prior {
    int i = 0;
    Eigen::Vector3d y = Eigen::Vector3d::Zero();  ///< target camera centre in W
  };
  std::vector<lie::Sim3d> truth;    ///< S_cw, scale 1
  std::vector<lie::Sim3d> initial;  ///< VO poses as Sim(3), scale 1 (drifting)
  std::vector<Edge> edges;
  std::vector<Prior> priors;
  double edge_weight = 1e5;
  double prior_weight = 1.0;
  double path_length = 0.0;  ///< metres
};

/// Camera centre c = −(1/s)·Rᵀ·t of a world -> camera Sim(3).
inline Eigen::Vector3d camera_centre(const lie::Sim3d& S) {
  return -(1.0 / S.scale()) * (S.rotation().inverse().act(S.translation()));
}

inline DriftGraph make_drift_graph(int n, unsigned seed, const DriftGraphOptions& o = {}) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  DriftGraph g;
  g.edge_weight = o.edge_weight;
  g.prior_weight = 1.0 / (o.prior_sigma * o.prior_sigma);

  // ---- ground truth path -----------------------------------------------------------------
  double x = 0.0, y = 0.0, heading = 0.0;
  double straight_left = o.block_min + (o.block_max - o.block_min) * u01(rng);
  double turn_left = 0.0, turn_dir = 0.0;
  std::vector<lie::SE3d> T_true;
  T_true.reserve(static_cast<std::size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double c = std::cos(heading), s = std::sin(heading);
    Eigen::Matrix3d R_wc;
    R_wc.col(0) = Eigen::Vector3d(s, -c, 0.0);      // x: right of the heading
    R_wc.col(1) = Eigen::Vector3d(0.0, 0.0, -1.0);  // y: down
    R_wc.col(2) = Eigen::Vector3d(c, s, 0.0);       // z: forward
    const Eigen::Vector3d centre(x, y, o.camera_height);
    const lie::SO3d R_cw(Eigen::Matrix3d(R_wc.transpose()));
    T_true.emplace_back(R_cw, -(R_cw.act(centre)));
    // advance
    const double step = o.keyframe_spacing;
    if (turn_left > 0.0) {
      const double dh = std::min(step / o.turn_radius, turn_left);
      x += step * std::cos(heading + 0.5 * turn_dir * dh);
      y += step * std::sin(heading + 0.5 * turn_dir * dh);
      heading += turn_dir * dh;
      turn_left -= dh;
      if (turn_left <= 1e-12) {
        heading = std::round(heading / (0.5 * M_PI)) * (0.5 * M_PI);  // exact grid heading
        straight_left = o.block_min + (o.block_max - o.block_min) * u01(rng);
      }
    } else {
      x += step * std::cos(heading);
      y += step * std::sin(heading);
      straight_left -= step;
      if (straight_left <= 0.0) {
        turn_left = 0.5 * M_PI;
        turn_dir = u01(rng) < 0.5 ? -1.0 : 1.0;
      }
    }
    g.path_length += step;
  }
  for (const lie::SE3d& T : T_true) g.truth.emplace_back(T);

  // ---- monocular VO with scale drift ---------------------------------------------------------
  const double scale_step =
      o.scale_drift_per_100m * std::sqrt(o.keyframe_spacing / 100.0);  // per keyframe
  double log_lambda = 0.0;
  std::vector<lie::SE3d> T_vo(static_cast<std::size_t>(n));
  T_vo[0] = T_true[0];
  for (int k = 0; k + 1 < n; ++k) {
    const lie::SE3d dT =
        T_true[static_cast<std::size_t>(k + 1)] * T_true[static_cast<std::size_t>(k)].inverse();
    Eigen::Vector3d rn(o.rot_noise * n01(rng), o.rot_noise * n01(rng), o.rot_noise * n01(rng));
    Eigen::Vector3d tn(o.trans_noise * n01(rng), o.trans_noise * n01(rng),
                       o.trans_noise * n01(rng));
    log_lambda += scale_step * n01(rng);
    const lie::SE3d dT_vo(lie::SO3d::exp(rn) * dT.rotation(),
                          std::exp(log_lambda) * dT.translation() + tn);
    T_vo[static_cast<std::size_t>(k + 1)] = dT_vo * T_vo[static_cast<std::size_t>(k)];
  }
  for (const lie::SE3d& T : T_vo) g.initial.emplace_back(T);

  // ---- edges and priors -------------------------------------------------------------------
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j <= std::min(n - 1, i + o.neighbours); ++j) {
      lie::Sim3d::Tangent noise;
      for (int a = 0; a < 3; ++a) noise[a] = o.edge_rot * n01(rng);
      noise[3] = o.edge_sigma * n01(rng);
      for (int a = 4; a < 7; ++a) noise[a] = o.edge_trans * n01(rng);
      const lie::Sim3d dS = lie::Sim3d::exp(noise) * g.initial[static_cast<std::size_t>(j)] *
                            g.initial[static_cast<std::size_t>(i)].inverse();
      g.edges.push_back({i, j, dS});
    }
  }
  for (int i = 0; i < n; i += o.prior_every) {
    const Eigen::Vector3d c = camera_centre(g.truth[static_cast<std::size_t>(i)]);
    g.priors.push_back({i, c + o.prior_sigma * Eigen::Vector3d(n01(rng), n01(rng), n01(rng))});
  }
  return g;
}

}  // namespace geodrift::bench
