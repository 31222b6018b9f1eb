#pragma once

/// @file
/// Geo-tagged image localization (the paper's Sec. 3.3, "Geo-tagged Image Localization"):
/// 2D-3D correspondences between a view's keypoints and map points (through the keyframe's
/// observations, C_map-geo = matches x C_map-kf) -> PnP RANSAC (OpenCV's AP3P minimal solver)
/// -> Levenberg-Marquardt refinement of the view's pose in M with the core solver
/// (solver::ReprojectionResidual, Huber loss, then plain least squares on the inliers) -> the
/// view's pose in M -> a map::Correspondence.
///
/// Acceptance (LocalizeOptions, all documented defaults): at least `min_correspondences`
/// 2D-3D pairs in, at least `min_inliers` RANSAC inliers that are also at least
/// `min_inlier_ratio` of the pairs, final reprojection RMS over the inliers at most
/// `max_rms_px`, all inliers in front of the view camera, and a non-degenerate spread of the
/// inliers in the image (their bounding box covers at least `min_image_spread` of each image
/// side). A rejection says which test failed.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/geotag/views.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/map/camera.hpp"
#include "geodrift/map/correspondence.hpp"
#include "geodrift/map/keyframe.hpp"

namespace geodrift::geotag {

struct LocalizeOptions {
  int min_correspondences = 20;  ///< 2D-3D pairs needed to try at all
  double ransac_threshold_px = 4.0;
  int ransac_iterations = 1000;
  double ransac_confidence = 0.999;
  /// After refinement. 40: on the rendered street world every wrong or poor (> 0.5 m, > 1 deg)
  /// localization had <= 35 inliers; a wrong correspondence costs the Corrector more than a
  /// missing one.
  int min_inliers = 40;
  double min_inlier_ratio = 0.15;  ///< inliers / pairs
  double max_rms_px = 2.5;         ///< reprojection RMS over the inliers
  double min_image_spread = 0.15;  ///< inlier bounding box / image size, each axis
  int lm_iterations = 30;
  std::uint64_t seed = 7;  ///< RANSAC sampling (cv::theRNG) for reproducibility
};

struct LocalizeResult {
  bool ok = false;
  std::string reason;  ///< why it was rejected (empty when ok)
  lie::SE3d T_vm;      ///< M -> view camera (valid when ok, else the last estimate: the
                       ///< RANSAC pose when RANSAC found too few inliers, identity if none)
  int correspondences = 0;
  int inliers = 0;
  double rms_px = 0;
  std::vector<int> inlier_indices;  ///< into the input arrays
  /// Covariance of T_vm over the final inliers (correction::pnp_pose_covariance: σ̂²·(JᵀJ)⁻¹,
  /// tangent (ω, ν), M units); zero when it could not be computed. Passed on to the
  /// Correspondence (pose_cov) by make_correspondence.
  Eigen::Matrix<double, 6, 6> pose_cov = Eigen::Matrix<double, 6, 6>::Zero();
};

/// Localizes a view from 2D-3D pairs (X_m[i] in M, uv[i] in view pixels).
/// @throws InvalidArgument if the sizes differ, a value is not finite, the camera is invalid or
///         the options are out of range.
LocalizeResult localize_view(const std::vector<Eigen::Vector3d>& X_m,
                             const std::vector<Eigen::Vector2d>& uv, const map::Camera& camera,
                             const LocalizeOptions& options = {});

/// The map-to-world correspondence of a view localized against a keyframe (DESIGN.md):
/// T_vk = T_vm * T_km^-1 (fixed relative pose keyframe -> view, M units), y_w = the geo-tag's
/// position in W, inlier count, RMS, and the geo-tag id.
map::Correspondence make_correspondence(int id, const GeoView& view, const map::Keyframe& keyframe,
                                        const LocalizeResult& result, const geo::LocalFrame& frame,
                                        double sigma_m);

}  // namespace geodrift::geotag
