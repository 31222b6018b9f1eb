#pragma once

#include <Eigen/Core>
#include <cmath>
#include <limits>
#include <vector>

#include "geodrift/correction/localization_covariance.hpp"
#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/map/camera.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/loss.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"

namespace geodrift::sim::detail {

/// Result of refine_pose_lm().
struct PnpResult {
  lie::SE3d T_cw;  ///< world -> camera
  /// Reprojection RMS per point, √(Σ|r_i|²/n) in pixels, at the solution; NaN when a point
  /// lies behind the camera at the initial pose (nothing was solved).
  double rms_px = std::numeric_limits<double>::quiet_NaN();
  int iterations = 0;  ///< LM iterations (accepted + rejected steps)
  bool converged = false;
  /// Gauss–Newton covariance of T_cw at the solution (correction::pnp_pose_covariance:
  /// σ̂²·(JᵀJ)⁻¹, σ̂² the reprojection residual variance); ok = false when nothing was solved.
  correction::PnpCovariance covariance;
};

/// Levenberg–Marquardt refinement of a camera pose from 3D–2D correspondences, minimising
/// ½ Σ |π(T_cw·X_i) − u_i|² (pixels) with the core solver: the pose is the only free block
/// (SE3, LEFT perturbation T ← exp(δ)·T, δ = (ω, ν)), the points are constant blocks of
/// solver::ReprojectionResidual (the geo view's PnP + LM step of the paper, Sec. 3.2).
/// A trial pose that puts a point behind the camera is a rejected step; a point behind the
/// camera at T_init leaves T_init unchanged with converged = false.
/// @param X world points; @param u their observed pixels (same size, at least 3).
/// @throws InvalidArgument if the sizes differ or there are fewer than 3 points.
inline PnpResult refine_pose_lm(const std::vector<Eigen::Vector3d>& X,
                                const std::vector<Eigen::Vector2d>& u, const map::Camera& cam,
                                const lie::SE3d& T_init, int max_iterations = 30) {
  GEODRIFT_CHECK(X.size() == u.size(),
                 "refine_pose_lm: " << X.size() << " points but " << u.size() << " pixels");
  GEODRIFT_CHECK(X.size() >= 3, "refine_pose_lm: " << X.size() << " points, need at least 3");
  PnpResult res;
  res.T_cw = T_init;
  std::vector<Eigen::Vector3d> points = X;  // the Problem refers to the states by address
  solver::Problem problem;
  for (std::size_t i = 0; i < points.size(); ++i) {
    problem.add_residual_block(
        solver::ReprojectionResidual{cam.fx, cam.fy, cam.cx, cam.cy, u[i], 1e-9},
        solver::RobustLoss(), 1.0, &res.T_cw, &points[i]);
    problem.set_constant(&points[i]);
  }
  solver::Options options;
  options.max_iterations = max_iterations;
  options.linear_solver = solver::LinearSolverType::kDense;
  // Converge to machine precision: the geo view's pose error is judged in millimetres.
  options.function_tolerance = 1e-12;
  options.parameter_tolerance = 1e-12;
  solver::LevenbergMarquardt lm(options);
  const solver::Summary summary = lm.solve(&problem);
  res.iterations = summary.iterations;
  res.converged = summary.converged();
  if (summary.termination != solver::Termination::kNonFiniteResidual)
    res.rms_px = std::sqrt(2.0 * summary.final_cost / static_cast<double>(points.size()));
  if (std::isfinite(res.rms_px))
    res.covariance = correction::pnp_pose_covariance(X, u, cam, res.T_cw);
  return res;
}

}  // namespace geodrift::sim::detail
