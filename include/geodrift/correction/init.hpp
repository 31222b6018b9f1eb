#pragma once

/// @file
/// INIT (paper Sec. 3.4; DESIGN.md "Correction" step 1): the first map -> world similarity,
/// S_wm with p_W = S_wm·p_M. It levels the map (the PCA plane of the camera centres gets W's
/// up, +z), then fits a horizontal similarity (a, b, s = exp(σ), θ) plus a height offset c to
/// the correspondences, by RANSAC and LM. Inputs: centres and anchors in M (any unit), geo-tags
/// in W (metres). Degenerate input (coincident anchors, too few inliers) gives ok = false and a
/// reason, never an arbitrary transform.

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <random>
#include <string>
#include <vector>

#include "geodrift/correction/residuals/init_similarity.hpp"
#include "geodrift/error.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"

namespace geodrift::correction {

/// Options of INIT (paper Sec. 3.4; DESIGN.md "Correction" step 1).
struct InitOptions {
  /// Number of correspondences INIT waits for (the paper's i = 4). Must be >= 2.
  int num_correspondences = 4;
  /// RANSAC inlier threshold on |A(p') − y| in metres (W).
  double ransac_threshold_m = 5.0;
  /// RANSAC hypotheses (each from 2 correspondences); all pairs are tried when there are
  /// fewer pairs than this.
  int ransac_max_hypotheses = 500;
  /// Anchors whose horizontal positions (in W, or in the levelled map relative to the map's
  /// extent) all lie within this distance make scale and yaw unobservable: reported.
  double min_anchor_spread_m = 1.0;
  /// Camera centres whose second principal extent is below this fraction of the first are
  /// collinear: the plane normal is then taken from the cameras' mean up vector instead.
  double plane_collinearity_ratio = 1e-2;
  unsigned seed = 1;

  /// @return false (and why) when an option is outside its domain.
  bool validate(std::string* why) const {
    auto fail = [&](const std::string& m) {
      if (why) *why = m;
      return false;
    };
    if (num_correspondences < 2)
      return fail("init num_correspondences " + std::to_string(num_correspondences) +
                  " must be >= 2");
    if (!(ransac_threshold_m > 0)) return fail("init ransac_threshold_m must be > 0");
    if (ransac_max_hypotheses < 1) return fail("init ransac_max_hypotheses must be >= 1");
    if (!(min_anchor_spread_m >= 0)) return fail("init min_anchor_spread_m must be >= 0");
    if (!(plane_collinearity_ratio > 0 && plane_collinearity_ratio < 1))
      return fail("init plane_collinearity_ratio must be in (0, 1)");
    return true;
  }
};

/// Outcome of INIT. When `ok` is false, `message` names the degeneracy (coincident anchors,
/// too few inliers, ...) and S_wm is the identity: never a garbage transform.
struct InitResult {
  bool ok = false;
  std::string message;
  lie::Sim3d S_wm;                                        ///< p_W = S_wm · p_M
  Eigen::Matrix3d R_level = Eigen::Matrix3d::Identity();  ///< M -> levelled map (normal -> +z)
  Eigen::Matrix<double, 5, 1> params = Eigen::Matrix<double, 5, 1>::Zero();  ///< (a,b,σ,θ,c)
  std::vector<int> inliers;           ///< indices of the correspondences used in the final fit
  double rms_m = 0.0;                 ///< RMS of |A(p') − y| over the inliers, metres
  bool plane_from_camera_up = false;  ///< camera centres were collinear: normal from camera up
};

namespace detail {

/// Rotation taking unit vector n to +z by the smallest angle (Rodrigues about n × z).
inline Eigen::Matrix3d rotation_to_z(const Eigen::Vector3d& n) {
  const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d axis = n.cross(z);
  const double sin_a = axis.norm(), cos_a = n.dot(z);
  if (sin_a < 1e-12) {
    // n is ±z: identity, or a half turn about x.
    return cos_a > 0 ? Eigen::Matrix3d::Identity()
                     : Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal());
  }
  return lie::SO3d::exp(axis / sin_a * std::atan2(sin_a, cos_a)).matrix();
}

/// Closed-form horizontal similarity from levelled map points to W through complex
/// least squares: w = q·m + t with q = s·e^{iθ}; heights: c = mean(y_z − s·p'_z).
/// Returns false when the map points coincide horizontally.
inline bool fit_similarity_closed_form(const std::vector<Eigen::Vector3d>& p,
                                       const std::vector<Eigen::Vector3d>& y,
                                       const std::vector<int>& idx,
                                       Eigen::Matrix<double, 5, 1>* x) {
  using C = std::complex<double>;
  C mp(0, 0), my(0, 0);
  for (int i : idx) {
    mp += C(p[i].x(), p[i].y());
    my += C(y[i].x(), y[i].y());
  }
  const double n = static_cast<double>(idx.size());
  mp /= n;
  my /= n;
  C num(0, 0);
  double den = 0;
  for (int i : idx) {
    const C a = C(p[i].x(), p[i].y()) - mp, b = C(y[i].x(), y[i].y()) - my;
    num += std::conj(a) * b;
    den += std::norm(a);
  }
  if (!(den > 1e-24) || std::abs(num) <= 0) return false;
  const C q = num / den;
  const double s = std::abs(q), theta = std::arg(q);
  const C t = my - q * mp;
  double c = 0;
  for (int i : idx) c += y[i].z() - s * p[i].z();
  *x << t.real(), t.imag(), std::log(s), theta, c / n;
  return true;
}

/// Largest horizontal (x, y) distance between two of `points`, exactly, in O(n log n): the
/// convex hull (monotone chain), then its antipodal pairs (rotating calipers).
inline double planar_diameter(const std::vector<Eigen::Vector3d>& points) {
  std::vector<Eigen::Vector2d> q(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) q[i] = points[i].head<2>();
  std::sort(q.begin(), q.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  q.erase(std::unique(q.begin(), q.end()), q.end());
  const int n = static_cast<int>(q.size());
  if (n < 2) return 0.0;
  auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  std::vector<Eigen::Vector2d> hull(2 * n);  // counter-clockwise, no collinear vertices
  int m = 0;
  for (int i = 0; i < n; ++i) {
    while (m >= 2 && cross(hull[m - 2], hull[m - 1], q[i]) <= 0) --m;
    hull[m++] = q[i];
  }
  for (int i = n - 2, lower = m + 1; i >= 0; --i) {
    while (m >= lower && cross(hull[m - 2], hull[m - 1], q[i]) <= 0) --m;
    hull[m++] = q[i];
  }
  --m;                                              // the last vertex repeats the first
  if (m < 3) return (q.back() - q.front()).norm();  // collinear: the sorted extremes
  double best = 0;
  for (int i = 0, j = 1; i < m; ++i) {
    const int ni = (i + 1) % m;
    // Advance j while it moves away from edge (i, i+1): the vertex farthest from the edge.
    while (cross(hull[i], hull[ni], hull[(j + 1) % m]) > cross(hull[i], hull[ni], hull[j]))
      j = (j + 1) % m;
    best = std::max({best, (hull[i] - hull[j]).norm(), (hull[ni] - hull[j]).norm()});
  }
  return best;
}

}  // namespace detail

/// INIT (paper Sec. 3.4): levels the map by the PCA plane of the camera centres (normal -> W's
/// up, sign chosen so cameras stay upright), then fits the horizontal similarity (a, b, s, θ)
/// plus a height offset c to the correspondences by RANSAC over 2-point hypotheses and LM on
/// the inliers (core solver), s = exp(σ) > 0 by construction.
///
/// @param centres_m  camera centres of the keyframes so far (M) — the plane is fitted to them
/// @param up_m       each keyframe camera's up direction in M (−y axis of the camera, i.e.
///                   −R_cwᵀ·e_y); decides the normal's sign and replaces a degenerate plane
/// @param anchor_m   correspondence positions in M (geo view camera centres)
/// @param anchor_w   their geo-tag positions in W (metres)
/// @return S_wm with p_W = S_wm·p_M, or ok = false with the reason (coincident anchors, too
///         few inliers). @throws InvalidArgument on non-finite input or size mismatch.
inline InitResult estimate_init(const std::vector<Eigen::Vector3d>& centres_m,
                                const std::vector<Eigen::Vector3d>& up_m,
                                const std::vector<Eigen::Vector3d>& anchor_m,
                                const std::vector<Eigen::Vector3d>& anchor_w,
                                const InitOptions& options = {}) {
  std::string why;
  GEODRIFT_CHECK(options.validate(&why), why);
  GEODRIFT_CHECK(centres_m.size() == up_m.size(), "init: " << centres_m.size()
                                                           << " camera centres but " << up_m.size()
                                                           << " up vectors");
  GEODRIFT_CHECK(anchor_m.size() == anchor_w.size(),
                 "init: " << anchor_m.size() << " anchors in M but " << anchor_w.size() << " in W");
  for (std::size_t i = 0; i < centres_m.size(); ++i)
    GEODRIFT_CHECK(centres_m[i].allFinite() && up_m[i].allFinite(),
                   "init: keyframe " << i << " centre or up vector is not finite");
  for (std::size_t i = 0; i < anchor_m.size(); ++i)
    GEODRIFT_CHECK(anchor_m[i].allFinite() && anchor_w[i].allFinite(),
                   "init: correspondence " << i << " position is not finite");

  InitResult out;
  const int n = static_cast<int>(anchor_m.size());
  if (n < options.num_correspondences) {
    out.message = "init: " + std::to_string(n) + " correspondences, " +
                  std::to_string(options.num_correspondences) + " needed";
    return out;
  }

  // ---- 1. level the map: PCA plane of the camera centres --------------------------------
  Eigen::Vector3d up_mean = Eigen::Vector3d::Zero();
  for (const auto& u : up_m) up_mean += u;
  if (up_mean.norm() < 1e-12) up_mean = Eigen::Vector3d::UnitZ();
  up_mean.normalize();
  Eigen::Vector3d normal = up_mean;
  if (centres_m.size() >= 3) {
    Eigen::Vector3d mu = Eigen::Vector3d::Zero();
    for (const auto& c : centres_m) mu += c;
    mu /= static_cast<double>(centres_m.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& c : centres_m) cov += (c - mu) * (c - mu).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);  // ascending eigenvalues
    const Eigen::Vector3d ev = eig.eigenvalues().cwiseMax(0.0);
    if (ev[2] > 0 && std::sqrt(ev[1] / ev[2]) >= options.plane_collinearity_ratio) {
      normal = eig.eigenvectors().col(0);
    } else {
      // Collinear (a straight road) or coincident centres: the plane is undetermined about the
      // line. The cameras' mean up vector, made orthogonal to the line, is the best normal.
      const Eigen::Vector3d line = eig.eigenvectors().col(2);
      Eigen::Vector3d u = up_mean - up_mean.dot(line) * line;
      normal = u.norm() > 1e-9 ? u.normalized() : up_mean;
      out.plane_from_camera_up = true;
    }
  } else {
    out.plane_from_camera_up = true;
  }
  if (normal.dot(up_mean) < 0) normal = -normal;  // cameras upright
  out.R_level = detail::rotation_to_z(normal.normalized());

  std::vector<Eigen::Vector3d> p(n);
  for (int i = 0; i < n; ++i) p[i] = out.R_level * anchor_m[i];

  // ---- 2. degeneracy: coincident anchors leave scale and yaw unobservable -----------------
  double extent_m = 0;
  for (int i = 0; i < n; ++i) extent_m = std::max(extent_m, p[i].head<2>().norm());
  const double spread_w = detail::planar_diameter(anchor_w);
  const double spread_m = detail::planar_diameter(p);
  if (spread_w < options.min_anchor_spread_m) {
    out.message = "init: the correspondences' geo-tags all lie within " + std::to_string(spread_w) +
                  " m of each other (minimum spread " +
                  std::to_string(options.min_anchor_spread_m) +
                  " m): scale and yaw are unobservable";
    return out;
  }
  if (!(spread_m > 1e-9 * std::max(1.0, extent_m))) {
    out.message =
        "init: the correspondences coincide in the map: scale and yaw are "
        "unobservable";
    return out;
  }

  // ---- 3. RANSAC over 2-point hypotheses ---------------------------------------------------
  std::vector<std::pair<int, int>> pairs;
  const long long all_pairs = static_cast<long long>(n) * (n - 1) / 2;
  if (all_pairs <= options.ransac_max_hypotheses) {
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j) pairs.push_back({i, j});
  } else {
    std::mt19937 rng(options.seed);
    std::uniform_int_distribution<int> pick(0, n - 1);
    while (static_cast<int>(pairs.size()) < options.ransac_max_hypotheses) {
      const int i = pick(rng), j = pick(rng);
      if (i != j) pairs.push_back({std::min(i, j), std::max(i, j)});
    }
  }
  const double thr2 = options.ransac_threshold_m * options.ransac_threshold_m;
  std::vector<int> best;
  double best_sse = 0;
  for (const auto& [i, j] : pairs) {
    Eigen::Matrix<double, 5, 1> x;
    if (!detail::fit_similarity_closed_form(p, anchor_w, {i, j}, &x)) continue;
    std::vector<int> in;
    double sse = 0;
    for (int k = 0; k < n; ++k) {
      const double e2 = (InitSimilarityResidual::apply(x, p[k]) - anchor_w[k]).squaredNorm();
      if (e2 <= thr2) {
        in.push_back(k);
        sse += e2;
      }
    }
    if (in.size() > best.size() || (in.size() == best.size() && sse < best_sse)) {
      best = std::move(in);
      best_sse = sse;
    }
  }
  if (static_cast<int>(best.size()) < 2) {
    out.message = "init: no 2 correspondences agree on a similarity within " +
                  std::to_string(options.ransac_threshold_m) + " m";
    return out;
  }

  // ---- 4. LM on the inliers (core solver), started from the closed form --------------------
  Eigen::Matrix<double, 5, 1> x;
  if (!detail::fit_similarity_closed_form(p, anchor_w, best, &x)) {
    out.message = "init: inlier correspondences coincide in the map";
    return out;
  }
  solver::Problem problem;
  for (int k : best)
    problem.add_residual_block(InitSimilarityResidual{p[k], anchor_w[k]}, solver::RobustLoss(), 1.0,
                               &x);
  solver::Options lm;
  lm.linear_solver = solver::LinearSolverType::kDense;
  lm.function_tolerance = 1e-12;
  const solver::Summary summary = solver::LevenbergMarquardt(lm).solve(&problem);
  if (!summary.converged() && summary.termination != solver::Termination::kMaxIterations &&
      summary.termination != solver::Termination::kNoDecrease) {
    out.message = "init: similarity refinement failed: " + summary.message;
    return out;
  }
  double sse = 0;
  for (int k : best) sse += (InitSimilarityResidual::apply(x, p[k]) - anchor_w[k]).squaredNorm();

  out.ok = true;
  out.params = x;
  out.inliers = best;
  out.rms_m = std::sqrt(sse / static_cast<double>(best.size()));
  const Eigen::Matrix3d Rz = Eigen::AngleAxisd(x[3], Eigen::Vector3d::UnitZ()).toRotationMatrix();
  out.S_wm = lie::Sim3d(lie::SO3d(Eigen::Matrix3d(Rz * out.R_level)),
                        Eigen::Vector3d(x[0], x[1], x[4]), std::exp(x[2]));
  return out;
}

}  // namespace geodrift::correction
