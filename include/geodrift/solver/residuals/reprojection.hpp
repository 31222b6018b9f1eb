#pragma once

/// @file
/// Pinhole reprojection residual for bundle adjustment: r = π(T_cw·X_w) − uv in pixels (of the
/// undistorted image), T_cw world -> camera (SE3, OpenCV camera x right, y down, z forward),
/// X_w in the world or map frame, in the unit of the poses. Jacobians w.r.t. the LEFT
/// perturbation T ← exp(δ)·T, tangent (ω, ν), and X ← X + δ.

#include <Eigen/Core>

#include "geodrift/lie/se3.hpp"

namespace geodrift::solver {

/// r = π(T_cw · X_w) − uv  [pixels], π(p) = (fx·x/z + cx, fy·y/z + cy).
/// T_cw: world→camera (SE3, tangent (ω, ν), LEFT perturbation T ← exp(δ)·T);
/// X_w: world point (R^3: Eigen::Vector3d or solver::Euclidean<3>).
///   J_r_T (2x6) = J_π · [ −[p]x | I ],  J_r_X (2x3) = J_π · R_cw,  p = T_cw·X_w,
///   J_π = [ fx/z  0  −fx·x/z² ;  0  fy/z  −fy·y/z² ].
/// Returns false (unevaluable) when the point is not in front of the camera (z ≤ min_depth).
struct ReprojectionResidual {
  static constexpr int kNumResiduals = 2;
  using Vec = Eigen::Matrix<double, 2, 1>;
  using MatT = Eigen::Matrix<double, 2, 6>;
  using MatX = Eigen::Matrix<double, 2, 3>;

  double fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0;
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();  ///< observed pixel
  double min_depth = 1e-6;                       ///< metres

  template <typename PointArg>
  bool operator()(const lie::SE3d& T_cw, const PointArg& X_w, Vec* r, MatT* J_r_T = nullptr,
                  MatX* J_r_X = nullptr) const {
    const Eigen::Vector3d X = X_w;
    Eigen::Matrix<double, 3, 6> J_p_T;
    Eigen::Matrix3d J_p_X;
    const Eigen::Vector3d p = T_cw.act(X, J_r_T ? &J_p_T : nullptr, J_r_X ? &J_p_X : nullptr);
    if (!(p.z() > min_depth)) return false;
    const double iz = 1.0 / p.z();
    (*r)[0] = fx * p.x() * iz + cx - uv[0];
    (*r)[1] = fy * p.y() * iz + cy - uv[1];
    if (J_r_T || J_r_X) {
      Eigen::Matrix<double, 2, 3> J_pi;
      J_pi << fx * iz, 0.0, -fx * p.x() * iz * iz, 0.0, fy * iz, -fy * p.y() * iz * iz;
      if (J_r_T) J_r_T->noalias() = J_pi * J_p_T;
      if (J_r_X) J_r_X->noalias() = J_pi * J_p_X;
    }
    return true;
  }
};

}  // namespace geodrift::solver
