#pragma once

/// @file
/// Levenberg–Marquardt refinement of a camera pose from 3D–2D pairs on the core solver: the
/// "PnP + LM" step that localizes a geo view in the map (paper Sec. 3.2), shared by the
/// simulator (sim::simulate) and the geo-tag frontend (geotag::localize_view).
///
/// Conventions: the pose is T_cw (world or map frame -> camera, OpenCV camera x right, y down,
/// z forward), in the unit of the given points; residuals in pixels; the pose update and its
/// covariance use the LEFT perturbation T ← exp(δ)·T, tangent (ω, ν).

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

namespace geodrift::correction {

/// Result of refine_pose_lm().
struct PnpResult {
  lie::SE3d T_cw;  ///< world -> camera
  /// RMS of the raw pixel residuals at the solution, √(Σ|π(T_cw·X_i) − u_i|²/n) (also with a
  /// Huber loss); NaN when a point lies behind the camera at the initial pose (nothing was
  /// solved) or at the solution.
  double rms_px = std::numeric_limits<double>::quiet_NaN();
  int iterations = 0;  ///< LM iterations (accepted + rejected steps)
  bool converged = false;
  /// Gauss–Newton covariance of T_cw at the solution (pnp_pose_covariance: σ̂²·(JᵀJ)⁻¹, σ̂² the
  /// reprojection residual variance); ok = false when nothing was solved.
  PnpCovariance covariance;
};

/// Levenberg–Marquardt refinement of a camera pose from 3D–2D correspondences, minimising
/// ½ Σ ρ(|π(T_cw·X_i) − u_i|²) (pixels; ρ = Huber(huber_px) when huber_px > 0, else plain
/// least squares) with the core solver: the pose is the only free block (SE3, LEFT
/// perturbation T ← exp(δ)·T, δ = (ω, ν)), the points are constant blocks of
/// solver::ReprojectionResidual. Converges to machine precision (function and parameter
/// tolerance 1e-12): a geo view's pose error is judged in millimetres. A trial pose that puts a
/// point behind the camera is a rejected step; a point behind the camera at T_init leaves
/// T_init unchanged with converged = false and rms_px = NaN.
/// @param X world points; @param u their observed pixels (same size, at least 3).
/// @throws InvalidArgument if the sizes differ, there are fewer than 3 points or huber_px < 0.
inline PnpResult refine_pose_lm(const std::vector<Eigen::Vector3d>& X,
                                const std::vector<Eigen::Vector2d>& u, const map::Camera& cam,
                                const lie::SE3d& T_init, int max_iterations = 30,
                                double huber_px = 0.0) {
  GEODRIFT_CHECK(X.size() == u.size(),
                 "refine_pose_lm: " << X.size() << " points but " << u.size() << " pixels");
  GEODRIFT_CHECK(X.size() >= 3, "refine_pose_lm: " << X.size() << " points, need at least 3");
  GEODRIFT_CHECK(huber_px >= 0.0, "refine_pose_lm: huber_px " << huber_px << " must be >= 0");
  PnpResult res;
  res.T_cw = T_init;
  for (const Eigen::Vector3d& p : X)
    if (!(T_init.act(p).z() > 1e-9)) return res;  // behind the camera: nothing to refine
  std::vector<Eigen::Vector3d> points = X;        // the Problem refers to the states by address
  const solver::RobustLoss loss =
      huber_px > 0.0 ? solver::RobustLoss::huber(huber_px) : solver::RobustLoss::trivial();
  solver::Problem problem;
  for (std::size_t i = 0; i < points.size(); ++i) {
    problem.add_residual_block(
        solver::ReprojectionResidual{cam.fx, cam.fy, cam.cx, cam.cy, u[i], 1e-9}, loss, 1.0,
        &res.T_cw, &points[i]);
    problem.set_constant(&points[i]);
  }
  solver::Options options;
  options.max_iterations = max_iterations;
  options.linear_solver = solver::LinearSolverType::kDense;
  options.function_tolerance = 1e-12;
  options.parameter_tolerance = 1e-12;
  solver::LevenbergMarquardt lm(options);
  const solver::Summary summary = lm.solve(&problem);
  res.iterations = summary.iterations;
  res.converged = summary.converged();
  double ss = 0.0;
  for (std::size_t i = 0; i < X.size(); ++i) {
    const Eigen::Vector3d p = res.T_cw.act(X[i]);
    if (!(p.z() > 1e-9)) return res;  // rms_px stays NaN
    ss += (cam.project(p) - u[i]).squaredNorm();
  }
  res.rms_px = std::sqrt(ss / static_cast<double>(X.size()));
  res.covariance = pnp_pose_covariance(X, u, cam, res.T_cw);
  return res;
}

}  // namespace geodrift::correction
