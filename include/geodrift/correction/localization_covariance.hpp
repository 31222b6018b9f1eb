#pragma once

/// @file
/// How well a geo view is localized in the map: the covariance of a camera pose refined by
/// PnP + Levenberg–Marquardt (paper Sec. 3.3), and the effective standard deviation of a geo
/// term that combines it with the geo-tag's (used by the Corrector's PGO e3 edges and BA geo
/// terms, CorrectorOptions::weight_by_localization).
///
/// Tangent order (ω, ν), LEFT perturbation T ← exp(δ)·T, as everywhere in geodrift.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/map/camera.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"

namespace geodrift::correction {

/// Result of pnp_pose_covariance().
struct PnpCovariance {
  bool ok = false;  ///< false: fewer than 4 usable points or a singular JᵀJ (see `why`)
  std::string why;
  /// Covariance of the pose T_cw in its tangent (ω, ν) (left perturbation; rad², M units²).
  Eigen::Matrix<double, 6, 6> pose = Eigen::Matrix<double, 6, 6>::Zero();
  /// Covariance of the camera centre c = T_cw⁻¹·0 in the world (map) frame, M units².
  Eigen::Matrix3d center = Eigen::Matrix3d::Zero();
  double sigma_px = 0;  ///< σ̂, the residual standard deviation used to scale (JᵀJ)⁻¹
  int points = 0;       ///< points in front of the camera that entered JᵀJ
};

/// Covariance of the camera centre from a pose covariance in the tangent (ω, ν) of T_cw:
/// c = T_cw⁻¹·0 and T⁻¹ ← T⁻¹·exp(−δ), exp(−δ)·0 ≈ −ν, so δc = −R_cwᵀ·ν and
/// Σ_c = R_cwᵀ · Σ_νν · R_cw (the rotation part does not move the centre to first order).
inline Eigen::Matrix3d center_covariance(const Eigen::Matrix<double, 6, 6>& pose_cov,
                                         const lie::SE3d& T_cw) {
  const Eigen::Matrix3d R = T_cw.rotation().matrix();
  return R.transpose() * pose_cov.block<3, 3>(3, 3) * R;
}

/// Gauss–Newton covariance of a pose refined by PnP + LM on 3D–2D pairs (X[i] in the map,
/// u[i] pixels), at the solution T_cw, the map points held fixed:
///
///     Σ_ξ = σ̂² · (JᵀJ)⁻¹,   J (2n×6) = ∂r/∂δ stacked over the points
///                                      (solver::ReprojectionResidual's J_r_T),
///     σ̂² = Σ|r_i|² / (2n − 6)   (the reprojection residual variance, 6 pose unknowns).
///
/// Scaling by the residual variance rather than the nominal pixel noise makes a view whose
/// points fit the drifted map badly (a locally inconsistent map scale, wrong matches kept by a
/// loose gate) come out less certain, as it is. The points are treated as exact and
/// independent: errors of the map points that are correlated between points (a locally warped
/// map) are not in Σ. Points behind the camera are left out.
/// @throws InvalidArgument if the sizes differ.
inline PnpCovariance pnp_pose_covariance(const std::vector<Eigen::Vector3d>& X,
                                         const std::vector<Eigen::Vector2d>& u,
                                         const map::Camera& cam, const lie::SE3d& T_cw) {
  GEODRIFT_CHECK(X.size() == u.size(),
                 "pnp_pose_covariance: " << X.size() << " points but " << u.size() << " pixels");
  PnpCovariance out;
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  double ss = 0;
  for (std::size_t i = 0; i < X.size(); ++i) {
    const solver::ReprojectionResidual r{cam.fx, cam.fy, cam.cx, cam.cy, u[i], 1e-9};
    solver::ReprojectionResidual::Vec e;
    solver::ReprojectionResidual::MatT J;
    if (!r(T_cw, X[i], &e, &J)) continue;
    H.noalias() += J.transpose() * J;
    ss += e.squaredNorm();
    ++out.points;
  }
  if (out.points < 4) {
    out.why = std::to_string(out.points) + " points in front of the camera, need at least 4";
    return out;
  }
  out.sigma_px = std::sqrt(ss / static_cast<double>(2 * out.points - 6));
  // Invert through the eigen-decomposition so a (nearly) singular JᵀJ is seen, not inverted.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(H);
  const double lmax = eig.eigenvalues().maxCoeff();
  if (!(eig.eigenvalues().minCoeff() > 1e-12 * lmax) || !(lmax > 0)) {
    out.why = "JᵀJ is singular (degenerate point configuration)";
    return out;
  }
  out.pose = out.sigma_px * out.sigma_px * eig.eigenvectors() *
             eig.eigenvalues().cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  out.center = center_covariance(out.pose, T_cw);
  out.ok = out.pose.allFinite();
  if (!out.ok) out.why = "covariance is not finite";
  return out;
}

/// Localization standard deviation of a geo view in metres: √(tr Σ_c / 3) (the RMS over the
/// three axes of the centre's sd, rotation-invariant so Σ_νν's trace serves) divided by the
/// map scale at the view (M units per metre, the keyframe's corrected Sim3 scale). 0 when the
/// correspondence carries no covariance (all zero).
inline double localization_sd_m(const Eigen::Matrix<double, 6, 6>& pose_cov,
                                double map_units_per_metre) {
  const double tr = pose_cov.block<3, 3>(3, 3).trace();
  if (!(tr > 0) || !(map_units_per_metre > 0)) return 0.0;
  return std::sqrt(tr / 3.0) / map_units_per_metre;
}

/// Effective standard deviation of a geo term (metres): the geo-tag's and the view's
/// localization error, independent, added in quadrature:  σ_eff = √(σ_tag² + σ_loc²).
inline double effective_geo_sd_m(double sigma_tag_m, double sigma_loc_m) {
  return std::sqrt(sigma_tag_m * sigma_tag_m + sigma_loc_m * sigma_loc_m);
}

}  // namespace geodrift::correction
