#pragma once

/// @file
/// map::Correspondence: the paper's C_map-world, one geo view (or GNSS fix) localized in the
/// map. It holds the fixed keyframe -> view pose T_vk (SE(3), M units), the geo-tag position
/// y_w in W (metres), its standard deviation sigma_m (metres) and, when PnP produced one, the
/// view pose covariance (tangent (ω, ν), LEFT perturbation, rad² and M units²). This is what
/// the Corrector consumes.

#include <Eigen/Core>

#include "geodrift/lie/se3.hpp"

namespace geodrift::map {

/// A map-to-world correspondence (the paper's C_map-world, Sec. 3.3): one localized geo VIEW.
/// Each of a panorama's 8 views may localize on its own and then carries the panorama's
/// geo-tag. The view's pose is known in M only relative to the keyframe it was localized
/// against; that keyframe bounds the PGO window (DESIGN.md, Correction step 2).
struct Correspondence {
  int id = 0;
  int keyframe = -1;  ///< Keyframe::id the view was localized against
  /// Fixed relative pose keyframe -> view in M's units: T_vw = T_vk · T_kw (view maps M points
  /// into its camera frame through the keyframe's pose). Identity for a GNSS fix at the
  /// keyframe's own camera centre.
  lie::SE3d T_vk;
  Eigen::Vector3d y_w = Eigen::Vector3d::Zero();  ///< geo-tag position in W (metres)
  double sigma_m = 1.0;         ///< standard deviation of y_w, metres (BA geo-term weight)
  int geotag_id = -1;           ///< GeoTag::id, -1 when the anchor came without one
  int inliers = 0;              ///< PnP inlier count (0 for anchors read from a file)
  double reprojection_rms = 0;  ///< pixels
  /// Covariance of the view's pose T_vw in M from its localization (PnP + LM: σ̂²·(JᵀJ)⁻¹ with
  /// σ̂² the reprojection residual variance, correction::pnp_pose_covariance), tangent (ω, ν),
  /// LEFT perturbation, rad² and M units². All zero when unknown (anchors read from a file, a
  /// GNSS fix): the Corrector then weights the geo term by sigma_m alone.
  Eigen::Matrix<double, 6, 6> pose_cov = Eigen::Matrix<double, 6, 6>::Zero();

  /// True when pose_cov was filled in by the localization.
  bool has_pose_covariance() const { return pose_cov.block<3, 3>(3, 3).trace() > 0; }
  /// True for a view localized in the map (PnP inliers or a pose covariance); false for a
  /// direct position fix of the keyframe (an anchor read from a file, a GNSS fix), whose
  /// sigma_m is then the whole uncertainty of the geo term.
  bool localized() const { return inliers > 0 || has_pose_covariance(); }
};

}  // namespace geodrift::map
