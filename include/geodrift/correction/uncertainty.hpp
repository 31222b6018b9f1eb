#pragma once

/// @file
/// Horizontal position uncertainty of a corrected path (issue 24 item 4): per keyframe, the
/// 2×2 covariance of its camera centre in W (x = east, y = north of the UTM grid, metres).
///
/// ## Model
/// The posterior of the keyframe poses given what the correction used, linearised at its
/// optimum (the Laplace approximation), under the monocular drift model of
/// correction/drift_model.hpp — the same for every correction mode, so the figure describes the
/// data, not the estimator:
///   - a Sim(3) chain over the keyframes: edge i−1→i measures the raw VO step
///     ΔS_i = T_cw,i · T_cw,i−1⁻¹ with the drift model's information over the step's length and
///     turn (a random walk: the VO's errors add in variance along the path, so only
///     consecutive keyframes are linked; covisibility edges would count the same error twice);
///   - per anchor in use (Corrector::correspondences()): a view node joined to its keyframe by
///     the fixed offset T_vk (drift model over the offset, plus the view's PnP covariance
///     where it has one) and a camera-centre prior at the geo-tag with σ = sigma_m.
/// Σ = H⁻¹ from solver::Covariance at the optimum, Σ_c = (1/s²)·Rᵀ·Σ_νν·R per keyframe.
///
/// ## About the corrected path
/// That posterior is centred on the drift model's own estimate m_i, but the path the user gets
/// is the Corrector's, c_i (its mode and weighting: the paper's PGO, BA, ...), which lies a
/// distance d_i = c_i − m_i away from it. What the user needs is the spread of the truth x_i
/// about c_i: under the posterior x_i ~ N(m_i, Σ_i), E[(x_i − c_i)(x_i − c_i)ᵀ] = Σ_i + d_i·d_iᵀ
/// (the mean squared error matrix: variance plus squared bias). `cov_en` is that matrix;
/// `posterior_cov_en` is Σ_i alone, about `map_estimate_w` (Σ_i in both widened by
/// region_factor, below). Where the Corrector agrees with the model (kDriftModel weights, at the
/// anchors) the two coincide; between sparse anchors, where the paper's weighting spreads the
/// misfit differently from the model, the bias term widens the ellipse along the direction the
/// two estimates disagree.
///
/// ## The drift level and the anchors' quality
/// A VO's drift differs from the model's nominal numbers by a factor (camera, texture, speed),
/// and anchors are often worse than their stated σ. Two variance factors, k_d on every chain
/// edge and k_a on each anchor's e2 + e3, are estimated from the data by variance-component
/// estimation (Helmert; Förstner 1979, "Ein Verfahren zur Schätzung von Varianz- und
/// Kovarianzkomponenten"): each group must explain its own weighted squared residuals with its
/// own redundancy,
///     k_g ← k_g · χ²_g / r_g,   r_A = Σ_anchor rows (1 − (W·J·Σ·Jᵀ)_rr),   r_D = (m − n) − r_A,
/// iterated to a fixed point (m residuals, n free tangent columns). A group with redundancy
/// below `min_redundancy` keeps its factor at 1, and the message says so.
///
/// ## Prediction
/// The fit's residuals see the drift only where the anchors are. A VO whose errors are not the
/// model's random walk (a scale that fluctuates over tens of metres and averages out over an
/// anchor interval, heading lost in a few turns) fits its anchors well and still strays
/// between them: on the simulator's KITTI 02 the fit said k_d ≈ 0.5 while the errors between
/// anchors were 2–3× larger in variance than that predicts. What the ellipses claim is a
/// prediction — where the truth is, away from the anchors — so k_d is finally set by that:
/// leave each anchor out and compare its tag with where the chain and the other anchors put
/// it. For a linear(ised) least-squares fit this needs no re-solve: with e_j = c(V_j) − y_j the
/// fit's residual, C_j the tag's covariance and Σ_c,j the fitted centre's, the left-out
/// residual is ẽ_j = C_j·(C_j − Σ_c,j)⁻¹·e_j with covariance C_j·(C_j − Σ_c,j)⁻¹·C_j (the whole
/// 3D tag left out), and its horizontal part is tested:
///     t_j = ẽ_hᵀ·(Cov ẽ)_hh⁻¹·ẽ_h,   E t_j = 2 when the factors are right
/// (Baarda's data snooping, studentised). k_d is rescaled by mean(t_j)/2 and the graph
/// re-solved until that mean is 2 within a quarter of its sampling error 1/√n (n anchors
/// tested; at least `min_predicted_anchors`, else the fit's k_d stands). On data drawn from the
/// model the two estimates agree; where they differ, the prediction is the one the ellipses are
/// judged by. An anchor that nothing else predicts (the last one, where the path ends soon
/// after it: C_j − Σ_c,j → 0) is not tested.
///
/// ## Regions with an estimated drift factor
/// k_d is itself an estimate, from ν = 2·n tests (n anchors predicted, 2 axes each; the fit's
/// drift redundancy when the fit alone sets it), and with ~15 anchors it is off by ±25 % in
/// variance from one path to the next. Plugging such an estimate into χ²₂ regions makes them too
/// small on average: where k_d came out low the region loses more than it gains where it came
/// out high. The exact region of a new error whose covariance is known up to an estimated factor
/// is Fisher's (the 2D form of the Student interval; e.g. Koch, "Parameter Estimation and
/// Hypothesis Testing in Linear Models", 1999): eᵀΣ⁻¹e/2 ~ F(2, ν), whose quantile has the
/// closed form
///     F⁻¹(p; 2, ν) = (ν/2)·((1 − p)^(−2/ν) − 1).
/// posterior_cov_en is multiplied by region_factor = 2·F⁻¹(0.95; 2, ν) / χ²₂⁻¹(0.95), so the
/// χ²₂ 95 % ellipse every reader draws from it (5.991) is that exact region: ×1.12 at ν = 28,
/// ×1.03 at ν = 100, → 1 as ν grows; cov_en is that plus d·dᵀ (the offset is no estimate of
/// the factor's). At another level p, scale by 2·F⁻¹(p; 2, ν) / χ²₂⁻¹(p) instead (report.json
/// gives ν as `variance_dof`).
/// Nothing here changes the corrected path.

#include <Eigen/Core>
#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/solver/covariance.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"

namespace geodrift::correction {

struct PathUncertaintyOptions {
  int max_iterations = 50;         ///< LM iterations per solve of the uncertainty graph
  int max_factor_iterations = 50;  ///< variance-component iterations
  /// Stop when both factors change by less than this fraction (or a quarter of their own
  /// sampling error, if larger).
  double factor_tolerance = 0.01;
  /// Below this redundancy of the drift edges k is not estimated (stays 1).
  double min_redundancy = 2.0;
  bool estimate_variance_factors = true;
  /// Rescale the drift factor until the anchors are predicted as well as Σ says (see
  /// "Prediction" in the file comment); off: the fit's variance-component estimate alone.
  bool predictive_drift_factor = true;
  /// Fewer anchors predicted by the others than this: the fit's drift factor is kept.
  int min_predicted_anchors = 5;
  /// An anchor whose tag rows have less redundancy than this (per axis) is not predicted: the
  /// others do not constrain it, and its residual is at the solver's tolerance.
  double min_anchor_redundancy = 1e-6;
  /// Widen the covariances to the exact 95 % regions of an estimated drift factor (see
  /// "Regions with an estimated drift factor"); off: the plug-in estimate (region_factor 1).
  bool estimated_factor_regions = true;
  int num_threads = 1;
};

struct PathUncertainty {
  bool ok = false;
  std::string message;  ///< why not ok, or a note (k not estimated)
  /// Per keyframe index: horizontal mean squared error matrix of the CORRECTED camera centre in
  /// W (m²): posterior_cov_en + d·dᵀ, d the horizontal offset of the Corrector's centre from
  /// map_estimate_w (see "About the corrected path").
  std::vector<Eigen::Matrix2d> cov_en;
  /// Per keyframe index: horizontal posterior covariance about map_estimate_w (m²), times
  /// region_factor.
  std::vector<Eigen::Matrix2d> posterior_cov_en;
  /// Per keyframe index: the camera centre in W at the uncertainty graph's optimum (the
  /// drift model's own estimate; the corrected path itself is the Corrector's).
  std::vector<Eigen::Vector3d> map_estimate_w;
  /// Variance factors of the drift model's components, data relative to the model: log-scale
  /// (drift_factor), rotation and translation (direction) rows of the chain.
  double drift_factor = 1.0;
  double fit_drift_factor = 1.0;   ///< k_d of the variance-component estimate (the fit alone)
  double prediction_factor = 1.0;  ///< mean leave-one-out χ²/2 of the anchors at drift_factor
  int predicted_anchors = 0;       ///< anchors that entered prediction_factor
  /// Degrees of freedom ν of drift_factor (2·predicted_anchors, or the fit's drift redundancy;
  /// +∞ when it is not estimated) and the factor posterior_cov_en (and with it cov_en) carries
  /// for it (see "Regions with an estimated drift factor").
  double variance_dof = std::numeric_limits<double>::infinity();
  double region_factor = 1.0;
  /// Per correspondence (Corrector::correspondences() order): t_j, its horizontal tag against
  /// where the chain and the other anchors put it, as a χ² with 2 degrees of freedom at the
  /// final factors (> 13.8: outside the 99.9 % region); NaN where the others do not predict it.
  std::vector<double> anchor_prediction_chi2;
  double redundancy = 0;  ///< m − n of the uncertainty graph
  double drift_redundancy = 0;
  double anchor_factor = 1.0;  ///< the anchors' variance relative to their stated σ and PnP
  double anchor_redundancy = 0;
  double chi2 = 0;  ///< 2·cost at the optimum (with k applied)
  int factor_iterations = 0;
  double seconds = 0;
};

namespace detail {

/// χ²₂-ellipse scale that makes the level-p ellipse of a 2D error, whose covariance is known up
/// to a factor estimated with ν degrees of freedom, the exact (Fisher) region:
/// 2·F⁻¹(p; 2, ν) / χ²₂⁻¹(p), with F⁻¹(p; 2, ν) = (ν/2)·((1 − p)^(−2/ν) − 1). 1 for ν = ∞.
inline double fisher_region_factor(double nu, double p = 0.95) {
  if (!(nu < std::numeric_limits<double>::infinity())) return 1.0;
  const double chi2 = -2.0 * std::log1p(-p);
  return nu * std::expm1(-2.0 / nu * std::log1p(-p)) / chi2;
}

/// Drift-model covariance (diagonal) of a relative Sim(3) measurement dS, in map units.
inline Eigen::Matrix<double, 7, 7> drift_covariance(const DriftModel& model, const lie::Sim3d& dS,
                                                    double map_per_metre) {
  const Eigen::Matrix<double, 7, 1> sd =
      model.sd(dS.translation().norm(), dS.rotation().log().norm(), map_per_metre);
  return sd.array().square().matrix().asDiagonal();
}

}  // namespace detail

/// The per-keyframe horizontal covariance of `corrector`'s path (see the file comment).
/// Needs an initialised corrector; fails (ok = false, message) when the graph is rank deficient
/// (e.g. every anchor on one line: the path may roll about it) or a solve fails.
inline PathUncertainty estimate_path_uncertainty(const Corrector& corrector,
                                                 const PathUncertaintyOptions& options = {}) {
  PathUncertainty out;
  const auto t0 = std::chrono::steady_clock::now();
  if (!corrector.initialized()) {
    out.message = "the correction is not initialised";
    return out;
  }
  const auto& kfs = corrector.keyframes();
  const auto& corr = corrector.correspondences();
  const int nk = static_cast<int>(kfs.size());
  const int na = static_cast<int>(corr.size());
  const double mpm = corrector.map_per_metre();
  const DriftModel& model = corrector.options().drift;

  // Measurements and their covariances (fixed over the iterations).
  std::vector<lie::Sim3d> steps(nk);
  std::vector<Eigen::Matrix<double, 7, 7>> step_cov(nk);
  for (int i = 1; i < nk; ++i) {
    steps[i] = lie::Sim3d(kfs[i].T_cw * kfs[i - 1].T_cw.inverse());
    step_cov[i] = detail::drift_covariance(model, steps[i], mpm);
  }
  std::vector<lie::Sim3d> offsets(na);
  std::vector<Eigen::Matrix<double, 7, 7>> offset_cov(na);
  std::vector<double> tag_sd(na);
  std::vector<int> kf_of(na);
  for (int j = 0; j < na; ++j) {
    const auto& c = corr[j];
    offsets[j] = lie::Sim3d(c.T_vk);
    offset_cov[j] = detail::drift_covariance(model, offsets[j], mpm);
    if (c.has_pose_covariance()) {
      const int at[6] = {0, 1, 2, 4, 5, 6};  // (ω, ν) into (ω, σ, ν)
      for (int a = 0; a < 6; ++a)
        for (int b = 0; b < 6; ++b) offset_cov[j](at[a], at[b]) += c.pose_cov(a, b);
    }
    tag_sd[j] = c.sigma_m > 0 ? c.sigma_m : corrector.options().ba_geo_sigma_m;
    kf_of[j] = corrector.keyframe_index(c.keyframe);
  }

  std::vector<int> by_keyframe(na);  // anchors in keyframe order (stable)
  std::iota(by_keyframe.begin(), by_keyframe.end(), 0);
  std::stable_sort(by_keyframe.begin(), by_keyframe.end(),
                   [&](int a, int b) { return kf_of[a] < kf_of[b]; });

  std::vector<lie::Sim3d> S(nk), V(na);
  for (int i = 0; i < nk; ++i) S[i] = corrector.keyframe_sim3(i);
  for (int j = 0; j < na; ++j) V[j] = offsets[j] * S[kf_of[j]];

  // Variance factors: k_d on the drift chain, k_a on each anchor's e2 + e3 (its view's
  // localization and its geo-tag), both estimated (see the file comment).
  double k_d = 1.0, k_a = 1.0;
  solver::Covariance cov;
  auto info = [](const Eigen::Matrix<double, 7, 7>& C, double k) {
    const Eigen::Matrix<double, 7, 7> I = (k * C).inverse();
    return Eigen::Matrix<double, 7, 7>(0.5 * (I + I.transpose()));
  };
  // Solves the uncertainty graph at the current (k_d, k_a) from the current S, V and computes
  // its covariance; false (out.message set) if either fails.
  double num_residuals = 0;
  auto solve_at = [&]() {
    solver::Problem problem;
    const solver::RobustLoss trivial;
    // Blocks are registered in the order they first appear, and that order is the factor's
    // natural order: each view node V_j (a leaf on its keyframe) comes just before its
    // keyframe, so eliminating it fills nothing. With every V after all the keyframes instead,
    // dense anchors (GNSS every keyframe) made the factor fill in: 2.8 GB and 140 s for 20k.
    for (int i = 0, j = 0; i < nk; ++i) {
      for (; j < na && kf_of[by_keyframe[j]] == i; ++j) {
        const int a = by_keyframe[j];
        problem.add_residual_block(solver::CameraCentrePriorResidual<lie::Sim3d>{corr[a].y_w},
                                   trivial, 1.0 / (k_a * tag_sd[a] * tag_sd[a]), &V[a]);
        problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{offsets[a]}, trivial,
                                   info(offset_cov[a], k_a), &S[i], &V[a]);
      }
      if (i > 0)
        problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{steps[i]}, trivial,
                                   info(step_cov[i], k_d), &S[i - 1], &S[i]);
    }
    solver::Options lm;
    lm.max_iterations = options.max_iterations;
    lm.linear_solver = solver::LinearSolverType::kAuto;
    lm.function_tolerance = 1e-12;
    lm.num_threads = options.num_threads;
    const solver::Summary sum = solver::LevenbergMarquardt(lm).solve(&problem);
    if (!std::isfinite(sum.final_cost)) {
      out.message = "the uncertainty graph's solve failed (" + sum.message + ")";
      return false;
    }
    std::vector<const void*> wanted;
    std::vector<solver::Covariance::Pair> pairs;
    wanted.reserve(nk + na);
    for (int i = 0; i < nk; ++i) wanted.push_back(&S[i]);
    for (int j = 0; j < na; ++j) {
      wanted.push_back(&V[j]);
      pairs.emplace_back(&S[kf_of[j]], &V[j]);
    }
    std::string why;
    if (!cov.compute(problem, wanted, pairs, &why)) {
      // Name the deficient state in the user's terms, not by its address.
      const void* bad = cov.rank_deficient_state();
      for (int i = 0; i < nk && bad; ++i)
        if (bad == &S[i])
          why = "the graph is rank deficient at keyframe " + std::to_string(kfs[i].id) +
                " (frame " + std::to_string(kfs[i].frame_index) + ")";
      for (int j = 0; j < na && bad; ++j)
        if (bad == &V[j])
          why = "the graph is rank deficient at the view node of anchor " + std::to_string(j) +
                " (on keyframe " + std::to_string(corr[j].keyframe) + ")";
      out.message = "no covariance: " + why;
      return false;
    }
    out.chi2 = 2 * sum.final_cost;
    num_residuals = sum.num_residuals;
    return true;
  };
  // Covariance of node X's camera centre c = X⁻¹·0 in W: (1/s²)·Rᵀ·Σ_νν·R (left perturbation:
  // c moves by −(1/s)·Rᵀ·δν).
  auto centre_cov = [&](const lie::Sim3d& X) {
    const Eigen::Matrix3d R = X.rotation().matrix();
    const double s = X.scale();
    return Eigen::Matrix3d(R.transpose() * cov.block(&X).bottomRightCorner<3, 3>() * R / (s * s));
  };
  for (int it = 0;; ++it) {
    if (!solve_at()) return out;
    // The anchors' group: weighted squared residuals and redundancy Σ (dim − tr(W·J·Σ·Jᵀ)).
    double chi2_a = 0, red_a = 0;
    for (int j = 0; j < na; ++j) {
      const lie::Sim3d& Sk = S[kf_of[j]];
      // e3 = c(V) − y, J = [0 0 −(1/s)·Rᵀ] on ν.
      const double w3 = 1.0 / (k_a * tag_sd[j] * tag_sd[j]);
      const Eigen::Vector3d c = V[j].inverse().translation();
      chi2_a += w3 * (c - corr[j].y_w).squaredNorm();
      red_a += 3.0 - w3 * centre_cov(V[j]).trace();
      // e2 between S_k and V_j.
      Eigen::Matrix<double, 7, 1> r2;
      Eigen::Matrix<double, 7, 7> Ji, Jj;
      solver::RelativePoseResidual<lie::Sim3d>{offsets[j]}(Sk, V[j], &r2, &Ji, &Jj);
      const Eigen::Matrix<double, 7, 7> W2 = info(offset_cov[j], k_a);
      chi2_a += r2.dot(W2 * r2);
      Eigen::Matrix<double, 7, 14> J;
      J << Ji, Jj;
      Eigen::Matrix<double, 14, 14> Sig;
      Sig.topLeftCorner<7, 7>() = cov.block(&Sk);
      Sig.bottomRightCorner<7, 7>() = cov.block(&V[j]);
      Sig.topRightCorner<7, 7>() = cov.block(&Sk, &V[j]);
      Sig.bottomLeftCorner<7, 7>() = Sig.topRightCorner<7, 7>().transpose();
      red_a += 7.0 - (W2 * J * Sig * J.transpose()).trace();
    }
    const double m = num_residuals;
    const double n = 7.0 * (nk + na);
    out.redundancy = m - n;
    out.drift_redundancy = out.redundancy - red_a;
    out.anchor_redundancy = red_a;
    out.factor_iterations = it;
    if (!options.estimate_variance_factors) break;
    // One update per group, each from its own χ² and redundancy; a group with too little
    // redundancy keeps its factor.
    const bool est_d = out.drift_redundancy >= options.min_redundancy;
    const bool est_a = red_a >= options.min_redundancy;
    const double u_d = est_d ? (out.chi2 - chi2_a) / out.drift_redundancy : 1.0;
    const double u_a = est_a ? chi2_a / red_a : 1.0;
    out.message.clear();
    if (!est_d || !est_a)
      out.message = std::string("too little redundancy to estimate the ") +
                    (!est_d && !est_a ? "drift and anchors'"
                     : !est_d         ? "drift"
                                      : "anchors'") +
                    " variance factor (kept at 1)";
    // Converged when each update is small against the factor's own sampling error (a variance
    // estimated with redundancy r has relative SD √(2/r)): a quarter of it, at least
    // factor_tolerance.
    const auto tol = [&](double r) {
      return std::max(options.factor_tolerance, 0.25 * std::sqrt(2.0 / std::max(r, 1.0)));
    };
    if (std::abs(u_d - 1.0) < tol(out.drift_redundancy) && std::abs(u_a - 1.0) < tol(red_a)) break;
    if (it + 1 >= options.max_factor_iterations) {
      out.message += std::string(out.message.empty() ? "" : "; ") +
                     "variance factors not converged after " + std::to_string(it + 1) +
                     " iterations (last updates x" + std::to_string(u_d) + ", x" +
                     std::to_string(u_a) + ")";
      break;
    }
    k_d *= u_d;  // Σ is recomputed with them: the Σ returned is always the one at (k_d, k_a)
    k_a *= u_a;
  }
  out.fit_drift_factor = k_d;
  // The drift factor from the anchors' prediction (see "Prediction" in the file comment): each
  // anchor's horizontal tag against where the others place it, from e_j = c(V_j) − y_j the
  // fit's residual, C_j = k_a·σ_j²·I the tag's covariance and Σ_c,j the fitted centre's (its
  // expectation is 2 per anchor when the factors are right). k_d is rescaled until their mean
  // is 2.
  out.anchor_prediction_chi2.assign(na, std::numeric_limits<double>::quiet_NaN());
  auto prediction_factor = [&](int* tested) {
    double t = 0;
    int n = 0;
    for (int j = 0; j < na; ++j) {
      out.anchor_prediction_chi2[j] = std::numeric_limits<double>::quiet_NaN();
      const Eigen::Matrix3d Sc = centre_cov(V[j]);
      const double c2 = k_a * tag_sd[j] * tag_sd[j];
      const Eigen::Matrix3d Q = c2 * Eigen::Matrix3d::Identity() - Sc;
      // Redundancy of the tag's rows: an anchor that the others do not predict (its tag alone
      // places that stretch of the path) tests nothing.
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Q / c2);
      if (!(es.eigenvalues()(0) >= options.min_anchor_redundancy)) continue;
      // The whole tag left out (3D), its horizontal part tested: ẽ = C·Q⁻¹·e, Cov ẽ = C·Q⁻¹·C.
      const Eigen::Matrix3d Qi = es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() *
                                 es.eigenvectors().transpose() / c2;
      const Eigen::Vector3d e = V[j].inverse().translation() - corr[j].y_w;
      const Eigen::Vector2d loo = (c2 * Qi * e).head<2>();
      const Eigen::Matrix2d loo_cov = (c2 * c2 * Qi).topLeftCorner<2, 2>();
      out.anchor_prediction_chi2[j] = loo.dot(loo_cov.ldlt().solve(loo));
      t += out.anchor_prediction_chi2[j];
      ++n;
    }
    *tested = n;
    return n > 0 ? t / (2.0 * n) : 1.0;
  };
  if (!options.estimate_variance_factors || !options.predictive_drift_factor) {
    out.prediction_factor = prediction_factor(&out.predicted_anchors);  // reported only
  } else {
    const double k_fit = k_d;
    std::string note;
    for (int it = 0;; ++it) {
      const double f = prediction_factor(&out.predicted_anchors);
      out.prediction_factor = f;
      const int n = out.predicted_anchors;
      if (n < options.min_predicted_anchors) {
        note = "only " + std::to_string(n) + " anchors predicted by the others (need " +
               std::to_string(options.min_predicted_anchors) + "): drift factor from the fit alone";
        break;
      }
      // f has relative SD 1/√n (a mean of n χ²₂/2): stop within a quarter of it.
      if (std::abs(f - 1.0) < std::max(options.factor_tolerance, 0.25 / std::sqrt(n))) break;
      if (it >= options.max_factor_iterations) {
        note = "drift factor from the prediction not converged (last update x" + std::to_string(f) +
               ")";
        break;
      }
      const double next = std::clamp(k_d * f, 1e-2 * k_fit, 1e2 * k_fit);
      if (next == k_d) {
        note = "drift factor from the prediction at its bound (x" + std::to_string(k_d / k_fit) +
               " the fit's)";
        break;
      }
      k_d = next;
      if (!solve_at()) return out;
    }
    if (!note.empty()) out.message += (out.message.empty() ? "" : "; ") + note;
  }
  out.anchor_factor = k_a;
  out.drift_factor = k_d;
  if (options.estimate_variance_factors) {  // else k_d is the model's: no estimate, ν = ∞
    const bool predicted =
        options.predictive_drift_factor && out.predicted_anchors >= options.min_predicted_anchors;
    if (predicted)
      out.variance_dof = 2.0 * out.predicted_anchors;
    else if (out.drift_redundancy >= options.min_redundancy)
      out.variance_dof = out.drift_redundancy;
  }
  out.region_factor = options.estimated_factor_regions && out.variance_dof > 0
                          ? detail::fisher_region_factor(out.variance_dof)
                          : 1.0;
  out.cov_en.resize(nk);
  out.posterior_cov_en.resize(nk);
  for (int i = 0; i < nk; ++i) {
    out.posterior_cov_en[i] = out.region_factor * centre_cov(S[i]).topLeftCorner<2, 2>();
    out.map_estimate_w.push_back(S[i].inverse().translation());
    const Eigen::Vector2d d = (corrector.keyframe_center_w(i) - out.map_estimate_w[i]).head<2>();
    out.cov_en[i] = out.posterior_cov_en[i] + d * d.transpose();
  }
  out.ok = true;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace geodrift::correction
