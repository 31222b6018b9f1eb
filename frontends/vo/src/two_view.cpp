// Two-view initialisation: essential matrix vs homography, ORB-SLAM style scoring and checks.

#include "geodrift/vo/two_view.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <sstream>

#include "geodrift/error.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"

namespace geodrift::vo {
namespace {

// Chi-square quantiles at 95 %: 1 dof (point-line distance) and 2 dof (point-point).
constexpr double kChi2_1 = 3.841, kChi2_2 = 5.991;

struct Hypothesis {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
};

struct CheckResult {
  int good = 0;
  double parallax_rank_deg = 0, median_deg = 0;
  std::vector<Eigen::Vector3d> points;
  std::vector<char> good_mask;
};

/// Triangulates the inliers under x2 ~ K(R x1 + t) and counts points passing cheirality in both
/// cameras, reprojection error below 2 sigma in both, and parallax above ~0.36 deg (ORB-SLAM's
/// cos 0.99998: below it the depth is unobservable).
CheckResult check_motion(const Hypothesis& h, const std::vector<Eigen::Vector2d>& x1,
                         const std::vector<Eigen::Vector2d>& x2, const std::vector<char>& inlier,
                         const map::Camera& cam, const TwoViewOptions& o) {
  CheckResult r;
  r.points.assign(x1.size(), Eigen::Vector3d::Zero());
  r.good_mask.assign(x1.size(), 0);
  Eigen::Matrix<double, 3, 4> P1, P2;
  P1 << Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero();
  P2 << h.R, h.t;
  const Eigen::Vector3d O2 = -h.R.transpose() * h.t;
  const double th2 = 4.0 * o.sigma_px * o.sigma_px;
  std::vector<double> parallax;
  for (std::size_t i = 0; i < x1.size(); ++i) {
    if (!inlier[i]) continue;
    const Eigen::Vector2d n1((x1[i].x() - cam.cx) / cam.fx, (x1[i].y() - cam.cy) / cam.fy);
    const Eigen::Vector2d n2((x2[i].x() - cam.cx) / cam.fx, (x2[i].y() - cam.cy) / cam.fy);
    const Eigen::Vector3d X = triangulate_dlt(P1, P2, n1, n2);
    if (!X.allFinite()) continue;
    const Eigen::Vector3d X2 = h.R * X + h.t;
    const Eigen::Vector3d a = X, b = X - O2;
    const double cosp = a.dot(b) / (a.norm() * b.norm());
    if (X.z() <= 0 || X2.z() <= 0 || !(cosp < 0.99998)) continue;
    const Eigen::Vector2d u1(cam.fx * X.x() / X.z() + cam.cx, cam.fy * X.y() / X.z() + cam.cy);
    const Eigen::Vector2d u2(cam.fx * X2.x() / X2.z() + cam.cx, cam.fy * X2.y() / X2.z() + cam.cy);
    if ((u1 - x1[i]).squaredNorm() > th2 || (u2 - x2[i]).squaredNorm() > th2) continue;
    r.points[i] = X;
    r.good_mask[i] = 1;
    ++r.good;
    parallax.push_back(std::acos(std::clamp(cosp, -1.0, 1.0)) * 180.0 / M_PI);
  }
  if (!parallax.empty()) {
    std::sort(parallax.begin(), parallax.end(), std::greater<double>());
    const std::size_t k = std::min<std::size_t>(o.parallax_rank, parallax.size() - 1);
    r.parallax_rank_deg = parallax[k];
    r.median_deg = parallax[parallax.size() / 2];
  }
  return r;
}

Eigen::Vector2d apply_h(const Eigen::Matrix3d& H, const Eigen::Vector2d& x) {
  const Eigen::Vector3d y = H * x.homogeneous();
  return y.hnormalized();
}

/// Two-view bundle adjustment through the core solver (camera 1 fixed at the origin, Huber on
/// chi2(2)), then the baseline is rescaled to 1. The minimal-solver motion is only as good as
/// its RANSAC sample; this uses every good point.
void refine_two_view(const std::vector<Eigen::Vector2d>& x1, const std::vector<Eigen::Vector2d>& x2,
                     const map::Camera& cam, const TwoViewOptions& o, TwoViewResult* res) {
  lie::SE3d T1, T2 = res->T_21;
  solver::Problem problem;
  solver::ReprojectionResidual r;
  r.fx = cam.fx;
  r.fy = cam.fy;
  r.cx = cam.cx;
  r.cy = cam.cy;
  const double info = 1.0 / (o.sigma_px * o.sigma_px);
  const auto loss = solver::RobustLoss::huber(std::sqrt(kChi2_2));
  for (std::size_t i = 0; i < x1.size(); ++i) {
    if (!res->good[i]) continue;
    r.uv = x1[i];
    problem.add_residual_block(r, loss, info, &T1, &res->points[i]);
    r.uv = x2[i];
    problem.add_residual_block(r, loss, info, &T2, &res->points[i]);
  }
  problem.set_constant(&T1);
  solver::Options so;
  so.linear_solver = solver::LinearSolverType::kSchur;
  so.max_iterations = 20;
  const solver::Summary s = solver::LevenbergMarquardt(so).solve(&problem);
  const double b = T2.translation().norm();
  if (s.final_cost > s.initial_cost || !(b > 1e-9) || !T2.matrix().allFinite()) return;
  res->T_21 = lie::SE3d(T2.rotation(), T2.translation() / b);
  for (std::size_t i = 0; i < x1.size(); ++i) {
    if (!res->good[i]) continue;
    res->points[i] /= b;
    const Eigen::Vector3d c2 = res->T_21.act(res->points[i]);
    if (!(res->points[i].z() > 0 && c2.z() > 0)) {
      res->good[i] = 0;
      --res->num_good;
    }
  }
}

}  // namespace

Eigen::Vector3d triangulate_dlt(const Eigen::Matrix<double, 3, 4>& P1,
                                const Eigen::Matrix<double, 3, 4>& P2, const Eigen::Vector2d& n1,
                                const Eigen::Vector2d& n2) {
  Eigen::Matrix4d A;
  A.row(0) = n1.x() * P1.row(2) - P1.row(0);
  A.row(1) = n1.y() * P1.row(2) - P1.row(1);
  A.row(2) = n2.x() * P2.row(2) - P2.row(0);
  A.row(3) = n2.y() * P2.row(2) - P2.row(1);
  const Eigen::JacobiSVD<Eigen::Matrix4d> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d X = svd.matrixV().col(3);
  if (std::abs(X[3]) < 1e-12) return Eigen::Vector3d::Constant(std::nan(""));
  return X.head<3>() / X[3];
}

TwoViewResult initialize_two_view(const std::vector<Eigen::Vector2d>& x1,
                                  const std::vector<Eigen::Vector2d>& x2, const map::Camera& cam,
                                  const TwoViewOptions& o) {
  GEODRIFT_CHECK(x1.size() == x2.size(),
                 "two-view init: " << x1.size() << " vs " << x2.size() << " points");
  TwoViewResult res;
  const int n = static_cast<int>(x1.size());
  if (n < o.min_matches) {
    res.reason =
        "only " + std::to_string(n) + " matches (need " + std::to_string(o.min_matches) + ")";
    return res;
  }
  std::vector<cv::Point2d> p1(n), p2(n);
  for (int i = 0; i < n; ++i) {
    p1[i] = {x1[i].x(), x1[i].y()};
    p2[i] = {x2[i].x(), x2[i].y()};
  }
  const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  cv::Mat maskE, maskH;
  const cv::Mat Ecv =
      cv::findEssentialMat(p1, p2, K, cv::RANSAC, 0.999, o.ransac_threshold_px, maskE);
  const cv::Mat Hcv =
      cv::findHomography(p1, p2, cv::RANSAC, o.ransac_threshold_px, maskH, 2000, 0.999);
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero(), H = Eigen::Matrix3d::Zero();
  const bool haveE = Ecv.rows == 3 && Ecv.cols == 3;  // may stack several solutions: take first
  const bool haveH = Hcv.rows == 3 && Hcv.cols == 3;
  if (haveE) cv::cv2eigen(Ecv.rowRange(0, 3), E);
  if (haveH) cv::cv2eigen(Hcv, H);
  if (!haveE && !haveH) {
    res.reason = "neither an essential matrix nor a homography could be fitted";
    return res;
  }

  // ORB-SLAM scores: sum over both transfer directions of (chi2_2 - d^2/sigma^2) for inliers.
  Eigen::Matrix3d Kinv;
  Kinv << 1 / cam.fx, 0, -cam.cx / cam.fx, 0, 1 / cam.fy, -cam.cy / cam.fy, 0, 0, 1;
  const Eigen::Matrix3d F = Kinv.transpose() * E * Kinv;
  const Eigen::Matrix3d Hinv = haveH ? Eigen::Matrix3d(H.inverse()) : Eigen::Matrix3d::Zero();
  const double is2 = 1.0 / (o.sigma_px * o.sigma_px);
  std::vector<char> inE(n, 0), inH(n, 0);
  int nE = 0, nH = 0;
  for (int i = 0; i < n; ++i) {
    if (haveH) {
      const double c21 = (apply_h(H, x1[i]) - x2[i]).squaredNorm() * is2;
      const double c12 = (apply_h(Hinv, x2[i]) - x1[i]).squaredNorm() * is2;
      if (c21 < kChi2_2 && c12 < kChi2_2) {
        res.score_h += 2 * kChi2_2 - c21 - c12;
        inH[i] = 1;
        ++nH;
      }
    }
    if (haveE) {
      const Eigen::Vector3d l2 = F * x1[i].homogeneous();
      const Eigen::Vector3d l1 = F.transpose() * x2[i].homogeneous();
      const double d2 = l2.dot(x2[i].homogeneous()), d1 = l1.dot(x1[i].homogeneous());
      const double c2 = d2 * d2 / l2.head<2>().squaredNorm() * is2;
      const double c1 = d1 * d1 / l1.head<2>().squaredNorm() * is2;
      if (c2 < kChi2_1 && c1 < kChi2_1) {
        res.score_e += 2 * kChi2_2 - c1 - c2;
        inE[i] = 1;
        ++nE;
      }
    }
  }
  const double rh = res.score_h / std::max(1e-12, res.score_h + res.score_e);
  const bool use_h = haveH && (rh > o.homography_ratio || !haveE);
  res.model = use_h ? TwoViewResult::Model::kHomography : TwoViewResult::Model::kEssential;
  const std::vector<char>& inl = use_h ? inH : inE;
  res.num_inliers = use_h ? nH : nE;

  std::vector<Hypothesis> hyps;
  if (use_h) {
    std::vector<cv::Mat> Rs, ts, ns;
    cv::decomposeHomographyMat(Hcv, K, Rs, ts, ns);
    for (std::size_t k = 0; k < Rs.size(); ++k) {
      Hypothesis h;
      cv::cv2eigen(Rs[k], h.R);
      cv::cv2eigen(ts[k], h.t);
      if (h.t.norm() < 1e-9) continue;  // pure rotation: no baseline at all
      h.t.normalize();
      hyps.push_back(h);
    }
  } else {
    cv::Mat R1, R2, t;
    cv::decomposeEssentialMat(Ecv.rowRange(0, 3), R1, R2, t);
    Eigen::Matrix3d eR1, eR2;
    Eigen::Vector3d et;
    cv::cv2eigen(R1, eR1);
    cv::cv2eigen(R2, eR2);
    cv::cv2eigen(t, et);
    hyps = {{eR1, et}, {eR1, -et}, {eR2, et}, {eR2, -et}};
  }
  std::ostringstream model;
  model << (use_h ? "homography" : "essential matrix") << " (R_H " << rh << ", " << res.num_inliers
        << " inliers of " << n << ")";
  if (hyps.empty()) {
    res.reason = "pure rotation: the " + model.str() + " has no translation";
    return res;
  }
  std::vector<CheckResult> checks;
  for (const auto& h : hyps) checks.push_back(check_motion(h, x1, x2, inl, cam, o));
  std::size_t best = 0;
  for (std::size_t k = 1; k < checks.size(); ++k)
    if (checks[k].good > checks[best].good) best = k;
  int second = 0;
  for (std::size_t k = 0; k < checks.size(); ++k)
    if (k != best) second = std::max(second, checks[k].good);
  const CheckResult& c = checks[best];
  res.parallax_deg = c.parallax_rank_deg;
  res.median_parallax_deg = c.median_deg;
  res.num_good = c.good;
  std::ostringstream why;
  if (c.parallax_rank_deg < o.min_parallax_deg) {
    why << "too little parallax (pure rotation or too short baseline): parallax "
        << c.parallax_rank_deg << " deg < " << o.min_parallax_deg << " deg, " << model.str();
  } else if (c.good < o.min_triangulated || c.good < o.min_good_ratio * res.num_inliers) {
    why << "only " << c.good << " of " << res.num_inliers
        << " inliers triangulate with positive depth, low reprojection error and parallax, "
        << model.str();
  } else if (second > 0.75 * c.good) {
    why << "ambiguous motion: two solutions triangulate " << c.good << " and " << second
        << " points, " << model.str();
  }
  res.reason = why.str();
  if (!res.reason.empty()) return res;
  res.ok = true;
  res.T_21 = lie::SE3d(lie::SO3d(hyps[best].R), hyps[best].t);
  res.points = c.points;
  res.good = c.good_mask;
  if (o.refine) refine_two_view(x1, x2, cam, o, &res);
  return res;
}

}  // namespace geodrift::vo
