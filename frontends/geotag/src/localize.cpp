#include "geodrift/geotag/localize.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "geodrift/correction/pose_refinement.hpp"
#include "geodrift/error.hpp"

namespace geodrift::geotag {

LocalizeResult localize_view(const std::vector<Eigen::Vector3d>& X_m,
                             const std::vector<Eigen::Vector2d>& uv, const map::Camera& cam,
                             const LocalizeOptions& o) {
  GEODRIFT_CHECK(X_m.size() == uv.size(),
                 "localize_view: " << X_m.size() << " points but " << uv.size() << " pixels");
  cam.validate();
  GEODRIFT_CHECK(o.min_correspondences >= 4 && o.min_inliers >= 4,
                 "localize_view: min_correspondences and min_inliers must be >= 4");
  GEODRIFT_CHECK(o.ransac_threshold_px > 0 && o.max_rms_px > 0 && o.ransac_iterations >= 1,
                 "localize_view: RANSAC threshold, RMS limit and iterations must be > 0");
  for (std::size_t i = 0; i < X_m.size(); ++i)
    GEODRIFT_CHECK(X_m[i].allFinite() && uv[i].allFinite(),
                   "localize_view: correspondence " << i << " is not finite");
  LocalizeResult r;
  r.correspondences = static_cast<int>(X_m.size());
  if (r.correspondences < o.min_correspondences) {
    r.reason = std::to_string(r.correspondences) + " 2D-3D pairs, need " +
               std::to_string(o.min_correspondences);
    return r;
  }
  std::vector<cv::Point3d> obj(X_m.size());
  std::vector<cv::Point2d> img(uv.size());
  for (std::size_t i = 0; i < X_m.size(); ++i) {
    obj[i] = {X_m[i].x(), X_m[i].y(), X_m[i].z()};
    img[i] = {uv[i].x(), uv[i].y()};
  }
  const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  cv::Mat rvec, tvec;
  std::vector<int> inl;
  cv::theRNG().state = o.seed;
  bool found = false;
  try {
    found = cv::solvePnPRansac(obj, img, K, cv::noArray(), rvec, tvec, false, o.ransac_iterations,
                               static_cast<float>(o.ransac_threshold_px), o.ransac_confidence, inl,
                               cv::SOLVEPNP_AP3P);
  } catch (const cv::Exception&) {
    found = false;  // degenerate samples (e.g. all points collinear) make OpenCV throw
  }
  const auto ransac_pose = [&] {
    cv::Mat R_cv;
    cv::Rodrigues(rvec, R_cv);
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    cv::cv2eigen(R_cv, R);
    cv::cv2eigen(tvec, t);
    return lie::SE3d(lie::SO3d(R), t);
  };
  if (!found || static_cast<int>(inl.size()) < o.min_inliers) {
    r.reason = "PnP RANSAC found " + std::to_string(inl.size()) + " inliers, need " +
               std::to_string(o.min_inliers);
    if (found && !inl.empty()) {  // the rejected RANSAC estimate, for diagnostics
      r.T_vm = ransac_pose();
      r.inliers = static_cast<int>(inl.size());
    }
    return r;
  }
  lie::SE3d T = ransac_pose();

  // Robust LM on all pairs from the RANSAC pose, then re-select inliers at the refined pose and
  // finish with plain least squares on them (twice: the inlier set can still change).
  const double huber = o.ransac_threshold_px / 2.0;
  T = correction::refine_pose_lm(X_m, uv, cam, T, o.lm_iterations, huber).T_cw;
  std::vector<int> idx;
  correction::PnpResult refined;  // the last plain-LS refinement, on the inliers idx
  for (int round = 0; round < 2; ++round) {
    idx.clear();
    for (std::size_t i = 0; i < X_m.size(); ++i) {
      const Eigen::Vector3d p = T.act(X_m[i]);
      if (p.z() > 0 && (cam.project(p) - uv[i]).norm() <= o.ransac_threshold_px)
        idx.push_back(static_cast<int>(i));
    }
    if (static_cast<int>(idx.size()) < o.min_inliers) break;
    std::vector<Eigen::Vector3d> Xi;
    std::vector<Eigen::Vector2d> ui;
    for (int i : idx) {
      Xi.push_back(X_m[i]);
      ui.push_back(uv[i]);
    }
    refined = correction::refine_pose_lm(Xi, ui, cam, T, o.lm_iterations);
    T = refined.T_cw;
    r.rms_px = refined.rms_px;
  }
  r.T_vm = T;
  r.inliers = static_cast<int>(idx.size());
  r.inlier_indices = idx;
  if (r.inliers < o.min_inliers) {
    r.reason = std::to_string(r.inliers) + " inliers after refinement, need " +
               std::to_string(o.min_inliers);
    return r;
  }
  const double ratio = double(r.inliers) / r.correspondences;
  if (ratio < o.min_inlier_ratio) {
    r.reason =
        "inlier ratio " + std::to_string(ratio) + " below " + std::to_string(o.min_inlier_ratio);
    return r;
  }
  if (!(r.rms_px <= o.max_rms_px)) {
    r.reason = "reprojection RMS " + std::to_string(r.rms_px) + " px above " +
               std::to_string(o.max_rms_px);
    return r;
  }
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (int i : idx) {
    umin = std::min(umin, uv[i].x());
    umax = std::max(umax, uv[i].x());
    vmin = std::min(vmin, uv[i].y());
    vmax = std::max(vmax, uv[i].y());
  }
  if ((umax - umin) < o.min_image_spread * cam.width ||
      (vmax - vmin) < o.min_image_spread * cam.height) {
    r.reason = "inliers cover too small a part of the image (degenerate geometry)";
    return r;
  }
  // The covariance at T on the inliers idx (refine_pose_lm computed it for that last solve).
  if (refined.covariance.ok) r.pose_cov = refined.covariance.pose;
  r.ok = true;
  return r;
}

map::Correspondence make_correspondence(int id, const GeoView& view, const map::Keyframe& kf,
                                        const LocalizeResult& result, const geo::LocalFrame& frame,
                                        double sigma_m) {
  GEODRIFT_CHECK(result.ok,
                 "make_correspondence: the view was not localized (" << result.reason << ")");
  GEODRIFT_CHECK(std::isfinite(sigma_m) && sigma_m > 0,
                 "make_correspondence: sigma " << sigma_m << " m must be > 0");
  map::Correspondence c;
  c.id = id;
  c.keyframe = kf.id;
  c.T_vk = result.T_vm * kf.T_cw.inverse();
  c.y_w = view_position_world(view, frame);
  c.sigma_m = sigma_m;
  c.geotag_id = view.tag.id;
  c.inliers = result.inliers;
  c.reprojection_rms = result.rms_px;
  c.pose_cov = result.pose_cov;
  return c;
}

}  // namespace geodrift::geotag
