#pragma once
/// @file
/// Two-view initialisation of a monocular map (ORB-SLAM's initializer, Mur-Artal et al. 2015,
/// Sec. IV): an essential matrix and a homography are fitted in parallel by RANSAC, scored by
/// their symmetric transfer errors (S_E, S_H), the homography is chosen when
/// R_H = S_H / (S_H + S_E) > homography_ratio, and the chosen model's motion hypotheses are
/// triangulated with cheirality, reprojection and parallax checks. The result fails with a reason
/// (too few matches, pure rotation / too little parallax, ambiguous homography solution).
/// The accepted solution is refined by a two-view bundle adjustment through the core solver.
///
/// Conventions: pixels of the undistorted images, OpenCV camera (x right, y down, z forward);
/// the result is T_21 (camera 1 -> camera 2) with a unit baseline |t| = 1, which fixes the
/// map's arbitrary scale, and points in camera 1's frame.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "geodrift/lie/se3.hpp"
#include "geodrift/map/camera.hpp"

namespace geodrift::vo {

struct TwoViewOptions {
  double sigma_px = 1.0;             ///< measurement noise, pixels (scores and checks)
  double ransac_threshold_px = 1.5;  ///< RANSAC inlier threshold of both models, pixels
  double homography_ratio = 0.45;  ///< R_H above which the homography is used (ORB-SLAM 0.40-0.45)
  double min_parallax_deg = 1.0;   ///< the `parallax_rank`-th largest parallax must exceed it
  int parallax_rank = 50;          ///< ORB-SLAM uses the 50th
  double min_derotated_flow_px = 3.0;  ///< median inlier motion beyond the rotation, pixels
  int min_matches = 100;               ///< fewer putative matches: fail without trying
  int min_triangulated = 50;           ///< good points needed
  double min_good_ratio = 0.5;         ///< good points / model inliers needed
  bool refine = true;                  ///< two-view BA (core solver) of the chosen solution
};

struct TwoViewResult {
  bool ok = false;
  std::string reason;  ///< why it failed (empty on success)
  enum class Model { kNone, kEssential, kHomography } model = Model::kNone;
  lie::SE3d T_21;                       ///< camera 1 -> camera 2, |t| = 1 (unit baseline)
  std::vector<Eigen::Vector3d> points;  ///< per input match: point in camera-1 frame
  std::vector<char> good;               ///< per input match: triangulated and passed every check
  int num_good = 0;
  int num_inliers = 0;  ///< inliers of the chosen model
  double score_h = 0, score_e = 0;
  double parallax_deg = 0;  ///< the parallax_rank-th largest parallax of good points
  double median_parallax_deg = 0;
  double derotated_flow_px = 0;  ///< median rotation-compensated inlier flow (pure-rotation test)
};

/// Initialises from matched undistorted pixels x1[i] <-> x2[i] of two views of `camera`.
/// Never throws on degenerate geometry: it returns ok = false with a reason.
/// @throws InvalidArgument when x1 and x2 differ in size.
TwoViewResult initialize_two_view(const std::vector<Eigen::Vector2d>& x1,
                                  const std::vector<Eigen::Vector2d>& x2, const map::Camera& camera,
                                  const TwoViewOptions& options = {});

/// Linear (DLT) triangulation of one point from two 3x4 projections of normalised coordinates.
Eigen::Vector3d triangulate_dlt(const Eigen::Matrix<double, 3, 4>& P1,
                                const Eigen::Matrix<double, 3, 4>& P2, const Eigen::Vector2d& n1,
                                const Eigen::Vector2d& n2);

}  // namespace geodrift::vo
