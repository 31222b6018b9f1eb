#pragma once

/// @file
/// Wrong anchors found before the correction uses them (issue 24 item 3): a geo-tag that is
/// tens or hundreds of metres off (a retrieval mistake, a mis-tagged panorama, a GNSS multipath
/// fix) disagrees with the anchors before AND after it along the path, by more than the VO can
/// have drifted between them. When every anchor is known up front (`geodrift correct`, the
/// experiment) each one can be tested against all the others, which a causal test against
/// the path so far (CorrectorOptions::gate_anchors) cannot: its prediction is an extrapolation,
/// this one an interpolation.
///
/// ## Model
/// The drift model's graph of uncertainty.hpp, over the raw path: a Sim(3) chain of the VO's
/// steps between consecutive keyframes (information from DriftModel over each step's length
/// and turn: the VO's errors add in variance along the path), per anchor a view node joined to
/// its keyframe by the fixed offset T_vk (drift over the offset plus the view's PnP covariance
/// where it has one) and, for an anchor in use, a camera-centre prior at its geo-tag with
/// σ = sigma_m. Solved by LM from INIT's global similarity (RANSAC over all anchors). All
/// information is physical (metres, radians), so the outcome does not depend on the map's unit.
///
/// ## The test (Baarda's data snooping)
/// At the optimum, for anchor j with residual r = y − ĉ (ĉ its view's centre, C its marginal
/// covariance, R = σ²I its geo-tag's):
///   - in use: the others predict its centre with covariance P = (C⁻¹ − R⁻¹)⁻¹, and the
///     leave-one-out innovation is e = (I + P·R⁻¹)·r (the linear-Gaussian identity
///     r = R·(P + R)⁻¹·e);
///   - left out: its view node has no prior, so P = C and e = r.
/// The statistic is horizontal, T = e_hᵀ·(P + R)_hh⁻¹·e_h ~ χ²₂ for a correct anchor.
/// Rounds, each a solve with the anchors in use and their statistics:
///   1. At the model's nominal drift (k = 1) the anchors with T > χ²₂(probability) that are
///      the worst among their in-use neighbours are left out (one wrong anchor also bends the
///      path near its neighbours and raises their T: removing only local maxima keeps those),
///      until none is.
///   2. The drift level of the data is not the model's (camera, texture, speed): the chain's
///      covariance is scaled by a factor k, the one at which the median of T over the anchors
///      in use is χ²₂'s median (2 ln 2); the median ignores wrong anchors while they are fewer
///      than half. Re-solved while k moves by more than 5 % (the k tried bracket the fixed
///      point; a step out of the bracket bisects it); once it has settled, anchors above the
///      threshold leave as in 1 and k settles again for the anchors left.
///   3. A left-out anchor with T ≤ χ²₂(readmit_probability) returns; so do two consecutive
///      left-out anchors that agree with each other (their displacement matches the path's
///      between them: it was the path, bent in a turn, that disagreed with the rest; two wrong
///      geo-tags are off independently). An anchor goes out or back in at most max_flips times.
///   4. Runs: consecutive anchors off by one common offset (GNSS multipath along a street
///      canyon, one capture run registered wrongly) vouch for each other in the test above, and
///      the correct anchors at the run's ends look wrong instead. Each stretch of 2 to
///      max_run_anchors consecutive anchors in use is tested for a common horizontal offset
///      (leave_out_run below); one whose residuals step in and back out at both ends (at its
///      inner end only, for a stretch that starts or ends the path: a receiver's cold start) is
///      left out whole and stays out. Before step 1's single anchors (a run left in sets k) and
///      again when the rounds end (a short run the nominal drift absorbed).
/// The probability is 0.99999 (threshold 23.0), not 0.999: the simulated and real drift is
/// heavier-tailed than the Gaussian model in turns, and at 0.999 a clean run lost 2-4 % of its
/// correct anchors; at 0.99999 about 0.3 %, while a 20 m shift 100 frames from its neighbours
/// still stands out. What it cannot do: tell a wrong anchor from a correct one after a turn
/// the model underrates, when both disagree with the rest alike (docs/correction_model.md
/// "Wrong anchors, screened": a clean run costs 0-4 % over the sequences, 11 % on a turn-heavy
/// stretch).
///
/// Fewer than three anchors, or anchors whose prediction is not determined (all on one point),
/// cannot be tested: they stay in use, and the result says so.

#include <Eigen/Core>
#include <Eigen/Dense>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/correction/drift_model.hpp"
#include "geodrift/correction/init.hpp"
#include "geodrift/error.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/map/correspondence.hpp"
#include "geodrift/map/keyframe.hpp"
#include "geodrift/solver/covariance.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"

namespace geodrift::correction {

struct AnchorScreeningOptions {
  DriftModel drift;
  /// χ²₂ quantile above which an anchor is left out (−2·ln(1 − p) = 13.8 at 0.999: a correct
  /// anchor is lost once in a thousand).
  double probability = 0.99999;
  /// χ²₂ quantile below which a left-out anchor returns (at most `probability`; max_flips
  /// bounds an anchor near the threshold going in and out).
  double readmit_probability = 0.99999;
  /// σ of anchors whose sigma_m is not > 0 (metres).
  double default_sigma_m = 1.0;
  /// RANSAC threshold of the starting similarity, as a fraction of the anchors' horizontal
  /// extent (at least min_start_threshold_m): the start only has to be near the optimum, and a
  /// drifting path misses a global similarity by a few percent of its length.
  double start_threshold_fraction = 0.03;
  double start_threshold_m = 10.0;
  double min_factor = 1e-2, max_factor = 1e4;  ///< bounds of the drift factor k
  /// Times an anchor may go out or back in (the rounds then end).
  int max_flips = 4;
  /// Runs (step 4 of the file comment): the longest stretch of consecutive anchors tested for
  /// a common offset (0: no run test). A run is also at most half the anchors in use less one.
  int max_run_anchors = 20;
  int max_rounds = 60;
  int max_iterations = 100;  ///< LM iterations per solve
  int num_threads = 1;

  bool validate(std::string* why) const {
    auto fail = [&](const std::string& m) {
      if (why) *why = "anchor screening: " + m;
      return false;
    };
    if (!drift.validate(why)) return false;
    if (!(probability > 0 && probability < 1)) return fail("probability must be in (0, 1)");
    if (!(readmit_probability > 0 && readmit_probability <= probability))
      return fail("readmit_probability must be in (0, probability]");
    if (!(default_sigma_m > 0 && std::isfinite(default_sigma_m)))
      return fail("default_sigma_m must be finite and > 0");
    if (!(start_threshold_fraction >= 0 && start_threshold_m > 0))
      return fail("start thresholds must be >= 0 and > 0");
    if (!(min_factor > 0 && max_factor >= min_factor && std::isfinite(max_factor)))
      return fail("factors must satisfy 0 < min_factor <= max_factor < inf");
    if (max_rounds < 1 || max_iterations < 1) return fail("max_rounds, max_iterations >= 1");
    if (max_run_anchors < 0) return fail("max_run_anchors must be >= 0");
    return true;
  }
};

/// The outcome for one anchor.
struct ScreenedAnchor {
  bool used = true;
  bool testable = false;  ///< false: its prediction from the others is not determined
  std::string why;        ///< why it is left out ("" when used)
  /// Horizontal leave-one-out innovation: its geo-tag minus where the other anchors and the
  /// path put its view (metres), that prediction's SD with the geo-tag's (√(trace/2), metres),
  /// and the statistic T (χ²₂ for a correct anchor).
  double innovation_m = std::numeric_limits<double>::quiet_NaN();
  double sd_m = std::numeric_limits<double>::quiet_NaN();
  double statistic = std::numeric_limits<double>::quiet_NaN();
  int readmissions = 0;
  /// Left out with a run of this many consecutive anchors off together (0: not in a run), the
  /// run's common horizontal offset (metres) and its test statistic (χ²₂ for a correct run).
  int run_length = 0;
  double run_offset_m = std::numeric_limits<double>::quiet_NaN();
  double run_statistic = std::numeric_limits<double>::quiet_NaN();
};

struct AnchorScreening {
  bool ok = false;      ///< false: nothing could be tested (message says why); all stay in use
  std::string message;  ///< why not ok, or a note
  std::vector<ScreenedAnchor> anchors;  ///< one per input correspondence, same order
  double drift_factor = 1.0;            ///< k: the data's drift variance relative to the model
  double threshold = 0;                 ///< χ²₂(probability)
  int rounds = 0;
  double seconds = 0;

  int num_left_out() const {
    int n = 0;
    for (const auto& a : anchors) n += !a.used;
    return n;
  }
};

namespace detail {

/// χ²₂ quantile: −2·ln(1 − p).
inline double chi2_2_quantile(double p) { return -2.0 * std::log1p(-p); }

/// Cross-covariances of the view nodes of screen_anchors()' graph from blocks on the factor's
/// pattern alone. That graph is a tree: the keyframes' chain S_0 – S_1 – … – S_{n−1} and each
/// view V_j a leaf on its keyframe S_{k(j)}. In a Gaussian whose information matrix has a tree's
/// pattern, two nodes are independent given any node on the path between them, so
/// Σ_ac = Σ_ab·Σ_bb⁻¹·Σ_bc, and along V_a – S_ka – S_ka+1 – … – S_kb – V_b (ka ≤ kb):
///   Σ_{V_a V_b} = Σ_{V_a S_ka}·Σ_{S_ka}⁻¹ · Π_{i=ka}^{kb−1} (Σ_{S_i S_i+1}·Σ_{S_i+1}⁻¹)
///                 · Σ_{S_kb V_b}.
/// Every block on the right shares a residual or is diagonal: the Covariance's recursion gives
/// it without a solve. Asked for the pairs themselves it solves with the whole factor once per
/// distinct anchor (898 GNSS fixes on 290 keyframes: 2.8 s of screening against 0.06 s without
/// the pairs of the run test). The products between consecutive anchors' keyframes are formed
/// once per compute, so a pair costs one 7×7 product per anchor keyframe between the two.
class TreeCrossCovariance {
 public:
  using Mat7 = Eigen::Matrix<double, 7, 7>;

  /// The diagonal blocks and pairs the Covariance has to compute: every S_i and V_j, the
  /// chain's consecutive pairs between the first and the last anchor's keyframe, and each view
  /// with its keyframe. `kf_of[j]`: the index in S of view j's keyframe.
  static void request(const std::vector<lie::Sim3d>& S, const std::vector<lie::Sim3d>& V,
                      const std::vector<int>& kf_of, std::vector<const void*>* blocks,
                      std::vector<solver::Covariance::Pair>* pairs) {
    if (V.empty()) return;
    const auto [lo, hi] = std::minmax_element(kf_of.begin(), kf_of.end());
    for (const auto& s : S) blocks->push_back(&s);
    for (const auto& v : V) blocks->push_back(&v);
    for (int i = *lo; i < *hi; ++i) pairs->emplace_back(&S[i], &S[i + 1]);
    for (std::size_t j = 0; j < V.size(); ++j) pairs->emplace_back(&V[j], &S[kf_of[j]]);
  }

  /// From a Covariance computed with request()'s blocks and pairs.
  /// @return false (with `why`) if a keyframe's diagonal block is not positive definite.
  bool build(const solver::Covariance& cov, const std::vector<lie::Sim3d>& S,
             const std::vector<lie::Sim3d>& V, const std::vector<int>& kf_of,
             std::string* why = nullptr) {
    const int na = static_cast<int>(V.size());
    knots_.assign(kf_of.begin(), kf_of.end());
    std::sort(knots_.begin(), knots_.end());
    knots_.erase(std::unique(knots_.begin(), knots_.end()), knots_.end());
    knot_of_.assign(na, 0);
    for (int j = 0; j < na; ++j)
      knot_of_[j] = static_cast<int>(std::lower_bound(knots_.begin(), knots_.end(), kf_of[j]) -
                                     knots_.begin());
    // Σ_{S_i}⁻¹ applied on the right: X·Σ⁻¹ = (Σ⁻¹·Xᵀ)ᵀ (Σ symmetric).
    auto right_inverse = [&](const Mat7& X, int i, Mat7* out) {
      const Mat7 Sii = cov.block(&S[i]);
      const Eigen::LLT<Mat7> llt(0.5 * (Sii + Sii.transpose()));
      if (llt.info() == Eigen::Success) return *out = llt.solve(X.transpose()).transpose(), true;
      if (why)
        *why = "the covariance of keyframe " + std::to_string(i) + " is not positive definite";
      return false;
    };
    left_.resize(na);
    right_.resize(na);
    for (int j = 0; j < na; ++j) {
      right_[j] = cov.block(&S[kf_of[j]], &V[j]);
      if (!right_inverse(cov.block(&V[j], &S[kf_of[j]]), kf_of[j], &left_[j])) return false;
    }
    step_.assign(knots_.empty() ? 0 : knots_.size() - 1, Mat7::Identity());
    for (std::size_t m = 0; m + 1 < knots_.size(); ++m)
      for (int i = knots_[m]; i < knots_[m + 1]; ++i) {
        Mat7 A;
        if (!right_inverse(cov.block(&S[i], &S[i + 1]), i + 1, &A)) return false;
        step_[m] = step_[m] * A;
      }
    return true;
  }

  /// Σ_{V_a V_b} (7×7, the Covariance's tangent coordinates), a ≠ b.
  Mat7 operator()(int a, int b) const {
    if (knot_of_[a] > knot_of_[b]) return (*this)(b, a).transpose();
    Mat7 G = left_[a];
    for (int m = knot_of_[a]; m < knot_of_[b]; ++m) G = G * step_[m];
    return G * right_[b];
  }

  /// Σ_{V_a V_b} for each b of `bs` (keyframe order, none before a's keyframe, none == a), in
  /// one walk along the chain.
  void row(int a, const std::vector<int>& bs, std::vector<Mat7>* out) const {
    out->resize(bs.size());
    Mat7 G = left_[a];
    int m = knot_of_[a];
    for (std::size_t t = 0; t < bs.size(); ++t) {
      for (; m < knot_of_[bs[t]]; ++m) G = G * step_[m];
      (*out)[t] = G * right_[bs[t]];
    }
  }

 private:
  std::vector<int> knots_;    ///< the views' keyframes (indices in S, sorted, distinct)
  std::vector<int> knot_of_;  ///< per view, its keyframe's position in knots_
  std::vector<Mat7> left_;    ///< Σ_{V_j S_k(j)}·Σ_{S_k(j)}⁻¹
  std::vector<Mat7> right_;   ///< Σ_{S_k(j) V_j}
  std::vector<Mat7> step_;    ///< Π over the chain from knot m to knot m + 1
};

}  // namespace detail

/// Tests every anchor against all the others along the raw path `keyframes` (time order, T_cw
/// in M) and leaves out the inconsistent ones (see the file comment).
/// @throws InvalidArgument on an unknown keyframe id, non-finite input or invalid options.
inline AnchorScreening screen_anchors(const std::vector<map::Keyframe>& keyframes,
                                      const std::vector<map::Correspondence>& anchors,
                                      const AnchorScreeningOptions& options = {}) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string why;
  GEODRIFT_CHECK(options.validate(&why), why);
  AnchorScreening out;
  const int nk = static_cast<int>(keyframes.size());
  const int na = static_cast<int>(anchors.size());
  out.anchors.resize(na);
  out.threshold = detail::chi2_2_quantile(options.probability);
  auto done = [&](bool ok, const std::string& msg) {
    out.ok = ok;
    out.message = msg;
    out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return out;
  };
  std::unordered_map<int, int> kf_index;
  for (int i = 0; i < nk; ++i) {
    GEODRIFT_CHECK(keyframes[i].T_cw.matrix().allFinite(),
                   "anchor screening: keyframe " << keyframes[i].id << " pose is not finite");
    map::check_map_coordinates(keyframes[i].T_cw.translation(), "anchor screening", "keyframe",
                               keyframes[i].id, "translation");
    kf_index[keyframes[i].id] = i;
  }
  std::vector<int> kf_of(na);
  for (int j = 0; j < na; ++j) {
    const auto& c = anchors[j];
    const auto it = kf_index.find(c.keyframe);
    GEODRIFT_CHECK(it != kf_index.end(),
                   "correspondence " << c.id << " names unknown keyframe " << c.keyframe);
    GEODRIFT_CHECK(c.y_w.allFinite() && c.T_vk.matrix().allFinite() && c.pose_cov.allFinite(),
                   "correspondence " << c.id << " is not finite");
    kf_of[j] = it->second;
  }
  if (na < 3) return done(false, "fewer than 3 anchors: none can be tested against the others");

  // ---- start: INIT's similarity over all anchors (RANSAC) ------------------------------------
  std::vector<Eigen::Vector3d> centres, ups, am, aw;
  for (const auto& k : keyframes) {
    const lie::SE3d T_wc = k.T_cw.inverse();
    centres.push_back(T_wc.translation());
    ups.push_back(-(T_wc.rotation().matrix().col(1)));  // camera y is down
  }
  Eigen::Vector2d lo = anchors[0].y_w.head<2>(), hi = lo;
  for (int j = 0; j < na; ++j) {
    am.push_back((anchors[j].T_vk * keyframes[kf_of[j]].T_cw).inverse().translation());
    aw.push_back(anchors[j].y_w);
    lo = lo.cwiseMin(anchors[j].y_w.head<2>());
    hi = hi.cwiseMax(anchors[j].y_w.head<2>());
  }
  InitOptions io;
  io.num_correspondences = 2;
  io.ransac_threshold_m =
      std::max(options.start_threshold_m, options.start_threshold_fraction * (hi - lo).norm());
  const InitResult init = estimate_init(centres, ups, am, aw, io);
  if (!init.ok) return done(false, "no starting similarity: " + init.message);
  const double mpm = 1.0 / init.S_wm.scale();  // map units per metre

  // ---- the graph's fixed parts ---------------------------------------------------------------
  auto covariance = [&](const lie::Sim3d& dS) {
    const Eigen::Matrix<double, 7, 1> sd =
        options.drift.sd(dS.translation().norm(), dS.rotation().log().norm(), mpm);
    return Eigen::Matrix<double, 7, 7>(sd.array().square().matrix().asDiagonal());
  };
  std::vector<lie::Sim3d> steps(nk);
  std::vector<Eigen::Matrix<double, 7, 7>> step_cov(nk);
  for (int i = 1; i < nk; ++i) {
    steps[i] = lie::Sim3d(keyframes[i].T_cw * keyframes[i - 1].T_cw.inverse());
    step_cov[i] = covariance(steps[i]);
  }
  std::vector<lie::Sim3d> offsets(na);
  std::vector<Eigen::Matrix<double, 7, 7>> offset_cov(na);
  std::vector<double> sigma(na);
  for (int j = 0; j < na; ++j) {
    const auto& c = anchors[j];
    offsets[j] = lie::Sim3d(c.T_vk);
    offset_cov[j] = covariance(offsets[j]);
    if (c.has_pose_covariance()) {
      const int at[6] = {0, 1, 2, 4, 5, 6};  // (ω, ν) into (ω, σ, ν)
      for (int a = 0; a < 6; ++a)
        for (int b = 0; b < 6; ++b) offset_cov[j](at[a], at[b]) += c.pose_cov(a, b);
    }
    sigma[j] = c.sigma_m > 0 ? c.sigma_m : options.default_sigma_m;
  }
  std::vector<lie::Sim3d> S(nk), V(na);
  const lie::Sim3d S_mw = init.S_wm.inverse();
  for (int i = 0; i < nk; ++i) S[i] = lie::Sim3d(keyframes[i].T_cw) * S_mw;
  for (int j = 0; j < na; ++j) V[j] = offsets[j] * S[kf_of[j]];

  auto info = [](const Eigen::Matrix<double, 7, 7>& C, double k) {
    const Eigen::Matrix<double, 7, 7> I = (k * C).inverse();
    return Eigen::Matrix<double, 7, 7>(0.5 * (I + I.transpose()));
  };
  // Anchors in keyframe order (for "neighbours").
  std::vector<int> order(na);
  for (int j = 0; j < na; ++j) order[j] = j;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return kf_of[a] < kf_of[b]; });

  double k = 1.0;
  bool estimate_k = false;
  std::vector<int> flips(na, 0);  // times each anchor went out or back in
  const double readmit = detail::chi2_2_quantile(options.readmit_probability);
  std::vector<Eigen::Vector2d> e(na);
  std::vector<Eigen::Matrix2d> Ph(na), Rh(na);  // prediction (at k) and geo-tag covariances
  // The graph with priors on the anchors `use`, solved from S, V at the drift factor k.
  auto solve = [&](const std::vector<char>& use, solver::Problem* problem) {
    const solver::RobustLoss trivial;
    // Blocks take the order they first appear in, and that is the factor's natural order: a
    // view node with its prior comes just before its keyframe and is eliminated, a leaf,
    // without fill; a left-out one just after it, with one block of fill. With every view
    // after all the keyframes, dense anchors filled the factor in (as in uncertainty.hpp).
    for (int i = 0, q = 0; i < nk; ++i) {
      for (; q < na && kf_of[order[q]] == i; ++q) {
        const int j = order[q];
        if (use[j])
          problem->add_residual_block(solver::CameraCentrePriorResidual<lie::Sim3d>{anchors[j].y_w},
                                      trivial, 1.0 / (sigma[j] * sigma[j]), &V[j]);
        problem->add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{offsets[j]}, trivial,
                                    info(offset_cov[j], k), &S[i], &V[j]);
      }
      if (i > 0)
        problem->add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{steps[i]}, trivial,
                                    info(step_cov[i], k), &S[i - 1], &S[i]);
    }
    solver::Options lm;
    lm.max_iterations = options.max_iterations;
    lm.linear_solver = solver::LinearSolverType::kAuto;
    lm.function_tolerance = 1e-10;
    // A long Sim(3) chain from a global similarity: the solver's setting for it (as the
    // Corrector's drift-weighted windows).
    lm.geodesic_acceleration = true;
    lm.backtracking = true;
    lm.initial_lambda = 1e-8;
    lm.num_threads = options.num_threads;
    return solver::LevenbergMarquardt(lm).solve(problem);
  };
  auto centre_cov = [](const lie::Sim3d& X, const lie::Sim3d& Y, const Eigen::MatrixXd& B) {
    // Cov(c_X, c_Y) from the tangent block: c ← c − (1/s)·Rᵀ·ν.
    const Eigen::Matrix3d AX = X.rotation().matrix().transpose() / X.scale();
    const Eigen::Matrix3d AY = Y.rotation().matrix().transpose() / Y.scale();
    return Eigen::Matrix3d(AX * B.bottomRightCorner<3, 3>() * AY.transpose());
  };
  // The longest run tested among n anchors in use: a minority, so that the rest can say which
  // side is off.
  auto run_limit = [&](int n) { return std::min(options.max_run_anchors, (n - 1) / 2); };
  std::vector<double> run_threshold(na, std::numeric_limits<double>::quiet_NaN());
  // Step 4: the stretch of consecutive anchors in use `u` (keyframe order) whose geo-tags most
  // likely share one horizontal offset b. With r the residuals y − ĉ at the solve, R their
  // covariance and Q_r = R − C_ĉ theirs at the optimum (C_ĉ the centres' joint covariance), the
  // generalised likelihood-ratio test of b on a window W (Teunissen's w-test with the signature
  // "every anchor of W shifted alike") is
  //   w = Σ_W R⁻¹·r_h,  S = Σ_{i,j∈W} R⁻¹·Q_r,ij·R⁻¹ (horizontal blocks),  T = wᵀ·S⁻¹·w ~ χ²₂,
  // b̂ = S⁻¹·w. For one anchor T is the leave-one-out statistic above. Of the windows of 1 to
  // run_limit anchors that step in and out at both ends (the inner one at the path's start or
  // end) among dense anchors (below), the one with the largest T is the most likely offset
  // stretch; it is left out when it has two or more anchors and T passes the threshold raised
  // for the number of windows tried (Bonferroni: χ²₂ at 1 − (1 − probability)/M).
  auto leave_out_run = [&](const std::vector<int>& u, const solver::Covariance& cov,
                           const detail::TreeCrossCovariance& cross) {
    const int n = static_cast<int>(u.size());
    const int len_max = run_limit(n);
    if (len_max < 2) return false;
    std::vector<Eigen::Vector2d> rh(n), rw(n);
    std::vector<double> w2(n);
    for (int q = 0; q < n; ++q) {
      const int j = u[q];
      w2[q] = 1.0 / (sigma[j] * sigma[j]);
      rh[q] = (anchors[j].y_w - V[j].inverse().translation()).head<2>();
      rw[q] = w2[q] * rh[q];
    }
    // Cov(r_a, r_b) of anchors up to a run apart (horizontal), each row in one walk.
    std::vector<std::vector<Eigen::Matrix2d>> near(n);
    std::vector<int> bs;
    std::vector<detail::TreeCrossCovariance::Mat7> row;
    for (int q = 0; q < n; ++q) {
      const int a = u[q];
      bs.clear();
      for (int d = 1; d < len_max + 1 && q + d < n; ++d) bs.push_back(u[q + d]);
      cross.row(a, bs, &row);
      near[q].resize(bs.size() + 1);
      near[q][0] = sigma[a] * sigma[a] * Eigen::Matrix2d::Identity() -
                   centre_cov(V[a], V[a], cov.block(&V[a])).topLeftCorner<2, 2>();
      for (std::size_t d = 1; d <= bs.size(); ++d)
        near[q][d] = -centre_cov(V[a], V[bs[d - 1]], row[d - 1]).topLeftCorner<2, 2>();
    }
    auto Qu = [&](int qa, int qb) { return near[qa][qb - qa]; };  // qa <= qb
    auto Q = [&](int qa, int qb) { return Eigen::Matrix2d(w2[qa] * w2[qb] * Qu(qa, qb)); };
    // A run starts and ends with a step: the residual jumps between the last correct anchor and
    // the first of the run, and back after its last, where a stretch the path drifted away
    // from (a turn the model underrates) changes gradually. edge[q]: the jump from q − 1 to q,
    // significant at the single anchors' threshold.
    std::vector<Eigen::Vector2d> jump(n, Eigen::Vector2d::Zero());
    std::vector<char> edge(n, 0);
    for (int q = 1; q < n; ++q) {
      jump[q] = rh[q] - rh[q - 1];
      const Eigen::Matrix2d X = Qu(q - 1, q);
      const Eigen::Matrix2d D = Qu(q, q) + Qu(q - 1, q - 1) - X - X.transpose();
      const Eigen::Matrix2d Ds = 0.5 * (D + D.transpose());
      edge[q] = Ds.determinant() > 0 && Ds.trace() > 0 &&
                jump[q].dot(Ds.inverse() * jump[q]) > out.threshold;
    }
    // Only where the anchors are dense: each predicted by the others and the path to within
    // 2 σ of its own (its prediction SD, at this k). Between sparse anchors the path drifts by
    // more than a fix is off, and a stretch it drifted away from steps like a run.
    std::vector<char> dense(n, 0);
    for (int q = 0; q < n; ++q) {
      const int j = u[q];
      dense[q] = out.anchors[j].testable && Ph[j].allFinite() &&
                 0.5 * Ph[j].trace() <= 4.0 * sigma[j] * sigma[j];
    }
    double best = 0;
    int best_q = -1, best_len = 0;
    Eigen::Vector2d best_b = Eigen::Vector2d::Zero();
    long windows = 0;
    for (int q0 = 0; q0 < n; ++q0) {
      bool all_dense = q0 == 0 || dense[q0 - 1];
      Eigen::Vector2d w = Eigen::Vector2d::Zero();
      Eigen::Matrix2d S = Eigen::Matrix2d::Zero();
      for (int len = 1; len <= len_max && q0 + len <= n; ++len) {
        const int qb = q0 + len - 1;
        // A stretch at the path's start or end (a GNSS receiver's cold start, the last fixes
        // in a canyon) has one edge only, at its inner end.
        const bool at_start = q0 == 0, at_end = qb == n - 1;
        w += rw[qb];
        S += Q(qb, qb);
        for (int q = q0; q < qb; ++q) {
          const Eigen::Matrix2d X = Q(q, qb);
          S += X + X.transpose();
        }
        windows += len >= 2;
        all_dense = all_dense && dense[qb];
        if (!all_dense) break;
        if (!(at_start || edge[q0]) || !(at_end || (edge[qb + 1] && dense[qb + 1]))) continue;
        const Eigen::Matrix2d Ss = 0.5 * (S + S.transpose());
        if (!(Ss.determinant() > 0 && Ss.trace() > 0)) continue;
        const Eigen::Vector2d b = Ss.inverse() * w;
        // In with +b, out with -b.
        if (!((at_start || jump[q0].dot(b) > 0) && (at_end || jump[qb + 1].dot(b) < 0))) continue;
        const double T = w.dot(b);
        if (T > best) best = T, best_q = q0, best_len = len, best_b = b;
      }
    }
    if (best_len < 2 || windows == 0) return false;
    const double threshold = out.threshold + 2.0 * std::log(static_cast<double>(windows));
    if (!(best > threshold)) return false;
    for (int q = best_q; q < best_q + best_len; ++q) {
      ScreenedAnchor& a = out.anchors[u[q]];
      run_threshold[u[q]] = threshold;
      a.used = false;
      a.run_length = best_len;
      a.run_offset_m = best_b.norm();
      a.run_statistic = best;
      flips[u[q]] = options.max_flips;  // out for good: one by one, each would pass again
    }
    return true;
  };
  auto used_mask = [&]() {
    std::vector<char> use(na);
    for (int j = 0; j < na; ++j) use[j] = out.anchors[j].used;
    return use;
  };
  double k_lo = 0, k_hi = std::numeric_limits<double>::infinity();  // bracket of k's fixed point
  std::vector<char> bracket_use;                                    // the anchors in use it is for
  for (int round = 0;; ++round) {
    if (round >= options.max_rounds) {
      out.message = "stopped after " + std::to_string(options.max_rounds) + " rounds";
      break;
    }
    out.rounds = round + 1;
    // Solve with the anchors in use.
    solver::Problem problem;
    const std::vector<char> use = used_mask();
    int in_use = 0;
    for (char u : use) in_use += u;
    const solver::Summary sum = solve(use, &problem);
    if (!std::isfinite(sum.final_cost)) {
      for (auto& a : out.anchors) a = ScreenedAnchor{};
      return done(false, "the screening graph's solve failed (" + sum.message + ")");
    }
    // Every view's and keyframe's covariance, and the blocks the views' cross-covariances
    // come from (step 4's stretches, the pair test below).
    std::vector<const void*> wanted;
    std::vector<solver::Covariance::Pair> pairs;
    detail::TreeCrossCovariance::request(S, V, kf_of, &wanted, &pairs);
    std::vector<int> in_use_order;
    if (options.max_run_anchors >= 2)
      for (int j : order)
        if (out.anchors[j].used) in_use_order.push_back(j);
    solver::Covariance cov;
    detail::TreeCrossCovariance cross;
    if (!cov.compute(problem, wanted, pairs, &why) || !cross.build(cov, S, V, kf_of, &why)) {
      for (auto& a : out.anchors) a = ScreenedAnchor{};
      return done(false, "the anchors do not determine the path (" + why +
                             "): none can be tested against the others");
    }
    // Leave-one-out innovations.
    std::vector<double> T(na, 0.0);
    for (int j = 0; j < na; ++j) {
      ScreenedAnchor& a = out.anchors[j];
      const Eigen::Matrix3d Rv = V[j].rotation().matrix();
      const double s = V[j].scale();
      Eigen::Matrix3d C =
          Rv.transpose() * cov.block(&V[j]).bottomRightCorner<3, 3>() * Rv / (s * s);
      C = 0.5 * (C + C.transpose());
      const Eigen::Vector3d r = anchors[j].y_w - V[j].inverse().translation();
      const double R = sigma[j] * sigma[j];
      Eigen::Matrix3d P;
      Eigen::Vector3d ej;
      a.testable = true;
      if (a.used) {
        // P = (C⁻¹ − R⁻¹)⁻¹ must be positive definite (finite prediction).
        const Eigen::Matrix3d M = C.inverse() - Eigen::Matrix3d::Identity() / R;
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(0.5 * (M + M.transpose()));
        const Eigen::Vector3d ev = es.eigenvalues();
        if (!(ev.minCoeff() > 1e-12 / R)) {
          a.testable = false;
        } else {
          P = es.eigenvectors() * ev.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
          ej = r + P * r / R;
        }
      } else {
        P = C;
        ej = r;
      }
      if (!a.testable || !P.allFinite() || !ej.allFinite()) {
        a.testable = false;
        continue;
      }
      e[j] = ej.head<2>();
      Ph[j] = P.topLeftCorner<2, 2>();
      Rh[j] = R * Eigen::Matrix2d::Identity();
      T[j] = e[j].dot((Ph[j] + Rh[j]).ldlt().solve(e[j]));
      a.innovation_m = e[j].norm();
      a.sd_m = std::sqrt(0.5 * (Ph[j] + Rh[j]).trace());
      a.statistic = T[j];
    }
    if (in_use < 3) break;
    // Runs first, at the model's nominal drift: a run's anchors vouch for each other, while
    // the correct anchors at its ends look wrong and would go one by one.
    if (!estimate_k && !in_use_order.empty() && leave_out_run(in_use_order, cov, cross)) continue;
    // Drift factor from the anchors in use: the f at which the median of T_j(f·P) is χ²₂'s.
    // Settled before any single anchor leaves at it: the first step from a path that follows
    // every anchor closely can go to min_factor (anchors with a σ well above their real
    // noise: the residuals are small at any k), and leaving out at that k went on for
    // dozens of rounds (110 of 233 exact anchors declared σ 1 m, a fix every 10 frames).
    std::vector<int> tested;
    if (estimate_k) {
      for (int j = 0; j < na; ++j)
        if (out.anchors[j].used && out.anchors[j].testable) tested.push_back(j);
      double f = 1.0;
      if (tested.size() >= 3) {
        std::vector<double> z(tested.size());
        auto median_T = [&](double g) {
          for (std::size_t q = 0; q < tested.size(); ++q) {
            const int j = tested[q];
            z[q] = e[j].dot((g * Ph[j] + Rh[j]).ldlt().solve(e[j]));
          }
          std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
          return z[z.size() / 2];
        };
        const double target = detail::chi2_2_quantile(0.5);
        double lo_f = std::log(options.min_factor / k), hi_f = std::log(options.max_factor / k);
        if (median_T(std::exp(lo_f)) <= target) {
          f = std::exp(lo_f);
        } else if (median_T(std::exp(hi_f)) >= target) {
          f = std::exp(hi_f);
        } else {
          for (int it = 0; it < 60; ++it) {
            const double mid = 0.5 * (lo_f + hi_f);
            (median_T(std::exp(mid)) > target ? lo_f : hi_f) = mid;
          }
          f = std::exp(0.5 * (lo_f + hi_f));
        }
      }
      // k is the fixed point of k -> k·f(k), each k re-solved. On dense anchors that map
      // overshoots (a larger k lets the path follow the anchors: smaller residuals and larger
      // predictions, T shrinks twice over) and k·f alone cycled (0.41 -> 0.63 -> 0.41 ... until
      // max_rounds, a fix every 10 frames on simulated 02). f > 1 puts the fixed point above this
      // k, f < 1 below, so the k tried bracket it (per set of anchors in use) and a step out of
      // the bracket bisects it in log k instead: within 5 % in a few rounds.
      if (std::abs(std::log(f)) > std::log(1.05)) {
        std::vector<char> use_now = used_mask();
        if (use_now != bracket_use) {
          bracket_use.swap(use_now);
          k_lo = 0;
          k_hi = std::numeric_limits<double>::infinity();
        }
        (f > 1 ? k_lo : k_hi) = k;
        if (!(k_hi <= 1.05 * k_lo)) {
          const double next = k * f;
          k = next > k_lo && next < k_hi ? next : std::sqrt(k_lo * k_hi);
          continue;  // re-solve at the new drift level before deciding
        }
      }
    }
    // Leave out the worst inconsistent anchors: T above the threshold and the largest among
    // the in-use neighbours (in keyframe order).
    std::vector<int> leave;
    std::vector<int> used_order;
    for (int j : order)
      if (out.anchors[j].used) used_order.push_back(j);
    for (std::size_t q = 0; q < used_order.size(); ++q) {
      const int j = used_order[q];
      if (!out.anchors[j].testable || !(T[j] > out.threshold) || flips[j] >= options.max_flips)
        continue;
      const bool prev_ok = q == 0 || T[used_order[q - 1]] < T[j];
      const bool next_ok = q + 1 == used_order.size() || T[used_order[q + 1]] <= T[j];
      if (prev_ok && next_ok) leave.push_back(j);
    }
    // Keep three in use (the worst go first).
    std::sort(leave.begin(), leave.end(), [&](int a, int b) { return T[a] > T[b]; });
    if (static_cast<int>(leave.size()) > in_use - 3) leave.resize(std::max(0, in_use - 3));
    bool changed = false;
    for (int j : leave) {
      out.anchors[j].used = false;
      ++flips[j];
      changed = true;
    }
    if (changed) continue;  // re-solve without them at the same k
    if (!estimate_k) {
      estimate_k = true;  // the grossly wrong anchors are out: k from the rest from now on
      continue;
    }
    // Left-out anchors consistent with the rest return.
    auto readmit_anchor = [&](int j) {
      ScreenedAnchor& a = out.anchors[j];
      a.used = true;
      a.why.clear();
      ++a.readmissions;
      ++flips[j];
      changed = true;
    };
    for (int j = 0; j < na; ++j) {
      const ScreenedAnchor& a = out.anchors[j];
      if (a.used || !a.testable || flips[j] >= options.max_flips || !(T[j] <= readmit)) continue;
      readmit_anchor(j);
    }
    // Two consecutive left-out anchors that agree with each other return together: their
    // displacement matches the path's between them, so the path (its drift in a turn, say) is
    // what disagreed with the rest. Two wrong geo-tags are off independently and rarely agree.
    for (int q = 0; q + 1 < na; ++q) {
      const int a = order[q], b = order[q + 1];
      if (out.anchors[a].used || out.anchors[b].used || flips[a] >= options.max_flips ||
          flips[b] >= options.max_flips)
        continue;
      const Eigen::Vector3d ca = V[a].inverse().translation(), cb = V[b].inverse().translation();
      const Eigen::Vector2d d = ((anchors[b].y_w - anchors[a].y_w) - (cb - ca)).head<2>();
      const Eigen::Matrix3d Caa = centre_cov(V[a], V[a], cov.block(&V[a]));
      const Eigen::Matrix3d Cbb = centre_cov(V[b], V[b], cov.block(&V[b]));
      const Eigen::Matrix3d Cab = centre_cov(V[a], V[b], cross(a, b));
      const Eigen::Matrix2d W =
          (Caa + Cbb - Cab - Cab.transpose()).topLeftCorner<2, 2>() +
          (sigma[a] * sigma[a] + sigma[b] * sigma[b]) * Eigen::Matrix2d::Identity();
      if (!(d.dot(W.ldlt().solve(d)) <= readmit)) continue;
      readmit_anchor(a);
      readmit_anchor(b);
    }
    // Runs again at the data's drift level: a short run the nominal drift absorbs stands out.
    if (!changed && !in_use_order.empty()) changed = leave_out_run(in_use_order, cov, cross);
    if (!changed) break;
  }
  out.drift_factor = k;
  // The reasons quote the final solve (the figures report.json gives), not the round an
  // anchor went out in: a grossly wrong anchor still in the fit bends the path, and that
  // round's linearised leave-one-out figures overstate it (a 9.8 km shift read as 54 km).
  for (int j = 0; j < na; ++j) {
    ScreenedAnchor& a = out.anchors[j];
    if (a.used) continue;
    std::ostringstream w;
    w.precision(3);
    if (a.run_length > 0) {
      // Its own statistic is now that of a left-out anchor against the path without the run.
      w << "one of " << a.run_length << " consecutive anchors off together by " << a.run_offset_m
        << " m (test of a common offset " << a.run_statistic << " > " << run_threshold[j]
        << "): a run of geo-tags with one error (GNSS multipath, one mis-registered capture)";
      if (a.testable)
        w << "; " << a.innovation_m << " m from where the other anchors and the path put its view "
          << "(SD " << a.sd_m << " m)";
    } else if (a.testable) {
      w << "inconsistent with the other anchors";
      w << ": " << a.innovation_m << " m from where they and the path put its view (SD " << a.sd_m
        << " m; test " << a.statistic;
      if (a.statistic > out.threshold)
        w << " > " << out.threshold << ")";
      else if (a.statistic > readmit)
        w << ", above the re-admission level " << readmit << ")";
      else
        w << "; in and out " << flips[j] << " times, left out)";
    } else {
      w << "inconsistent with the other anchors (left out in an earlier round; not testable in "
           "the last)";
    }
    a.why = w.str();
  }
  int untestable = 0;
  for (const auto& a : out.anchors) untestable += !a.testable;
  return done(true, untestable ? std::to_string(untestable) +
                                     " anchor(s) could not be tested (no prediction from the "
                                     "others)"
                               : out.message);
}

/// Screening when several correspondences share one geo-tag (`geodrift run`: one panorama is
/// localized from several keyframes; Correspondence::geotag_id says which). A wrong geo-tag is
/// wrong in every one of its localizations alike, so in screen_anchors() its siblings would
/// predict each one where it is and vouch for it (and the pair rule would readmit two of them:
/// they agree). The test therefore runs at two levels:
///   1. geo-tags: one localization per geo-tag (the one with the most PnP inliers, the first
///      on a tie) is screened against those of the other geo-tags; a geo-tag left out takes
///      all its localizations with it;
///   2. localizations: those of the geo-tags kept are screened together at the drift level
///      (k) found for the geo-tags, so one that disagrees with the rest (a view matched to the
///      wrong place, a PnP that converged wrongly) goes on its own while its geo-tag's others
///      stay. k is not re-estimated here: localizations of one geo-tag agree with each other
///      (they share its error), so their median statistic is too small, and the path it implies
///      too stiff: correct geo-tags' localizations would go (one by one, 40 of 219 localizations
///      of correct geo-tags in robust_anchors_test.cpp, 24 with level 2 re-estimating k; both
///      measured while k's fixed point could cycle, before it was bracketed; 5 one by one now).
/// A correspondence with geotag_id < 0 is a geo-tag of its own. When every geo-tag has one
/// correspondence this is screen_anchors().
inline AnchorScreening screen_anchors_by_geotag(const std::vector<map::Keyframe>& keyframes,
                                                const std::vector<map::Correspondence>& anchors,
                                                const AnchorScreeningOptions& options = {}) {
  const auto t0 = std::chrono::steady_clock::now();
  const int na = static_cast<int>(anchors.size());
  std::vector<std::vector<int>> members;  // per geo-tag, in input order
  std::unordered_map<int, int> group_of_tag;
  for (int j = 0; j < na; ++j) {
    const int tag = anchors[j].geotag_id;
    const auto it = tag >= 0 ? group_of_tag.find(tag) : group_of_tag.end();
    if (it != group_of_tag.end()) {
      members[it->second].push_back(j);
    } else {
      if (tag >= 0) group_of_tag[tag] = static_cast<int>(members.size());
      members.push_back({j});
    }
  }
  if (static_cast<int>(members.size()) == na) return screen_anchors(keyframes, anchors, options);

  // 1. one localization per geo-tag.
  std::vector<int> rep(members.size());
  std::vector<map::Correspondence> reps;
  for (std::size_t g = 0; g < members.size(); ++g) {
    rep[g] = members[g][0];
    for (int j : members[g])
      if (anchors[j].inliers > anchors[rep[g]].inliers) rep[g] = j;
    reps.push_back(anchors[rep[g]]);
  }
  const AnchorScreening tags = screen_anchors(keyframes, reps, options);
  // 2. every localization of the geo-tags kept.
  std::vector<int> kept;
  for (std::size_t g = 0; g < members.size(); ++g)
    if (!tags.ok || tags.anchors[g].used)
      kept.insert(kept.end(), members[g].begin(), members[g].end());
  std::sort(kept.begin(), kept.end());
  std::vector<map::Correspondence> sub;
  for (int j : kept) sub.push_back(anchors[j]);
  // The drift level comes from the geo-tags, which err independently: a geo-tag's
  // localizations share its error and agree with each other, and their median statistic would
  // make the path stiff enough to throw out correct geo-tags' localizations.
  AnchorScreeningOptions at_k = options;
  if (tags.ok) at_k.min_factor = at_k.max_factor = tags.drift_factor;
  // Nor runs: a geo-tag's localizations are a run by construction (one offset, its error),
  // and after level 1 the geo-tags are right.
  at_k.max_run_anchors = 0;
  const AnchorScreening views = screen_anchors(keyframes, sub, at_k);

  AnchorScreening out;
  out.anchors.resize(na);
  out.threshold = detail::chi2_2_quantile(options.probability);
  if (views.ok)
    for (std::size_t q = 0; q < kept.size(); ++q) out.anchors[kept[q]] = views.anchors[q];
  if (tags.ok)
    for (std::size_t g = 0; g < members.size(); ++g) {
      if (tags.anchors[g].used) continue;
      for (int j : members[g]) {
        ScreenedAnchor& a = out.anchors[j];
        a = tags.anchors[g];
        a.why = "geo-tag " + std::to_string(anchors[j].geotag_id) + " left out (" +
                std::to_string(members[g].size()) + " localization(s); tested through the one " +
                "at keyframe " + std::to_string(anchors[rep[g]].keyframe) +
                "): " + tags.anchors[g].why;
      }
    }
  out.ok = tags.ok || views.ok;
  out.drift_factor = views.ok ? views.drift_factor : tags.drift_factor;
  out.rounds = tags.rounds + views.rounds;
  std::string msg;
  if (!tags.ok || !tags.message.empty()) msg += "geo-tags: " + tags.message;
  if (!views.ok || !views.message.empty())
    msg += std::string(msg.empty() ? "" : "; ") + "localizations: " + views.message;
  out.message = msg;
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

/// Tells `corrector` (before the anchors are streamed into it) to leave out the anchors
/// `screening` left out; their AnchorDecisions carry the reason, the innovation and the test's
/// gate (√threshold SDs).
inline void apply_screening(const AnchorScreening& screening,
                            const std::vector<map::Correspondence>& anchors, Corrector* corrector) {
  GEODRIFT_CHECK(screening.anchors.size() == anchors.size(),
                 "apply_screening: " << screening.anchors.size() << " decisions for "
                                     << anchors.size() << " anchors");
  for (std::size_t j = 0; j < anchors.size(); ++j) {
    const ScreenedAnchor& a = screening.anchors[j];
    if (a.used) continue;
    corrector->exclude_correspondence(anchors[j].id, a.why, a.innovation_m,
                                      a.sd_m * std::sqrt(screening.threshold));
  }
}

}  // namespace geodrift::correction
