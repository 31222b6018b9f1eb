#pragma once

/// @file
/// Corrector: the paper's scale-drift correction as a stream (DESIGN.md "Correction"). A SLAM
/// front end (or correction::replay() over a finished map) hands it cameras, keyframes, map
/// points, observations and geo-referenced correspondences as they appear; INIT fits a
/// similarity M → W to the first anchors, and every later correspondence runs a sliding-window
/// Sim(3) pose graph (+ BA with a map) per CorrectorOptions::mode.
///
/// Conventions: keyframe poses T_cw in the map frame M (world → camera, the map's arbitrary
/// unit); corrected poses S_cw ∈ Sim(3) from W (UTM grid shifted, x east, y north, z up,
/// metres) to the camera in M units; tangent (ω, σ, ν), perturbations on the LEFT; geo-tags
/// y_w in W with σ in metres. Edge weights: the paper's λ (default) or the drift model
/// (correction/drift_model.hpp, unit-invariant). Uncertainty of the result:
/// correction/uncertainty.hpp.

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "geodrift/correction/drift_model.hpp"
#include "geodrift/correction/init.hpp"
#include "geodrift/correction/localization_covariance.hpp"
#include "geodrift/correction/piecewise.hpp"
#include "geodrift/correction/residuals/geo_view_centre.hpp"
#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/map/map.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/loss.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"

namespace geodrift::correction {

/// What the Corrector does when a correspondence arrives (DESIGN.md "Correction" step 4).
enum class Mode {
  kOurs,       ///< the paper: INIT, then sliding-window Sim3 PGO followed by BA
  kInitPgo,    ///< INIT, then sliding-window PGO only
  kInitBa,     ///< INIT, then sliding-window BA with the geo term only (Lhuillier 2012 style)
  kInitOnly,   ///< INIT only (the paper's baseline similarity)
  kFullBatch,  ///< INIT, then at finish() one PGO + BA over the whole path with every anchor
  /// The naive baseline (DESIGN.md "Correction" 4): one similarity per segment between
  /// consecutive anchors, the last one carried on after the last anchor
  /// (correction/piecewise.hpp): 2D in INIT's levelled frame, exact at the anchors ...
  kPiecewise2D,
  kPiecewise3D,  ///< ... or a Sim(3) fitted to each segment's anchors and their neighbours
};

inline const char* to_string(Mode m) {
  switch (m) {
    case Mode::kOurs:
      return "ours";
    case Mode::kInitPgo:
      return "init+pgo";
    case Mode::kInitBa:
      return "init+ba";
    case Mode::kInitOnly:
      return "init";
    case Mode::kFullBatch:
      return "batch";
    case Mode::kPiecewise2D:
      return "piecewise";
    case Mode::kPiecewise3D:
      return "piecewise3d";
  }
  return "?";
}

/// True for the modes that run a Sim(3) pose graph (ours, init+pgo, batch): those whose result
/// the relative-pose edges' weights and the local scale offsets shape.
inline bool uses_pose_graph(Mode m) {
  return m == Mode::kOurs || m == Mode::kInitPgo || m == Mode::kFullBatch;
}

/// Parses "ours" | "init+pgo" | "init+ba" | "init" | "batch". @throws InvalidArgument.
inline Mode mode_from_string(const std::string& s) {
  for (Mode m : {Mode::kOurs, Mode::kInitPgo, Mode::kInitBa, Mode::kInitOnly, Mode::kFullBatch,
                 Mode::kPiecewise2D, Mode::kPiecewise3D})
    if (s == to_string(m)) return m;
  GEODRIFT_CHECK(false, "unknown correction mode '"
                            << s
                            << "' (ours, init+pgo, init+ba, init, batch, piecewise, piecewise3d)");
  return Mode::kOurs;
}

/// Corrector options; defaults are the paper's where it gives them (Sec. 3.5, 4.1).
struct CorrectorOptions {
  Mode mode = Mode::kOurs;
  InitOptions init;
  /// Correspondences per window: the PGO/BA window spans the keyframes of the newest
  /// `window_correspondences` correspondences (the paper: 3).
  int window_correspondences = 3;
  /// Minimum window length in keyframes: the window is extended to older correspondences
  /// until it spans at least this many keyframes (0 = exactly the paper's window). The paper's
  /// window assumes anchors far apart (its KITTI protocol: >= 100 frames, about 33 keyframes,
  /// so windows of >= 66 keyframes, which this default leaves unchanged). Street-view
  /// panoramas every 5 m localize every 1-3 keyframes; the paper's window then shrinks to a
  /// few keyframes held by lambda1 = 1e5 edges to the fixed past, the geo terms cannot turn or
  /// rescale it, and the path keeps INIT's heading error (rendered KITTI 02 frames 0-300 with
  /// 29 localized views: 11 m after 300 m with INIT+PGO). 30 keyframes is about 90 frames,
  /// the covisibility span of a keyframe in that VO map.
  int min_window_keyframes = 30;
  /// The first window after INIT starts at the first keyframe instead of at the keyframe of
  /// its oldest correspondence, and holds every correspondence so far (INIT's four too: a
  /// window from keyframe 0 anchored only by its newest three could roll about their line when
  /// they are nearly collinear). Before it, keyframes carry only INIT's single similarity; with
  /// the paper's window they are never corrected again, and both PGO (e1 edges to fixed
  /// covisible keyframes) and BA (fixed observers of window points) clamp the first window to
  /// them. Diagnosed on simulated KITTI 08, seed 11 (not a reported seed), interval 400: the
  /// clamp left the BA's geo terms 1.4 and 2.1 m from their geo-tags (σ = 5 cm), the BA turned
  /// the window's heading by 5-8° and the path bulged 45 m between anchors; every later window
  /// is tied to that one. With the first window from keyframe 0 the residuals are 1 cm and the
  /// final mean 2D error of Ours drops from 7.2 to 4.7 m (INIT+PGO: 4.9 to 4.3 m).
  bool first_window_from_start = true;
  /// A PGO window whose solution rescales any keyframe by more than this factor is not applied
  /// (a diverged solve: a monocular VO's scale drifts by tens of per cent between anchors).
  /// Seen with --weights drift on simulated 08, trajectory only, seed 5, interval 300, where
  /// the path otherwise ended at a mean 2D error of 4.8e14 m.
  double max_window_rescale = 10.0;
  /// Windows as long as their anchors need (the modes with a pose graph; INIT+BA stays the
  /// paper's baseline). A window's keyframes before it are fixed, i.e. taken as exact, and
  /// with a map they hold it through many covisible edges (PGO) and shared points (BA). With
  /// anchors to a few centimetres the past is that good; with GNSS-like anchors (σ 1-2 m every
  /// ~10 m) its heading is only known to the degree or so its anchors leave, the window keeps
  /// it, and the error grows window after window: our VO on rendered KITTI 08 (600 frames, a
  /// fix every 10 frames, 2 m noise, σ 2 m) ended 15 and 33 m off with the map, against 0.8
  /// and 1.7 m without it. Two rules (docs/correction_model.md):
  ///  - before the solve, the window reaches back to older anchors until their geo-tags fix
  ///    its heading at least as well as the VO knows it over the window (heading_window: the
  ///    tags' heading variance 1/Σ w_j |p_j − p̄|² <= the drift model's rotation variance
  ///    over the window's keyframes), up to 16 times the keyframes it had;
  ///  - after it, a window whose solution leaves one of its own anchors outside its SD
  ///    (horizontal |r|²/σ² above χ²₂'s gate_probability quantile, 13.8; σ its geo term's)
  ///    was held by the past, not by its anchors: the state is restored and the window run
  ///    again over twice as many keyframes, up to max_window_growths times.
  /// With centimetre anchors (the paper's protocol) both hold for the paper's window already.
  bool adaptive_windows = true;
  int max_window_growths = 4;
  /// How the PGO edges are weighted.
  ///  - kDriftModel: every edge carries the uncertainty of what it measures, in
  ///    physical units (correction/drift_model.hpp, docs/correction_model.md): e1 the VO's
  ///    relative-pose error over the pair's distance and turn (`drift`); e2 the same over the
  ///    keyframe→view offset, plus the view's PnP covariance when it has one; e3 the geo-tag's
  ///    σ (Correspondence::sigma_m, ba_geo_sigma_m when unset). The corrected path does not
  ///    depend on the map's unit or frame. lambda1..3 are not used. Not the default yet:
  ///    measured on the simulator (docs/RESULTS.md, "Drift-model weights") it is better at
  ///    anchor intervals of 100-200 frames and worse at 300-500 on 08. Its PGO windows run
  ///    with geodesic acceleration and backtracking (run_pgo), without which LM from INIT's
  ///    state stopped at the iteration limit far from the optimum on some seeds.
  ///  - kPaperMetric (default): the paper's λ1 = λ2 = 1e5 on the rotation and log-scale of
  ///    e1/e2 and λ3 = 1 on e3. The translation of an e1 edge has the SD of a monocular VO's
  ///    direction-of-motion error over the pair's own length, drift.direction_sd_rad · d
  ///    (1 % of d; d in metres at INIT's scale), the translation of e2 the SD 1/√λ2 in METRES
  ///    (map units divided by map_per_metre()). Both follow the map's unit, so the corrected
  ///    path does not depend on the map's unit or frame (INIT's similarity scales with the map;
  ///    rotation and log-scale errors do not). Until 2026-12-06 e1's translation also had
  ///    1/√λ1 m = 3.2 mm whatever the length: a VO's step direction known to 0.06° over a 3 m
  ///    step. The simulator's drift is a smooth warp without per-step translation noise, so it
  ///    did not tell the two apart (every Ours and INIT+PGO cell of docs/RESULTS.md equal or up to
  ///    0.05 m lower with 1 %); our own VO on the rendered 02 stretch, with a localized view every
  ///    ~3 keyframes, ended at 1.19 m mean 2D error with 3.2 mm and 0.87 m with 1 %
  ///    (docs/correction_model.md). e3 of a view localized in
  ///    the map (the paper's geo-tagged images) keeps λ3 = 1: it stands for a view ~1 m off
  ///    beyond its tag, what a view localized in a drifted map is (PnP's own covariance
  ///    underrates it 8-10×: weight_by_localization). e3 of a direct position fix of the
  ///    keyframe (an anchor file, a GNSS fix: Correspondence::localized() false) has
  ///    information 1/σ² [1/m²] from its own sigma_m, as it has no localization error: with
  ///    λ3 = 1 there, a σ of 5 cm was read as a metre and trajectory-only correction of our own
  ///    VO on rendered 02 (anchors every 100 frames from the ground truth, σ 0.05 m) ended
  ///    0.34 m off; with 1/σ² 0.12 m (docs/vo_drift.md). On a map in metres with localized
  ///    views it is the paper's weighting itself.
  ///  - kPaper: the paper's weights verbatim, λ1 = λ2 = 1e5 on all seven components of e1/e2
  ///    in MAP units and λ3 = 1 on e3 in metres. A map unit of translation then weighs as
  ///    much as a radian and a unit of log-scale, so the result changes with the map's unit (a
  ///    monocular map's unit is arbitrary: ORB-SLAM sets it from the first median depth).
  enum class EdgeWeights { kDriftModel, kPaper, kPaperMetric };
  EdgeWeights edge_weights = EdgeWeights::kPaperMetric;
  DriftModel drift;  ///< the VO's error model (kDriftModel)
  /// kPaperMetric: SD of the local, mean-reverting part of a monocular VO's scale error
  /// (0 = none, the paper's chain alone). A monocular VO's scale at a keyframe rests on the
  /// depths of the points it is tracking there; those points are replaced every few tens of
  /// metres, and with them most of their depth error: a scale error that comes and goes, on top
  /// of the part that propagates (a random walk: e1's log-scale information λ1). A random walk
  /// cannot do both at once: one stiff enough for the slow drift (λ1: 0.32 % per edge, ~3 % over
  /// 100 keyframes) forbids the 5-10 % local scale changes a VO makes within a few hundred
  /// metres, and one loose enough for those (kDriftModel) lets the scale wander without bound
  /// between sparse anchors. A real monocular VO on KITTI shows both: the scale of consecutive
  /// 50 m windows differs by SD 0.07 while the whole sequence's window scales spread by only
  /// SD 0.08 (a random walk with 0.07 per window would spread by 0.07·√(windows): 0.5 over
  /// 50 windows). Modelled as a per-keyframe log-scale offset u_k, a Gauss–Markov process
  /// along the path with SD local_scale_sd and correlation length local_scale_length_m, which
  /// e1's log-scale residual subtracts (solver::RelativeSim3LocalScaleResidual,
  /// LocalScaleLinkResidual; docs/correction_model.md). Unit-free (a log-scale over metres at
  /// INIT's scale), so the corrected path stays independent of the map's unit.
  /// How large that part is differs by an order of magnitude between VOs (geodrift's own VO on
  /// rendered KITTI stretches: SD 0.003-0.025 over 50 m windows, consecutive windows 0.005-
  /// 0.007), so it is not fixed here: 0 (off) by default, and correction/local_scale.hpp
  /// chooses it per run by cross-validation over the anchors (`geodrift correct`'s default).
  double local_scale_sd = 0.0;
  /// Correlation length of the local scale offsets [m]: the distance over which a VO's tracked
  /// points are replaced (points 5-30 m ahead of a car-mounted camera leave the view within
  /// ~25 m of travel).
  double local_scale_length_m = 25.0;
  double lambda1 = 1e5;  ///< kPaper*: weight of e1 (keyframe–keyframe Sim3 edges)
  double lambda2 = 1e5;  ///< kPaper*: weight of e2 (keyframe–geo-view Sim3 edges)
  /// kPaper*: weight of e3 (geo view centre − geo-tag, metres); kPaperMetric: of localized
  /// views only (direct fixes weigh 1/σ²).
  double lambda3 = 1.0;
  /// e1 edges join keyframe pairs sharing at least this many map points. The paper extends
  /// Strasdat's / ORB-SLAM's Sim3 pose graph, which ORB-SLAM runs on its essential graph:
  /// covisibility with θ_min = 100 shared points (Mur-Artal et al. 2015, Sec. VIII-B). With
  /// every pair sharing 15 points (the data model's covisibility default) the λ1 = 1e5 edges
  /// span long tracks and freeze the relative scale: measured on the simulated KITTI 02 at
  /// interval 100, INIT+PGO reached 8.75 m mean 2D error with 15 and 1.33 m with 100.
  int min_shared_points = 100;
  /// Consecutive keyframes are always linked by an e1 edge (ORB-SLAM's spanning tree), so a
  /// window never falls apart where covisibility is thin.
  bool link_consecutive = true;
  /// With link_consecutive: each keyframe is also linked to this many preceding keyframes
  /// (1 = only its predecessor). A trajectory without a map (`geodrift correct` without --map)
  /// has no covisibility; linking the next few keyframes stands in for it.
  int consecutive_links = 1;
  /// A map point adds to the covisibility counts (min_shared_points) of the keyframe pairs among
  /// its first this-many observers only. A point seen by far more keyframes is a distant
  /// landmark (a tower, a mountain) that ties no two keyframes' relative pose, and counting
  /// every pair of its observers costs their number squared: 5e9 map updates for one point
  /// seen by 100,000 keyframes (BENCHMARKS.md "Limits"). Real tracks are far shorter (a few
  /// to ~100 keyframes), so the default changes nothing for them.
  int covisibility_max_track = 1000;
  /// Weight each geo term (PGO e3 edge, BA geo term) by how well its view is localized in the
  /// map as well as by its geo-tag's standard deviation. A view localized by PnP + LM carries
  /// its pose covariance (Correspondence::pose_cov); with
  ///
  ///     σ_tag = Correspondence::sigma_m (ba_geo_sigma_m when <= 0),
  ///     σ_loc = √(tr Σ_c / 3) / s_k   (Σ_c its centre covariance in M units², s_k the current
  ///             map scale at its keyframe, M units per metre: localization_sd_m()),
  ///     σ_eff = √(σ_tag² + σ_loc²),
  ///
  /// the BA geo term has weight 1/σ_eff² (instead of 1/σ_tag²) and the PGO e3 edge
  /// λ3·σ_tag²/σ_eff² (instead of λ3), so a view localized to much worse than its geo-tag (at a
  /// turn, from few or far points) pulls the window less than a well-localized one.
  /// Correspondences without a covariance keep σ_eff = σ_tag. false (default): the paper's
  /// weights. Not the default because it did not help on both sequences: measured with Ours on
  /// simulated KITTI 02 and 08, intervals 100 and 300, seeds 1-2 (BENCHMARKS.md "Correction of
  /// a whole sequence"), mean 2D error 02: 1.865 -> 1.866 m, 08: 2.175 -> 2.138 m (tolerance
  /// 0.1 SD). The PnP covariance treats the map points as exact and independent, while a
  /// drifted map's local warp is correlated between them: on those runs the predicted σ_loc
  /// ranks the views' actual localization errors (Pearson 0.95 on 08, 0.49 on 02) but is 8-10x
  /// smaller (RMS centre error per run: 2-6 cm predicted, 16-93 cm actual), so σ_eff departs
  /// from the 5 cm geo-tag σ only for the worst views (08 seed 1 frame 800: σ_loc 12 cm, actual
  /// error 3.4 m). Inflating every covariance by the inlier count (errors fully correlated
  /// between points) made it far worse (08 seed 1 @100: 1.14 -> 2.42 m).
  bool weight_by_localization = false;
  /// BA robust loss: Huber threshold in pixels (ORB-SLAM: √5.991 for monocular points); with
  /// ba_two_pass the χ² gate before the second pass instead.
  double ba_huber_px = 2.447651936;
  /// BA in two passes, as ORB-SLAM's local BA (Mur-Artal et al. 2015, Sec. VI-D; ORB-SLAM2
  /// Optimizer::LocalBundleAdjustment: optimise, drop the observations beyond the χ² gate,
  /// optimise again without a robust kernel), but with the robust kernel of the first pass
  /// set by ba_first_pass_huber_px (default none):
  ///   pass 1: every observation, Huber at ba_first_pass_huber_px (<= 0: plain least squares);
  ///   pass 2: if pass 1 left a gross residual (> ba_outlier_px), from pass 1's solution,
  ///           plain least squares on the observations whose reprojection error there is
  ///           within ba_huber_px (the χ² gate; points left with fewer than two observations
  ///           stay put); each pass up to ba_max_iterations.
  /// Why not Huber at ba_huber_px throughout: the correction BA starts far from the noise
  /// level. With INIT+BA (simulated KITTI 08, interval 100) the keyframes chained 80 m past the
  /// last anchor are 3-30 m from the next geo-tag when it arrives; the σ = 5 cm geo term then
  /// pulls the anchored keyframe by metres, its correct observations pass the √5.991 px
  /// threshold, the Huber cost grows only linearly in them, and the minimum tears the keyframe
  /// off its points instead of bending the map (torn windows ended at 5-50× the noise-level
  /// cost, the next prediction 30-200 m off). Measured on simulated KITTI, seeds 1-5, interval
  /// 100 (docs/RESULTS.md, round 4): INIT+BA 08 42.2 -> 1.21 m, 02 14.4 -> 1.18 m; Ours and
  /// full batch within 0.02 m in every cell of 02 and 08. false: one pass, Huber at
  /// ba_huber_px.
  bool ba_two_pass = true;
  /// Pass-1 Huber threshold in pixels (<= 0: plain least squares, the default: the map's
  /// observations are the front end's own BA inliers, which a SLAM already culled at its χ²
  /// gate). A wide kernel bounds the pull of gross mismatches in a map that has them; 24.5 px
  /// (10 × ba_huber_px) measured the same as plain least squares (08 and 02 at interval 100,
  /// seeds 1-5, pass 2 in every window: INIT+BA 0.985 / 1.134 m against 1.027 / 1.139 m, Ours
  /// 0.949 / 1.083 m against 0.948 / 1.082 m).
  double ba_first_pass_huber_px = 0.0;
  /// Pass 2 runs only if some reprojection error at pass 1's solution exceeds this many
  /// pixels (default 3 × √5.991 = 7.34 px: χ²₂ = 54, probability e⁻²⁷ for an inlier with
  /// 1 px noise), i.e. only when pass 1 left an outlier; otherwise the gate would drop just the
  /// tail of the noise (5 % of the inliers by its definition) and pass 1's solution is kept.
  /// On the simulator (no outliers) no window needs pass 2: bench_correction, Ours on KITTI 02
  /// at interval 100, 184 BA iterations instead of 278 with pass 2 always run (one pass with
  /// Huber: 154), mean 2D error 0.922 m either way.
  double ba_outlier_px = 7.343;
  /// Standard deviation of the BA geo term in metres when a correspondence has none (<= 0).
  double ba_geo_sigma_m = 1.0;
  /// Map points whose rays from the BA's keyframes span less than this angle are not BA
  /// variables (they move with their reference keyframe, as after PGO). Their depth is nearly
  /// unobservable: an undamped Gauss–Newton step sends some behind a camera, which rejects the
  /// whole LM step. Default: ORB-SLAM's triangulation parallax limit (cos = 0.9998, 1.15°).
  /// Measured on simulated KITTI 02, seed 11, interval 100: 2 % of the window points, total BA
  /// iterations 502 -> 291, mean 2D error 1.04 -> 1.02 m. 0 keeps every point.
  double ba_min_parallax_deg = 1.146;
  /// BA stops when an accepted step lowers the cost by less than this many standard deviations
  /// of the cost itself (½χ² of m scalar residuals at the noise level has SD √(m/2), relative
  /// SD √(2/m)): a smaller decrease is below what the data can tell apart. 1 gives a relative
  /// tolerance of 1e-2 for 20,000 residuals (the solver's default 1e-6 would be 1e-4 SD).
  /// Measured on simulated KITTI 02 and 08, intervals 100 and 300, seeds 1-2 (8 runs of Ours):
  /// 1.0 instead of 0.1 takes 21 % less correction CPU, mean 2D error 2.020 -> 1.976 m
  /// (02: 1.865 -> 1.878 m, 08: 2.175 -> 2.075 m).
  double ba_cost_tolerance_sd = 1.0;
  int pgo_max_iterations = 50;
  int ba_max_iterations = 30;
  int num_threads = 1;

  /// Wrong anchors (a retrieval mistake, a mis-tagged panorama, a GNSS multipath fix) are found
  /// by their consistency with the path before they enter it. After INIT each new anchor is
  /// compared with where the current corrected path puts its view (the innovation e, horizontal)
  /// and the spread that prediction has under the drift model (correction/drift_model.hpp) since
  /// the last anchor in use, plus both anchors' σ (docs/correction_model.md):
  ///
  ///     V = k·Σ_i |c_b − c_i|²·(var ω_i + var σ_i) + 2·var t_i  +  |c_b − c_a|²·2σ_a²/L²
  ///         + σ_a² + σ_b²                                      (total horizontal variance, m²)
  ///     reject when 2|e|²/V > χ²₂(gate_probability)
  ///
  /// (i over the keyframe steps from the last anchor's keyframe a to the new one's b, L the
  /// distance of the last two anchors in use: the heading they leave). k is the data's drift
  /// level relative to the model, estimated from the anchors tested so far, used or not (the k
  /// that makes the median of 2|e|²/V χ²₂'s median: robust while fewer than half are wrong;
  /// clamped to [gate_min_factor, gate_max_factor]; 1 until gate_min_samples were tested), so
  /// a VO that drifts more than DriftModel's defaults widens its gate instead of losing its
  /// correct anchors. A rejected anchor is re-admitted with the next one when the two agree
  /// with each other (their displacement in W matches the path's within the same test): then the
  /// path's prediction was wrong, not the anchors. INIT's RANSAC outliers are rejected too, and
  /// INIT waits for more anchors while fewer than init.min_inliers agree.
  /// INIT needs this many anchors agreeing on its similarity (RANSAC inliers; all of them
  /// when fewer are in); with fewer it waits for the next anchor.
  int init_min_inliers = 3;
  ///
  /// Off by default: measured on the simulator (docs/RESULTS.md, "Wrong anchors"), the causal
  /// test rejects anchors hundreds of metres off without loss, but at long anchor intervals the
  /// prediction it tests against is an extrapolation over hundreds of metres, a correct anchor
  /// can fall outside the gate, and the path then runs on unanchored (08, interval 300: mean
  /// 2D error of INIT+PGO 4.8 m without the gate, 7-17 m with it on four seeds, one divergent).
  bool gate_anchors = false;
  double gate_probability = 0.999;  ///< χ²₂ quantile of the test (−2·ln(1 − p) = 13.8)
  int gate_min_samples = 3;         ///< anchors in use after INIT before k is estimated
  double gate_min_factor = 1e-2, gate_max_factor = 1e6;

  bool validate(std::string* why) const {
    auto fail = [&](const std::string& m) {
      if (why) *why = m;
      return false;
    };
    if (!init.validate(why)) return false;
    if (!drift.validate(why)) return false;
    if (window_correspondences < 2)
      return fail("window_correspondences " + std::to_string(window_correspondences) +
                  " must be >= 2");
    if (min_window_keyframes < 0)
      return fail("min_window_keyframes " + std::to_string(min_window_keyframes) + " must be >= 0");
    if (!(std::isfinite(local_scale_sd) && local_scale_sd >= 0))
      return fail("local_scale_sd must be finite and >= 0");
    if (!(std::isfinite(local_scale_length_m) && local_scale_length_m > 0))
      return fail("local_scale_length_m must be finite and > 0");
    for (double l : {lambda1, lambda2, lambda3})
      if (!(std::isfinite(l) && l > 0)) return fail("PGO weights lambda1..3 must be finite, > 0");
    if (min_shared_points < 1) return fail("min_shared_points must be >= 1");
    if (consecutive_links < 1) return fail("consecutive_links must be >= 1");
    if (covisibility_max_track < 2) return fail("covisibility_max_track must be >= 2");
    if (!(max_window_rescale > 1) || std::isnan(max_window_rescale))
      return fail("max_window_rescale must be > 1");
    if (max_window_growths < 0) return fail("max_window_growths must be >= 0");
    if (!(ba_huber_px > 0 && std::isfinite(ba_huber_px)))
      return fail("ba_huber_px must be finite and > 0");
    if (!std::isfinite(ba_first_pass_huber_px))
      return fail("ba_first_pass_huber_px must be finite (<= 0: no robust loss)");
    if (!(ba_outlier_px >= ba_huber_px && std::isfinite(ba_outlier_px)))
      return fail("ba_outlier_px must be finite and >= ba_huber_px");
    if (!(ba_geo_sigma_m > 0 && std::isfinite(ba_geo_sigma_m)))
      return fail("ba_geo_sigma_m must be finite and > 0");
    if (!(ba_min_parallax_deg >= 0 && ba_min_parallax_deg < 90))
      return fail("ba_min_parallax_deg must be in [0, 90)");
    if (!(ba_cost_tolerance_sd >= 0 && std::isfinite(ba_cost_tolerance_sd)))
      return fail("ba_cost_tolerance_sd must be finite and >= 0");
    if (pgo_max_iterations < 1 || ba_max_iterations < 1)
      return fail("pgo/ba max iterations must be >= 1");
    if (num_threads < 1 || num_threads > 2) return fail("num_threads must be 1 or 2");
    if (!(gate_probability > 0 && gate_probability < 1))
      return fail("gate_probability must be in (0, 1)");
    if (gate_min_samples < 1) return fail("gate_min_samples must be >= 1");
    if (init_min_inliers < 2) return fail("init_min_inliers must be >= 2");
    if (!(gate_min_factor > 0 && gate_max_factor >= gate_min_factor &&
          std::isfinite(gate_max_factor)))
      return fail("gate factors must satisfy 0 < gate_min_factor <= gate_max_factor < inf");
    return true;
  }
};

/// The PGO edge weighting named `s`: "metric" (CorrectorOptions::EdgeWeights::kPaperMetric),
/// "paper" (kPaper) or "drift" (kDriftModel). @throws InvalidArgument on anything else.
inline CorrectorOptions::EdgeWeights edge_weights_from_string(const std::string& s) {
  GEODRIFT_CHECK(s == "metric" || s == "paper" || s == "drift",
                 "unknown edge weighting '" << s << "' (metric, paper, drift)");
  return s == "metric"  ? CorrectorOptions::EdgeWeights::kPaperMetric
         : s == "paper" ? CorrectorOptions::EdgeWeights::kPaper
                        : CorrectorOptions::EdgeWeights::kDriftModel;
}

/// The name edge_weights_from_string() takes for `w`.
inline const char* to_string(CorrectorOptions::EdgeWeights w) {
  switch (w) {
    case CorrectorOptions::EdgeWeights::kPaperMetric:
      return "metric";
    case CorrectorOptions::EdgeWeights::kPaper:
      return "paper";
    case CorrectorOptions::EdgeWeights::kDriftModel:
      return "drift";
  }
  return "?";
}

/// What the Corrector did with one correspondence (anchor) it received.
struct AnchorDecision {
  int id = -1;        ///< Correspondence::id
  int keyframe = -1;  ///< its keyframe id
  bool used = false;  ///< in the correction (false: rejected, or waiting for INIT)
  /// Why it is not used ("" when used): INIT's RANSAC, the consistency gate, a duplicate.
  std::string why;
  /// At arrival (after INIT): horizontal distance from where the path then put the view, and
  /// the gate it was tested against (metres); NaN for INIT's anchors.
  double innovation_m = std::numeric_limits<double>::quiet_NaN();
  double gate_m = std::numeric_limits<double>::quiet_NaN();
  bool readmitted = false;  ///< rejected at arrival, re-admitted with the next anchor
};

/// What one correction step did (one per correspondence after INIT, plus INIT itself).
struct StepReport {
  std::string kind;  ///< "init", "pgo", "ba", "init-failed"
  int correspondence = -1;
  int window_first_keyframe = -1, window_last_keyframe = -1;  ///< keyframe ids
  int nodes = 0, edges = 0;
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
  int skipped_points = 0;      ///< BA: window points left out for lack of parallax
  double huber_px = 0;         ///< BA: Huber threshold of the last pass (pixels; 0: none)
  int passes = 0;              ///< BA: passes run (CorrectorOptions::ba_two_pass)
  int gated_observations = 0;  ///< BA pass 2: observations left out by the χ² gate (0: no pass 2)
  int pass1_iterations = 0;    ///< BA: iterations of pass 1 (of `iterations`)
  std::string termination;
  double seconds = 0;      ///< whole step, wall clock
  double cpu_seconds = 0;  ///< whole step, process CPU time (std::clock)
  /// Where the step's time went (wall, seconds): building the problem (window, points, edges)
  /// and the solver's own phases (solver::Summary).
  double time_setup = 0, time_evaluate = 0, time_assemble = 0, time_analyze = 0, time_factorize = 0,
         time_solve = 0;
  std::string linear_solver;       ///< the solver's name for the linear solver it used
  std::vector<double> cost_trace;  ///< cost at the start, then after each LM iteration
};

namespace detail {

/// Cosine of the widest angle between two of the unit vectors `rays`, or any value <= `stop`
/// once a pair that wide is found. Exact for up to 256 rays (pairwise). Beyond that (a point
/// seen by thousands of keyframes) it is the widest angle between the first ray, the ray
/// farthest from it, and every ray: at least half the widest angle, in linear time.
inline double widest_ray_cos(const std::vector<Eigen::Vector3d>& rays, double stop) {
  double min_cos = 1.0;
  if (rays.size() <= 256) {
    for (std::size_t i = 0; i < rays.size() && min_cos > stop; ++i)
      for (std::size_t j = 0; j < i; ++j) min_cos = std::min(min_cos, rays[i].dot(rays[j]));
    return min_cos;
  }
  std::size_t far = 0;
  for (std::size_t i = 1; i < rays.size(); ++i) {
    const double c = rays[0].dot(rays[i]);
    if (c < min_cos) {
      min_cos = c;
      far = i;
    }
  }
  for (const auto& r : rays) min_cos = std::min(min_cos, rays[far].dot(r));
  return min_cos;
}

}  // namespace detail

/// The Corrector (DESIGN.md "who owns what"). It receives keyframes, points, observations and
/// correspondences in the front end's map frame M (raw, never rewritten), keeps its own copy,
/// and holds their corrected state in W:
///   - each keyframe i: S_i ∈ Sim(3), W → camera in M units (scale s_i = local M units per
///     metre); its metric pose in W is S_i.to_se3() = [R | t/s];
///   - each map point: its position in W.
/// Before INIT nothing is corrected (`initialized()` is false). A keyframe added after the
/// last correction is placed by chaining its raw relative pose to its corrected predecessor.
/// Synchronous: add_correspondence runs INIT / PGO / BA as the mode says and returns.
class Corrector {
 public:
  explicit Corrector(CorrectorOptions options = {}) : options_(std::move(options)) {
    std::string why;
    GEODRIFT_CHECK(options_.validate(&why), why);
  }

  const CorrectorOptions& options() const { return options_; }

  /// @throws InvalidArgument on an invalid camera or a duplicate id.
  void add_camera(const map::Camera& camera) {
    camera.validate();
    GEODRIFT_CHECK(!cameras_.count(camera.id), "camera id " << camera.id << " added twice");
    cameras_[camera.id] = camera;
  }

  /// Adds a keyframe (raw pose in M). Keyframes must arrive in time order.
  /// @throws InvalidArgument on a duplicate id, unknown camera, non-finite pose, a translation
  ///         beyond map::kMaxMapCoordinate, or a timestamp earlier than the previous keyframe's.
  void add_keyframe(const map::Keyframe& kf) {
    GEODRIFT_CHECK(!kf_index_.count(kf.id), "keyframe id " << kf.id << " added twice");
    GEODRIFT_CHECK(kf.T_cw.matrix().allFinite(), "keyframe " << kf.id << " pose is not finite");
    map::check_map_coordinates(kf.T_cw.translation(), "add_keyframe", "keyframe", kf.id,
                               "translation");
    GEODRIFT_CHECK(std::isfinite(kf.timestamp), "keyframe " << kf.id << " timestamp not finite");
    GEODRIFT_CHECK(cameras_.empty() || cameras_.count(kf.camera_id),
                   "keyframe " << kf.id << " names unknown camera " << kf.camera_id);
    if (!kfs_.empty())
      GEODRIFT_CHECK(kf.timestamp >= kfs_.back().timestamp,
                     "keyframe " << kf.id << " at t = " << kf.timestamp
                                 << " s arrives after keyframe " << kfs_.back().id
                                 << " at t = " << kfs_.back().timestamp << " s");
    materialize_tail(static_cast<int>(kfs_.size()) - 1);  // the new keyframe is not in the tail
    kf_index_[kf.id] = static_cast<int>(kfs_.size());
    kfs_.push_back(kf);
    pts_of_ref_.emplace_back();
    kf_pts_.emplace_back();
    covisible_before_.emplace_back();
    lie::Sim3d S;
    if (initialized_) S = chain_from_previous(static_cast<int>(kfs_.size()) - 1);
    S_.push_back(S);
    U_.push_back(U_.empty() ? 0.0 : U_.back());
  }

  /// Adds a map point (raw position in M; its reference keyframe must exist).
  void add_point(const map::MapPoint& p) {
    GEODRIFT_CHECK(!pt_index_.count(p.id), "map point id " << p.id << " added twice");
    GEODRIFT_CHECK(p.position.allFinite(), "map point " << p.id << " position is not finite");
    map::check_map_coordinates(p.position, "add_point", "map point", p.id, "position");
    GEODRIFT_CHECK(
        kf_index_.count(p.reference_keyframe),
        "map point " << p.id << " names unknown reference keyframe " << p.reference_keyframe);
    materialize_tail(static_cast<int>(kfs_.size()) - 1);  // X_w_ below is stored as is
    const int ref = kf_index_.at(p.reference_keyframe);
    pt_index_[p.id] = static_cast<int>(pts_.size());
    pts_of_ref_[ref].push_back(static_cast<int>(pts_.size()));
    ref_of_pt_.push_back(ref);
    pts_.push_back(p);
    X_w_.push_back(initialized_ ? point_from_reference(static_cast<int>(pts_.size()) - 1)
                                : Eigen::Vector3d::Zero());
    observers_.emplace_back();
  }

  /// Adds an observation; updates covisibility incrementally.
  void add_observation(const map::Observation& o) {
    const auto k = kf_index_.find(o.keyframe);
    const auto p = pt_index_.find(o.point);
    GEODRIFT_CHECK(k != kf_index_.end(), "observation names unknown keyframe " << o.keyframe);
    GEODRIFT_CHECK(p != pt_index_.end(), "observation names unknown point " << o.point);
    GEODRIFT_CHECK(o.pixel.allFinite(), "observation (keyframe " << o.keyframe << ", point "
                                                                 << o.point << ") not finite");
    auto& obs = observers_[p->second];
    const std::size_t cap = static_cast<std::size_t>(options_.covisibility_max_track);
    if (obs.size() < cap) {
      for (const auto& [ki, oi] : obs)
        if (ki == k->second) return;  // a point is observed once per keyframe
      for (const auto& [ki, oi] : obs) {
        const int a = std::min(ki, k->second), b = std::max(ki, k->second);
        if (++shared_[{a, b}] == 1) covisible_before_[b].push_back(a);
      }
    } else {
      // A track past the cap: no covisibility counts, and a hash set of its observers (built
      // once) keeps the once-per-keyframe test O(1).
      auto [it, fresh] = long_track_observers_.try_emplace(p->second);
      if (fresh)
        for (const auto& [ki, oi] : obs) it->second.insert(ki);
      if (!it->second.insert(k->second).second) return;
    }
    obs.push_back({k->second, static_cast<int>(obs_.size())});
    obs_.push_back(o);
    kf_pts_[k->second].push_back(p->second);
  }

  /// Adds a map-to-world correspondence and runs the correction the mode asks for.
  /// Correspondences of the same keyframe and geo-tag position (within 1 mm) are merged.
  /// @throws InvalidArgument if its keyframe is unknown, a value is not finite or its pose
  ///         covariance has a negative variance.
  void add_correspondence(const map::Correspondence& c) {
    GEODRIFT_CHECK(kf_index_.count(c.keyframe),
                   "correspondence " << c.id << " names unknown keyframe " << c.keyframe);
    GEODRIFT_CHECK(c.y_w.allFinite() && c.T_vk.matrix().allFinite(),
                   "correspondence " << c.id << " is not finite");
    GEODRIFT_CHECK(c.pose_cov.allFinite() && (c.pose_cov.diagonal().array() >= 0).all(),
                   "correspondence " << c.id
                                     << ": pose covariance is not finite or has a negative "
                                        "variance");
    AnchorDecision dec;
    dec.id = c.id;
    dec.keyframe = c.keyframe;
    if (const auto ex = excluded_.find(c.id); ex != excluded_.end()) {
      dec.why = ex->second.why;
      dec.innovation_m = ex->second.innovation_m;
      dec.gate_m = ex->second.gate_m;
      received_.push_back(c);
      decisions_.push_back(dec);
      gate_var_.push_back({0.0, 0.0});
      return;
    }
    const auto same_kf = corr_of_kf_.find(c.keyframe);
    if (same_kf != corr_of_kf_.end())
      for (int j : same_kf->second)
        if (const auto& d = corr_[j]; (d.y_w - c.y_w).norm() < 1e-3) {
          dec.why = "duplicate of correspondence " + std::to_string(d.id) +
                    " (same keyframe, within 1 mm): merged";
          received_.push_back(c);
          decisions_.push_back(dec);
          gate_var_.push_back({0.0, 0.0});
          return;
        }
    if (!initialized_) {
      dec.used = true;
      corr_of_kf_[c.keyframe].push_back(static_cast<int>(corr_.size()));
      corr_.push_back(c);
      corr_dec_.push_back(static_cast<int>(decisions_.size()));
      received_.push_back(c);
      decisions_.push_back(dec);
      gate_var_.push_back({0.0, 0.0});
      if (static_cast<int>(corr_.size()) >= options_.init.num_correspondences) try_init();
      return;
    }
    std::pair<double, double> var{0.0, 0.0};
    if (options_.gate_anchors) {
      update_factor();  // from the anchors before this one
      const Eigen::Vector2d e = innovation(c, &var.first, &var.second);
      const double chi2 = -2.0 * std::log(1.0 - options_.gate_probability);
      dec.innovation_m = e.norm();
      dec.gate_m = std::sqrt(chi2 * (var.first + drift_factor_ * var.second) / 2.0);
      if (!(dec.innovation_m <= dec.gate_m)) {
        std::ostringstream why;
        why << "inconsistent with the path: " << dec.innovation_m
            << " m from where it puts the view, gate " << dec.gate_m << " m";
        dec.why = why.str();
        // The previous anchor was rejected too: if the two agree with each other, the path's
        // prediction is what was wrong: both go in.
        const bool pair = !decisions_.empty() && !decisions_.back().used &&
                          std::isfinite(decisions_.back().innovation_m) &&
                          agree(received_.back(), c, chi2);
        received_.push_back(c);
        decisions_.push_back(dec);
        gate_var_.push_back(var);
        if (!pair) return;
        const int prev = static_cast<int>(decisions_.size()) - 2;
        for (int d : {prev, prev + 1}) {
          decisions_[d].used = true;
          decisions_[d].readmitted = true;
          decisions_[d].why.clear();
          use(d);
        }
        return;
      }
    }
    dec.used = true;
    received_.push_back(c);
    decisions_.push_back(dec);
    gate_var_.push_back(var);
    use(static_cast<int>(decisions_.size()) - 1);
  }

  /// Leaves correspondence `id` out when it arrives: a decision made before the stream with
  /// every anchor known (correction/screening.hpp). Its AnchorDecision gets `why` and the
  /// innovation and gate (metres) the decision was made on.
  void exclude_correspondence(int id, const std::string& why,
                              double innovation_m = std::numeric_limits<double>::quiet_NaN(),
                              double gate_m = std::numeric_limits<double>::quiet_NaN()) {
    excluded_[id] = AnchorDecision{id, -1, false, why, innovation_m, gate_m, false};
  }

  /// Every correspondence received (duplicates aside), in arrival order, and what was done
  /// with it (CorrectorOptions::gate_anchors).
  const std::vector<map::Correspondence>& received() const { return received_; }
  const std::vector<AnchorDecision>& anchor_decisions() const { return decisions_; }
  /// The data's drift level relative to DriftModel (k of CorrectorOptions::gate_anchors).
  double drift_factor() const { return drift_factor_; }
  /// PGO window updates that were not applied because they rescaled a keyframe by more than
  /// CorrectorOptions::max_window_rescale.
  int rejected_window_updates() const { return rejected_updates_; }
  /// Window steps run again over more keyframes because their anchors did not fit
  /// (CorrectorOptions::adaptive_windows).
  int grown_windows() const { return grown_windows_; }
  /// Where the current path puts received correspondence d's view centre in W (after INIT).
  Eigen::Vector3d received_view_center_w(int d) const {
    require_init();
    const auto& c = received_.at(d);
    return view_sim3(c, S_at(kf_index_.at(c.keyframe))).inverse().translation();
  }

 private:
  /// Adds an accepted correspondence after INIT and runs the mode's window step.
  void use(int d) {
    corr_of_kf_[received_[d].keyframe].push_back(static_cast<int>(corr_.size()));
    corr_.push_back(received_[d]);
    corr_dec_.push_back(d);
    const int n = static_cast<int>(corr_.size());
    if (piecewise()) return run_piecewise();
    if (options_.mode == Mode::kInitOnly || options_.mode == Mode::kFullBatch) return;
    int first = n - options_.window_correspondences;
    if (first < 0) return;
    // Dense anchors: extend the window to older correspondences until it is long enough
    // (CorrectorOptions::min_window_keyframes).
    const int k_newest = kf_index_.at(corr_[n - 1].keyframe);
    while (first > 0 &&
           k_newest - kf_index_.at(corr_[first].keyframe) + 1 < options_.min_window_keyframes)
      --first;
    // Metre-level anchors: extend it until they fix its heading (CorrectorOptions::
    // adaptive_windows), up to 16 times the keyframes it has so far.
    if (options_.adaptive_windows && uses_pose_graph(options_.mode))
      first = heading_window(first, n - 1);
    // The first window reaches back to keyframe 0 with every correspondence so far (INIT's):
    // without them its start is anchored by nothing, and three nearly collinear anchors leave
    // it free to roll about their line (simulated 08, interval 200: 54 m error downstream).
    // A window extended back into INIT's correspondences is treated the same way.
    if (options_.first_window_from_start && first <= first_window_) first = 0;
    run_window(first, n - 1);
  }

  /// The mode's window step over correspondences [first, last], grown while its anchors do not
  /// fit its solution (CorrectorOptions::adaptive_windows).
  void run_window(int first, int last) {
    const bool grow = options_.adaptive_windows && uses_pose_graph(options_.mode);
    for (int growths = 0;; ++growths) {
      const bool may_grow = grow && growths < options_.max_window_growths && first > 0;
      WindowState saved;
      if (may_grow) saved = save_state(first, last);
      if (options_.mode != Mode::kInitBa) run_pgo(first, last);
      if (options_.mode != Mode::kInitPgo) run_ba(first, last);
      double worst = 0;
      if (!may_grow || window_fits(first, last, &worst)) return;
      restore_state(saved);
      // Twice as many keyframes, to the correspondence at or before that start.
      const int k_last = kf_index_.at(corr_[last].keyframe);
      const int k_first = kf_index_.at(corr_[first].keyframe);
      const int target = k_last - 2 * (k_last - k_first + 1) + 1;
      while (first > 0 && kf_index_.at(corr_[first].keyframe) > target) --first;
      if (options_.first_window_from_start && first <= first_window_) first = 0;
      std::ostringstream why;
      why << " (discarded: an anchor of the window " << std::sqrt(worst)
          << " SD off after it; run again from keyframe "
          << kfs_[window_of(first, last, false).first].id << ")";
      for (std::size_t r = saved.reports; r < reports_.size(); ++r)
        reports_[r].termination += why.str();
      ++grown_windows_;
    }
  }

  /// The `first` at or before the given one from which the geo-tags of correspondences
  /// [first, last] fix the heading of their window at least as well as the VO knows it over
  /// the window, 1/I_θ <= θ_VO², or the oldest that keeps the window within 16 times its
  /// keyframes. I_θ = Σ w_j |p_j − p̄|² (horizontal geo-tags, w_j = 1/σ_j² of their geo terms,
  /// p̄ their weighted mean) is the tags' heading information, θ_VO² the drift model's rotation
  /// variance (one axis) summed over the window's consecutive raw keyframe steps.
  int heading_window(int first, int last) const {
    const int k_last = kf_index_.at(corr_[last].keyframe);
    const int max_span = 16 * (k_last - kf_index_.at(corr_[first].keyframe) + 1);
    double sw = 0, spp = 0, var = 0;
    Eigen::Vector2d sp = Eigen::Vector2d::Zero();
    int lo = k_last;  // the rotation variance covers keyframes [lo, k_last]
    for (int j = last;; --j) {
      const int k = kf_index_.at(corr_[j].keyframe);
      const double sd = e3_sd_m(corr_[j], k);
      const Eigen::Vector2d p = corr_[j].y_w.head<2>() - corr_[last].y_w.head<2>();
      sw += 1.0 / (sd * sd);
      sp += p / (sd * sd);
      spp += p.squaredNorm() / (sd * sd);
      for (; lo > k; --lo) {
        const Eigen::Matrix<double, 7, 1> e =
            edge_sd(sim3(kfs_[lo].T_cw * kfs_[lo - 1].T_cw.inverse()), map_per_metre());
        var += e[0] * e[0];
      }
      if (j > first) continue;
      if (j == 0 || (spp - sp.squaredNorm() / sw) * var >= 1.0 ||
          k_last - kf_index_.at(corr_[j - 1].keyframe) + 1 > max_span)
        return j;
      first = j - 1;
    }
  }

  /// Whether every correspondence of the window [first, last] lies within the χ²₂ gate of its
  /// geo term's SD, horizontally, on the current path; `worst`: the largest |r|²/σ².
  bool window_fits(int first, int last, double* worst) const {
    const double chi2 = -2.0 * std::log(1.0 - options_.gate_probability);
    *worst = 0;
    for (int j = first; j <= last; ++j) {
      const auto& c = corr_[j];
      const int k = kf_index_.at(c.keyframe);
      const Eigen::Vector2d r = (view_sim3(c, S_at(k)).inverse().translation() - c.y_w).head<2>();
      const double sd = e3_sd_m(c, k);
      *worst = std::max(*worst, r.squaredNorm() / (sd * sd));
    }
    return *worst <= chi2;
  }

  /// SD (metres) of correspondence c's e3 term in the pose graph (its information's).
  double e3_sd_m(const map::Correspondence& c, int k) const {
    if (options_.edge_weights == CorrectorOptions::EdgeWeights::kDriftModel) return tag_sd_m(c);
    const bool metric = options_.edge_weights == CorrectorOptions::EdgeWeights::kPaperMetric;
    return 1.0 / std::sqrt(paper_geo_information(c, geo_term_sd_m(c, k), metric));
  }

  /// The corrected state a window step over correspondences [first, last] can change, to undo
  /// it (run_window), in O(window): the stored poses and local scale offsets of the window's
  /// keyframes and of those up to the lazy tail's start (apply_window_update, materialize_tail
  /// rewrite them), the stored points referenced to them or seen from the window (the BA's),
  /// and the lazy tail. Its reports stay, and a rejected update in it still counts in
  /// rejected_window_updates(), as its report says.
  struct WindowState {
    int lo = 0;
    std::vector<lie::Sim3d> S;
    std::vector<double> U;
    std::vector<std::pair<int, Eigen::Vector3d>> X;
    int tail_from = kNoTail;
    lie::Sim3d tail_D, tail_D_inverse;
    double tail_u = 0.0;
    std::size_t reports = 0;
  };
  WindowState save_state(int first, int last) const {
    WindowState w;
    const auto [lo, hi] = window_of(first, last, false);
    const int end = tail_from_ != kNoTail && tail_from_ > hi + 1 ? tail_from_ - 1 : hi;
    w.lo = lo;
    w.S.assign(S_.begin() + lo, S_.begin() + end + 1);
    w.U.assign(U_.begin() + lo, U_.begin() + end + 1);
    for (int i = lo; i <= end; ++i)
      for (int p : pts_of_ref_[i]) w.X.emplace_back(p, X_w_[p]);
    for (int k = lo; k <= hi; ++k)
      for (int p : kf_pts_[k]) w.X.emplace_back(p, X_w_[p]);
    w.tail_from = tail_from_;
    w.tail_D = tail_D_;
    w.tail_D_inverse = tail_D_inverse_;
    w.tail_u = tail_u_;
    w.reports = reports_.size();
    return w;
  }
  void restore_state(const WindowState& w) {
    std::copy(w.S.begin(), w.S.end(), S_.begin() + w.lo);
    std::copy(w.U.begin(), w.U.end(), U_.begin() + w.lo);
    for (const auto& [p, X] : w.X) X_w_[p] = X;
    tail_from_ = w.tail_from;
    tail_D_ = w.tail_D;
    tail_D_inverse_ = w.tail_D_inverse;
    tail_u_ = w.tail_u;
  }

 public:
  /// Ends the stream: in full-batch mode runs PGO and BA over the whole path with every
  /// correspondence. Other modes have nothing left to do.
  void finish() {
    if (options_.mode != Mode::kFullBatch || !initialized_ || corr_.empty()) return;
    run_pgo(0, static_cast<int>(corr_.size()) - 1, /*whole_path=*/true);
    run_ba(0, static_cast<int>(corr_.size()) - 1, /*whole_path=*/true);
  }

  bool initialized() const { return initialized_; }
  /// Why INIT has not succeeded yet (empty when it has, or was not tried).
  const std::string& init_message() const { return init_message_; }
  const InitResult& init_result() const { return init_; }
  /// Map units per metre for the drift model's distances: INIT's similarity, one number for the
  /// whole path. Not the keyframes' current scales: a window drawn to a wrong anchor can shrink
  /// or blow up a keyframe's scale, and weights taken from it would feed that back into every
  /// later window. The local scale drift (tens of %) matters little to a variance that grows
  /// with distance. Scales with the map's unit, so the weights stay unit-free.
  double map_per_metre() const { return 1.0 / init_.S_wm.scale(); }

  int num_keyframes() const { return static_cast<int>(kfs_.size()); }
  int num_points() const { return static_cast<int>(pts_.size()); }
  const std::vector<map::Keyframe>& keyframes() const { return kfs_; }
  const std::vector<map::Correspondence>& correspondences() const { return corr_; }
  const std::vector<map::MapPoint>& points() const { return pts_; }
  const std::vector<StepReport>& reports() const { return reports_; }

  /// Corrected pose of the i-th keyframe (insertion order): W → camera, M units.
  /// @throws Error before INIT.
  lie::Sim3d keyframe_sim3(int i) const {
    require_init();
    GEODRIFT_CHECK(i >= 0 && i < static_cast<int>(S_.size()),
                   "keyframe index " << i << " out of range");
    return S_at(i);
  }
  /// Corrected metric pose of the i-th keyframe in W (world → camera, metres).
  lie::SE3d keyframe_pose_w(int i) const { return keyframe_sim3(i).to_se3(); }
  /// Corrected camera centre of the i-th keyframe in W (metres).
  Eigen::Vector3d keyframe_center_w(int i) const {
    return keyframe_sim3(i).inverse().translation();
  }
  /// Corrected position of the i-th point (insertion order) in W.
  Eigen::Vector3d point_w(int i) const {
    require_init();
    GEODRIFT_CHECK(i >= 0 && i < static_cast<int>(X_w_.size()),
                   "point index " << i << " out of range");
    return X_at(i);
  }
  /// Index of keyframe `id` in insertion order, or -1.
  int keyframe_index(int id) const {
    const auto it = kf_index_.find(id);
    return it == kf_index_.end() ? -1 : it->second;
  }
  /// Index of map point `id` in insertion order, or -1.
  int point_index(int id) const {
    const auto it = pt_index_.find(id);
    return it == pt_index_.end() ? -1 : it->second;
  }
  /// Standard deviation (metres) the geo terms of correspondence j use now: σ_eff of
  /// CorrectorOptions::weight_by_localization at its keyframe's current scale (before INIT, at
  /// scale 1), or its geo-tag's σ when that option is off or the view has no covariance.
  double geo_sd_m(int j) const {
    return geo_term_sd_m(corr_.at(j), kf_index_.at(corr_.at(j).keyframe));
  }
  /// The view's localization standard deviation (metres) at its keyframe's current scale, 0
  /// without a covariance.
  double localization_sd_of(int j) const {
    const auto& c = corr_.at(j);
    return localization_sd_m(c.pose_cov, S_at(kf_index_.at(c.keyframe)).scale());
  }

  /// Camera centre in W of correspondence j's geo view, as currently corrected.
  Eigen::Vector3d view_center_w(int j) const {
    const auto& c = corr_.at(j);
    return view_sim3(c, S_at(kf_index_.at(c.keyframe))).inverse().translation();
  }

 private:
  void require_init() const {
    if (!initialized_) throw Error("corrector: not initialised yet (" + init_message_ + ")");
  }

  /// The geo-tag's standard deviation (metres) of a correspondence.
  double tag_sd_m(const map::Correspondence& c) const {
    return c.sigma_m > 0 ? c.sigma_m : options_.ba_geo_sigma_m;
  }
  /// kPaper* e3 information for correspondence c whose geo term has SD `eff` (geo_term_sd_m):
  /// the paper's λ3 times σ_tag²/eff² (weight_by_localization), except that kPaperMetric
  /// weighs a direct position fix (not localized in the map) by its own 1/eff² [1/m²]
  /// (CorrectorOptions::EdgeWeights).
  double paper_geo_information(const map::Correspondence& c, double eff, bool metric) const {
    if (metric && !c.localized()) return 1.0 / (eff * eff);
    const double tag = tag_sd_m(c);
    return options_.lambda3 * (tag * tag) / (eff * eff);
  }
  /// σ of the geo terms of correspondence c localized against keyframe index k (metres).
  double geo_term_sd_m(const map::Correspondence& c, int k) const {
    const double tag = tag_sd_m(c);
    if (!options_.weight_by_localization || !c.has_pose_covariance()) return tag;
    return effective_geo_sd_m(tag, localization_sd_m(c.pose_cov, S_at(k).scale()));
  }

  /// Standard deviations (ω, σ, ν) of a relative-pose measurement dS = S_j·S_i⁻¹ under the drift
  /// model, ν in map units (its length is the raw edge's), distances at `map_per_metre`.
  Eigen::Matrix<double, 7, 1> edge_sd(const lie::Sim3d& dS, double map_per_metre) const {
    // In camera j's frame the centre of i is dS·0 = t(dS): its norm is the pair's distance in
    // map units, the angle of dS's rotation the turn between them.
    const double length = dS.translation().norm();
    const double turn = dS.rotation().log().norm();
    return options_.drift.sd(length, turn, map_per_metre);
  }
  Eigen::Matrix<double, 7, 7> edge_information(const lie::Sim3d& dS, double map_per_metre) const {
    const Eigen::Matrix<double, 7, 1> sd = edge_sd(dS, map_per_metre);
    return sd.array().square().inverse().matrix().asDiagonal();
  }

  /// Total horizontal variance (m²) the drift model gives keyframe b's position relative to
  /// keyframe a's along the current path, before the drift factor.
  double drift_variance_m2(int a, int b) const {
    if (b <= a) return 0;
    const Eigen::Vector3d cb = S_at(b).inverse().translation();
    double v = 0;
    for (int i = a + 1; i <= b; ++i) {
      const lie::Sim3d dS = sim3(kfs_[i].T_cw * kfs_[i - 1].T_cw.inverse());
      const Eigen::Matrix<double, 7, 1> sd = edge_sd(dS, map_per_metre());
      const double arm2 = (cb - S_at(i - 1).inverse().translation()).head<2>().squaredNorm();
      const double t = sd[4] / map_per_metre();  // metres
      v += arm2 * (sd[0] * sd[0] + sd[3] * sd[3]) + 2 * t * t;
    }
    return v;
  }

  /// Horizontal innovation of c (predicted view centre − geo-tag) and the parts of its total
  /// variance (m²) under the drift model from the newest anchor in use at or before its
  /// keyframe: `fixed` (the anchors' σ and the heading they leave) and `drift` (the drift
  /// model's, before the drift factor): V = fixed + k·drift.
  Eigen::Vector2d innovation(const map::Correspondence& c, double* fixed, double* drift) const {
    const int b = kf_index_.at(c.keyframe);
    const Eigen::Vector3d pred = view_sim3(c, S_at(b)).inverse().translation();
    int last = -1;  // newest anchor in use at or before b
    for (int j = static_cast<int>(corr_.size()) - 1; j >= 0 && last < 0; --j)
      if (kf_index_.at(corr_[j].keyframe) <= b) last = j;
    const double sb = tag_sd_m(c);
    *fixed = 2 * sb * sb;
    *drift = 0;
    if (last < 0) return (pred - c.y_w).head<2>();
    const int a = kf_index_.at(corr_[last].keyframe);
    const double sa = tag_sd_m(corr_[last]);
    *fixed += 2 * sa * sa;
    *drift = drift_variance_m2(a, b);
    // The heading the last two anchors in use leave: (σ_a² + σ_j²)/L² rad² over the arm to b.
    for (int j = last - 1; j >= 0; --j) {
      const double L = (corr_[last].y_w - corr_[j].y_w).head<2>().norm();
      if (L < 1e-3) continue;
      const double arm = (pred - corr_[last].y_w).head<2>().norm();
      *fixed += arm * arm * (sa * sa + tag_sd_m(corr_[j]) * tag_sd_m(corr_[j])) / (L * L);
      break;
    }
    return (pred - c.y_w).head<2>();
  }

  /// Whether correspondences p (earlier) and c agree with each other: their displacement in W
  /// matches the one the path predicts between their views, within the gate.
  bool agree(const map::Correspondence& p, const map::Correspondence& c, double chi2) const {
    const int a = kf_index_.at(p.keyframe), b = kf_index_.at(c.keyframe);
    const Eigen::Vector3d pa = view_sim3(p, S_at(a)).inverse().translation();
    const Eigen::Vector3d pb = view_sim3(c, S_at(b)).inverse().translation();
    const Eigen::Vector2d d = ((pb - pa) - (c.y_w - p.y_w)).head<2>();
    const double sa = tag_sd_m(p), sb = tag_sd_m(c);
    const double V = 2 * (sa * sa + sb * sb) + drift_factor_ * drift_variance_m2(a, b);
    return 2 * d.squaredNorm() <= chi2 * V;
  }

  /// Re-estimates the drift factor k from every anchor tested after INIT, used or not (the
  /// median ignores the wrong ones while they are fewer than half): the k for which the
  /// median of 2|e|²/(fixed + k·drift) is χ²₂'s median (2 ln 2), found by bisection in log k
  /// (the median falls as k grows).
  void update_factor() {
    std::vector<int> in;
    for (std::size_t d = 0; d < decisions_.size(); ++d)
      if (std::isfinite(decisions_[d].innovation_m) && gate_var_[d].second > 0)
        in.push_back(static_cast<int>(d));
    if (static_cast<int>(in.size()) < options_.gate_min_samples) return;
    std::vector<double> z2(in.size());
    auto median_z2 = [&](double k) {
      for (std::size_t i = 0; i < in.size(); ++i) {
        const double e = decisions_[in[i]].innovation_m;
        z2[i] = 2 * e * e / (gate_var_[in[i]].first + k * gate_var_[in[i]].second);
      }
      std::nth_element(z2.begin(), z2.begin() + z2.size() / 2, z2.end());
      return z2[z2.size() / 2];
    };
    const double target = 2 * std::log(2.0);
    double lo = std::log(options_.gate_min_factor), hi = std::log(options_.gate_max_factor);
    if (median_z2(std::exp(lo)) <= target) {
      drift_factor_ = std::exp(lo);
      return;
    }
    if (median_z2(std::exp(hi)) >= target) {
      drift_factor_ = std::exp(hi);
      return;
    }
    for (int it = 0; it < 60; ++it) {
      const double mid = 0.5 * (lo + hi);
      (median_z2(std::exp(mid)) > target ? lo : hi) = mid;
    }
    drift_factor_ = std::exp(0.5 * (lo + hi));
  }

  bool piecewise() const {
    return options_.mode == Mode::kPiecewise2D || options_.mode == Mode::kPiecewise3D;
  }

  /// The piecewise-similarity baseline over every anchor in use (correction/piecewise.hpp).
  void run_piecewise() {
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    std::vector<lie::SE3d> T(kfs_.size());
    for (std::size_t i = 0; i < kfs_.size(); ++i) T[i] = kfs_[i].T_cw;
    std::vector<PiecewiseAnchor> a;
    for (const auto& c : corr_) {
      const int k = kf_index_.at(c.keyframe);
      a.push_back({k, (c.T_vk * kfs_[k].T_cw).inverse().translation(), c.y_w});
    }
    std::stable_sort(a.begin(), a.end(), [](const PiecewiseAnchor& x, const PiecewiseAnchor& y) {
      return x.keyframe < y.keyframe;
    });
    PiecewiseOptions po;
    po.variant =
        options_.mode == Mode::kPiecewise2D ? PiecewiseVariant::k2D : PiecewiseVariant::k3D;
    StepReport rep;
    rep.kind = "piecewise";
    rep.correspondence = static_cast<int>(corr_.size()) - 1;
    try {
      const PiecewiseResult r = piecewise_similarity(T, a, init_.R_level.row(2).transpose(), po);
      clear_tail();
      S_ = r.S;
      for (std::size_t q = 0; q < pts_.size(); ++q) {
        const int k = kf_index_.at(pts_[q].reference_keyframe);
        X_w_[q] = r.segments[r.segment[k]].S_wm.act(pts_[q].position);
      }
      rep.nodes = static_cast<int>(r.segments.size());
      rep.termination = std::to_string(r.segments.size()) + " segments";
    } catch (const InvalidArgument& e) {
      rep.kind = "piecewise-failed";  // the previous state stays
      rep.termination = e.what();
    }
    rep.seconds = seconds_since(t0);
    rep.cpu_seconds = cpu_seconds_since(c0);
    reports_.push_back(rep);
  }

  static lie::Sim3d sim3(const lie::SE3d& T) { return lie::Sim3d(T); }
  /// The view's Sim3 pose from its keyframe's: S_v = T_vk · S_k (T_vk in M units).
  static lie::Sim3d view_sim3(const map::Correspondence& c, const lie::Sim3d& S_k) {
    return sim3(c.T_vk) * S_k;
  }

  lie::Sim3d chain_from_previous(int i) const {
    // S_i = (T_i · T_{i-1}⁻¹) · S_{i-1}: the raw relative pose, at the predecessor's scale.
    return sim3(kfs_[i].T_cw * kfs_[i - 1].T_cw.inverse()) * S_at(i - 1);
  }
  Eigen::Vector3d point_from_reference(int p) const {
    const int r = kf_index_.at(pts_[p].reference_keyframe);
    return S_at(r).inverse().act(kfs_[r].T_cw.act(pts_[p].position));
  }

  // ---- INIT ---------------------------------------------------------------------------------
  void try_init() {
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    std::vector<Eigen::Vector3d> centres, ups, am, aw;
    for (const auto& k : kfs_) {
      const lie::SE3d T_wc = k.T_cw.inverse();
      centres.push_back(T_wc.translation());
      ups.push_back(-(T_wc.rotation().matrix().col(1)));  // camera y is down
    }
    for (const auto& c : corr_) {
      const lie::SE3d T_vw = c.T_vk * kfs_[kf_index_.at(c.keyframe)].T_cw;
      am.push_back(T_vw.inverse().translation());
      aw.push_back(c.y_w);
    }
    init_ = estimate_init(centres, ups, am, aw, options_.init);
    StepReport rep;
    rep.correspondence = static_cast<int>(corr_.size()) - 1;
    rep.seconds = seconds_since(t0);
    rep.cpu_seconds = cpu_seconds_since(c0);
    if (!init_.ok) {
      init_message_ = init_.message;
      rep.kind = "init-failed";
      rep.termination = init_.message;
      reports_.push_back(rep);
      return;
    }
    const int n_in = static_cast<int>(init_.inliers.size());
    if (options_.gate_anchors &&
        n_in < std::min(options_.init_min_inliers, static_cast<int>(corr_.size()))) {
      // Too few agree: a wrong anchor among INIT's could be the one that made the fit; wait.
      init_message_ = "only " + std::to_string(n_in) + " of " + std::to_string(corr_.size()) +
                      " anchors agree on one similarity within " +
                      std::to_string(options_.init.ransac_threshold_m) +
                      " m: waiting for more anchors";
      rep.kind = "init-failed";
      rep.termination = init_message_;
      reports_.push_back(rep);
      return;
    }
    init_message_.clear();
    initialized_ = true;
    // INIT's RANSAC outliers leave: before INIT every anchor received is in use, so corr_ and
    // the decisions in use are in step.
    if (options_.gate_anchors) {
      std::vector<char> inlier(corr_.size(), 0);
      for (int i : init_.inliers) inlier[i] = 1;
      std::vector<map::Correspondence> kept;
      std::vector<int> kept_dec;
      int j = 0;
      for (std::size_t d = 0; d < decisions_.size(); ++d) {
        if (!decisions_[d].used) continue;
        const Eigen::Vector3d p = init_.S_wm.act(
            (corr_[j].T_vk * kfs_[kf_index_.at(corr_[j].keyframe)].T_cw).inverse().translation());
        const double r = (p - corr_[j].y_w).head<2>().norm();
        // RANSAC's threshold decides INIT's fit; an anchor is only left out of the correction
        // when it is also twice that far (and 4 SD of its own) from the others' similarity: a
        // correct anchor can miss INIT's similarity by the drift over INIT's span.
        const double out = std::max(2 * options_.init.ransac_threshold_m, 4 * tag_sd_m(corr_[j]));
        if (inlier[j] || r <= out) {
          kept.push_back(corr_[j]);
          kept_dec.push_back(static_cast<int>(d));
        } else {
          decisions_[d].used = false;
          std::ostringstream why;
          why << "INIT: outside the RANSAC consensus of the others (" << r
              << " m from their similarity)";
          decisions_[d].why = why.str();
        }
        ++j;
      }
      corr_ = std::move(kept);
      corr_dec_ = std::move(kept_dec);
      corr_of_kf_.clear();
      for (std::size_t i = 0; i < corr_.size(); ++i)
        corr_of_kf_[corr_[i].keyframe].push_back(static_cast<int>(i));
    }
    // The first window is the one of the next correspondence: [n + 1 − w, n].
    first_window_ = static_cast<int>(corr_.size()) + 1 - options_.window_correspondences;
    const lie::Sim3d S_mw = init_.S_wm.inverse();
    clear_tail();
    for (std::size_t i = 0; i < kfs_.size(); ++i) S_[i] = sim3(kfs_[i].T_cw) * S_mw;
    for (std::size_t p = 0; p < pts_.size(); ++p) X_w_[p] = init_.S_wm.act(pts_[p].position);
    rep.kind = "init";
    rep.nodes = static_cast<int>(init_.inliers.size());
    rep.final_cost = init_.rms_m;
    rep.termination = "rms " + std::to_string(init_.rms_m) + " m over " +
                      std::to_string(init_.inliers.size()) + " inliers";
    reports_.push_back(rep);
    if (piecewise()) run_piecewise();
  }

  static double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  static double cpu_seconds_since(std::clock_t c0) {
    return static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
  }

  /// The report of a window step, before it runs.
  StepReport window_report(const char* kind, int correspondence, int lo, int hi) const {
    StepReport rep;
    rep.kind = kind;
    rep.correspondence = correspondence;
    rep.window_first_keyframe = kfs_[lo].id;
    rep.window_last_keyframe = kfs_[hi].id;
    return rep;
  }

  /// Keyframe index range [lo, hi] of the window spanned by correspondences [first, last].
  std::pair<int, int> window_of(int first, int last, bool whole_path) const {
    if (whole_path) return {0, static_cast<int>(kfs_.size()) - 1};
    int lo = static_cast<int>(kfs_.size()), hi = -1;
    for (int j = first; j <= last; ++j) {
      const int k = kf_index_.at(corr_[j].keyframe);
      lo = std::min(lo, k);
      hi = std::max(hi, k);
    }
    if (options_.first_window_from_start && first == 0) lo = 0;
    return {lo, hi};
  }

  /// Applies new window poses: points follow their reference keyframe's correction, keyframes
  /// after the window (and their points) follow the last window keyframe's. O(window + points
  /// of the window): the keyframes after it share one correction, which stays lazy (tail_D_).
  /// With `U_new` (the window's local scale offsets, run_pgo), the keyframes after the window
  /// also follow the last window keyframe's offset change, lazily as well (tail_u_).
  void apply_window_update(int lo, int hi, const std::vector<lie::Sim3d>& S_new,
                           const std::vector<double>* U_new = nullptr) {
    materialize_tail(hi);
    const int n = static_cast<int>(kfs_.size());
    lie::Sim3d last_delta;  // S_new⁻¹ · S_old of the last window keyframe, W → W
    for (int i = lo; i <= hi; ++i) {
      const lie::Sim3d delta = S_new[i - lo].inverse() * S_[i];
      S_[i] = S_new[i - lo];
      for (int p : pts_of_ref_[i]) X_w_[p] = delta.act(X_w_[p]);
      if (i == hi) last_delta = delta;
    }
    double last_du = 0.0;
    if (U_new) {
      last_du = (*U_new)[hi - lo] - U_[hi];
      for (int i = lo; i <= hi; ++i) U_[i] = (*U_new)[i - lo];
    }
    if (hi + 1 >= n) return;
    // Keyframes after the window keep their relative pose to the last window keyframe: those
    // stored as they are (up to the lazy tail) now, the tail by composing its correction.
    if (tail_from_ == kNoTail) {
      tail_from_ = hi + 1;
      tail_D_ = lie::Sim3d();
      tail_u_ = 0.0;
    }
    const lie::Sim3d last_inverse = last_delta.inverse();
    for (int i = hi + 1; i < tail_from_; ++i) {  // after a window that ended later than this one
      S_[i] = S_[i] * last_inverse;
      for (int p : pts_of_ref_[i]) X_w_[p] = last_delta.act(X_w_[p]);
      U_[i] += last_du;
    }
    tail_D_ = last_delta * tail_D_;
    tail_D_inverse_ = tail_D_.inverse();
    tail_u_ += last_du;
  }

  /// Keyframe i's corrected pose: S_[i] as stored, or through the lazy tail's correction.
  lie::Sim3d S_at(int i) const { return i >= tail_from_ ? S_[i] * tail_D_inverse_ : S_[i]; }
  /// Point p's corrected position, likewise by its reference keyframe.
  Eigen::Vector3d X_at(int p) const {
    return ref_of_pt_[p] >= tail_from_ ? tail_D_.act(X_w_[p]) : X_w_[p];
  }
  void set_X(int p, const Eigen::Vector3d& X) {
    X_w_[p] = ref_of_pt_[p] >= tail_from_ ? tail_D_inverse_.act(X) : X;
  }
  /// Stores keyframes up to index `last` (and their points) with the tail's correction applied.
  void materialize_tail(int last) {
    const int end = std::min(last, static_cast<int>(kfs_.size()) - 1);
    if (end < tail_from_) return;
    for (int i = tail_from_; i <= end; ++i) {
      S_[i] = S_[i] * tail_D_inverse_;
      for (int p : pts_of_ref_[i]) X_w_[p] = tail_D_.act(X_w_[p]);
      U_[i] += tail_u_;
    }
    tail_from_ = end + 1;
    if (tail_from_ >= static_cast<int>(kfs_.size())) clear_tail();
  }
  void clear_tail() {
    tail_from_ = kNoTail;
    tail_D_ = lie::Sim3d();
    tail_D_inverse_ = lie::Sim3d();
    tail_u_ = 0.0;
  }

  // ---- PGO (paper Sec. 3.5) ----------------------------------------------------------------
  void run_pgo(int first, int last, bool whole_path = false) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto [lo, hi] = window_of(first, last, whole_path);
    const std::clock_t c0 = std::clock();
    StepReport rep = window_report("pgo", last, lo, hi);

    const int nw = hi - lo + 1;
    materialize_tail(hi);
    std::vector<lie::Sim3d> S(S_.begin() + lo, S_.begin() + hi + 1);  // window nodes
    std::map<int, lie::Sim3d> fixed;                                  // covisible past
    const int nv = last - first + 1;
    std::vector<lie::Sim3d> V(nv);  // geo view nodes
    for (int j = 0; j < nv; ++j) {
      const auto& c = corr_[first + j];
      V[j] = view_sim3(c, S_at(kf_index_.at(c.keyframe)));
    }
    solver::Problem problem;
    const solver::RobustLoss trivial;
    int edges = 0;
    auto node = [&](int i) -> lie::Sim3d* {
      if (i >= lo && i <= hi) return &S[i - lo];
      return &fixed.try_emplace(i, S_at(i)).first->second;
    };
    const bool paper = options_.edge_weights != CorrectorOptions::EdgeWeights::kDriftModel;
    const bool metric = options_.edge_weights == CorrectorOptions::EdgeWeights::kPaperMetric;
    // The paper's λ on (ω, σ) and, with kPaperMetric, on ν in metres: λ / m² per map unit²,
    // m = map_per_metre() (INIT's scale, so the weights follow the map's unit).
    auto paper_information = [&](double lambda) {
      Eigen::Matrix<double, 7, 1> w = Eigen::Matrix<double, 7, 1>::Constant(lambda);
      if (metric) w.tail<3>() /= map_per_metre() * map_per_metre();
      return Eigen::Matrix<double, 7, 7>(w.asDiagonal());
    };
    const Eigen::Matrix<double, 7, 7> info1 = paper_information(options_.lambda1);
    const Eigen::Matrix<double, 7, 7> info2 = paper_information(options_.lambda2);
    // Local scale offsets u_k (CorrectorOptions::local_scale_sd): the window's free, the
    // keyframes before it held fixed like their poses.
    const bool local = metric && options_.local_scale_sd > 0;
    std::vector<double> U(U_.begin() + lo, U_.begin() + hi + 1);
    std::map<int, double> fixed_u;
    auto unode = [&](int i) -> double* {
      if (i >= lo && i <= hi) return &U[i - lo];
      return &fixed_u.try_emplace(i, U_[i]).first->second;
    };
    auto add_e1 = [&](int i, int j) {
      lie::Sim3d* Si = node(i);
      lie::Sim3d* Sj = node(j);
      // ΔS_ij from the poses before optimisation: e1 = 0 at the start.
      const lie::Sim3d dS = *Sj * Si->inverse();
      if (metric) {
        // The translation's SD is the VO's direction error over the pair's own length,
        // DriftModel::direction_sd_rad · d (in map units), not 1/√λ1 metres whatever the length.
        Eigen::Matrix<double, 7, 7> info = info1;
        const double t = edge_sd(dS, map_per_metre())[4];
        info.diagonal().tail<3>().setConstant(1.0 / (t * t));
        if (local) {
          // e1 = 0 at the start with the offsets as they are: the measurement absorbs them.
          const double du = U_[i] - U_[j];
          const lie::Sim3d dS_local =
              lie::Sim3d::exp((Eigen::Matrix<double, 7, 1>() << 0, 0, 0, du, 0, 0, 0).finished()) *
              dS;
          problem.add_residual_block(solver::RelativeSim3LocalScaleResidual{dS_local}, trivial,
                                     info, Si, Sj, solver::euclidean<1>(unode(i)),
                                     solver::euclidean<1>(unode(j)));
        } else {
          problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{dS}, trivial, info,
                                     Si, Sj);
        }
      } else if (paper)
        problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{dS}, trivial,
                                   options_.lambda1, Si, Sj);
      else
        problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{dS}, trivial,
                                   edge_information(dS, map_per_metre()), Si, Sj);
      ++edges;
    };
    std::set<std::pair<int, int>> linked;
    // Covisible pairs with one end in the window and none after it: b in [lo, hi], in the
    // order of shared_.
    std::vector<std::pair<int, int>> covisible;
    for (int b = lo; b <= hi; ++b)
      for (int a : covisible_before_[b]) covisible.emplace_back(a, b);
    std::sort(covisible.begin(), covisible.end());
    for (const auto& pair : covisible) {
      if (shared_.at(pair) < options_.min_shared_points) continue;
      add_e1(pair.first, pair.second);
      linked.insert(pair);
    }
    if (options_.link_consecutive) {
      for (int d = 1; d <= options_.consecutive_links; ++d)
        for (int i = std::max(lo, d); i <= hi; ++i)
          if (linked.insert({i - d, i}).second) add_e1(i - d, i);
    }
    for (int j = 0; j < nv; ++j) {
      const auto& c = corr_[first + j];
      const int k = kf_index_.at(c.keyframe);
      // e2: keyframe -> view, with the fixed relative pose T_vk as ΔS.
      const solver::RelativePoseResidual<lie::Sim3d> e2{sim3(c.T_vk)};
      // e3: the view's camera centre (not its translation) minus the geo-tag.
      const solver::CameraCentrePriorResidual<lie::Sim3d> e3{c.y_w};
      if (paper) {
        // weighted down by the view's localization uncertainty
        // (CorrectorOptions::weight_by_localization).
        const double eff = geo_term_sd_m(c, k);
        if (metric)
          problem.add_residual_block(e2, trivial, info2, node(k), &V[j]);
        else
          problem.add_residual_block(e2, trivial, options_.lambda2, node(k), &V[j]);
        problem.add_residual_block(e3, trivial, paper_geo_information(c, eff, metric), &V[j]);
      } else {
        // The VO's error over the keyframe→view offset, plus the view's own localization
        // covariance (in the map, so already in map units) where it has one.
        Eigen::Matrix<double, 7, 1> sd = edge_sd(e2.dS_ij, map_per_metre());
        Eigen::Matrix<double, 7, 7> cov = sd.array().square().matrix().asDiagonal();
        if (c.has_pose_covariance()) {
          const int at[6] = {0, 1, 2, 4, 5, 6};  // (ω, ν) into (ω, σ, ν)
          for (int a = 0; a < 6; ++a)
            for (int b = 0; b < 6; ++b) cov(at[a], at[b]) += c.pose_cov(a, b);
        }
        const Eigen::Matrix<double, 7, 7> info = cov.inverse();
        problem.add_residual_block(e2, trivial,
                                   Eigen::Matrix<double, 7, 7>(0.5 * (info + info.transpose())),
                                   node(k), &V[j]);
        const double tag = tag_sd_m(c);
        problem.add_residual_block(e3, trivial, 1.0 / (tag * tag), &V[j]);
      }
      edges += 2;
    }
    if (local) {
      // The offsets' Gauss–Markov prior along consecutive keyframes, ρ = exp(−d/L) over the
      // step's length in W (metres); the path's first keyframe has the stationary prior.
      const double sd = options_.local_scale_sd, L = options_.local_scale_length_m;
      if (lo == 0)
        problem.add_residual_block(solver::LocalScalePriorResidual{}, trivial, 1.0 / (sd * sd),
                                   solver::euclidean<1>(unode(0)));
      for (int k = std::max(lo, 1); k <= hi; ++k) {
        const double d =
            (S_at(k).inverse().translation() - S_at(k - 1).inverse().translation()).norm();
        const double rho = std::exp(-d / L);
        const double var = sd * sd * std::max(1.0 - rho * rho, 1e-12);
        problem.add_residual_block(solver::LocalScaleLinkResidual{rho}, trivial, 1.0 / var,
                                   solver::euclidean<1>(unode(k - 1)),
                                   solver::euclidean<1>(unode(k)));
      }
      for (auto& [i, u] : fixed_u) problem.set_constant(&u);
    }
    for (auto& [i, Sf] : fixed) problem.set_constant(&Sf);

    rep.time_setup = seconds_since(t0);
    solver::Options lm;
    lm.max_iterations = options_.pgo_max_iterations;
    // kAuto: the block Cholesky (7×7 kernels, no BLAS) on these thin Sim(3) graphs. Measured on
    // bench_correction (02, interval 100, OPENBLAS_NUM_THREADS=1): PGO 0.13 -> 0.078 s CPU over
    // the 44 windows, same 350 iterations and mean 2D error (0.923 m) as CHOLMOD.
    lm.linear_solver = solver::LinearSolverType::kAuto;
    lm.function_tolerance = 1e-10;
    lm.num_threads = options_.num_threads;
    if (!paper) {
      // Drift weights span rotation, scale and metre-level translation informations over
      // orders of magnitude, and a window starts far from its optimum when the new anchor is
      // metres off the extrapolated path: the solver's setting for such Sim(3) chains
      // (solver::Options, docs/library.md). Without it, simulated 08 (trajectory only, seed 5,
      // interval 300) stopped a window at 50 iterations 1000x above its noise-level cost and
      // every later window diverged.
      lm.geodesic_acceleration = true;
      lm.backtracking = true;
      lm.initial_lambda = 1e-8;
    }
    const solver::Summary sum = solver::LevenbergMarquardt(lm).solve(&problem);
    rep.nodes = nw + nv;
    rep.edges = edges;
    fill(&rep, sum);
    // A window update that rescales a keyframe by more than max_window_rescale is a diverged
    // solve, not a correction (a monocular VO's scale drifts by tens of per cent between
    // anchors, docs/correction_model.md): the window keeps its state, and the report says so.
    double rescale = 1.0;
    for (int i = lo; i <= hi; ++i)
      rescale =
          std::max(rescale, std::exp(std::abs(std::log(S[i - lo].scale() / S_at(i).scale()))));
    if (usable(sum) && rescale <= options_.max_window_rescale) {
      // Keyframes after the window follow its last keyframe, its local scale offset included.
      apply_window_update(lo, hi, S, local ? &U : nullptr);
    } else if (usable(sum)) {
      rep.termination +=
          " (update rejected: a keyframe rescaled by " + std::to_string(rescale) + "x)";
      ++rejected_updates_;
    }
    rep.seconds = seconds_since(t0);
    rep.cpu_seconds = cpu_seconds_since(c0);
    reports_.push_back(rep);
  }

  // ---- BA with the geo term (paper Sec. 3.6) ------------------------------------------------
  void run_ba(int first, int last, bool whole_path = false) {
    const auto t0 = std::chrono::steady_clock::now();
    const auto [lo, hi] = window_of(first, last, whole_path);
    const std::clock_t c0 = std::clock();
    StepReport rep = window_report("ba", last, lo, hi);

    materialize_tail(hi);
    const int nw = hi - lo + 1;
    std::vector<lie::SE3d> T(nw);
    for (int i = 0; i < nw; ++i) T[i] = S_at(lo + i).to_se3();
    std::map<int, lie::SE3d> fixed;
    // Points seen by window keyframes (C5), optimised in W.
    std::vector<int> pts;
    // Keyframe centres in W, for the parallax test (the window's and its points' observers).
    std::unordered_map<int, Eigen::Vector3d> centre;
    auto centre_of = [&](int k) -> const Eigen::Vector3d& {
      auto [it, fresh] = centre.try_emplace(k);
      if (fresh) it->second = S_at(k).inverse().translation();
      return it->second;
    };
    const double max_cos = std::cos(options_.ba_min_parallax_deg * M_PI / 180.0);
    std::vector<Eigen::Vector3d> rays;
    // The points window keyframes observe, in index order.
    std::vector<int> seen;
    for (int k = lo; k <= hi; ++k) seen.insert(seen.end(), kf_pts_[k].begin(), kf_pts_[k].end());
    std::sort(seen.begin(), seen.end());
    seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
    for (const int p : seen) {
      if (options_.ba_min_parallax_deg > 0) {
        // Widest angle between two rays to the point from keyframes the BA uses.
        rays.clear();
        for (const auto& [k, o] : observers_[p]) {
          if (k > hi && !whole_path) continue;
          rays.push_back((X_at(p) - centre_of(k)).normalized());
        }
        if (detail::widest_ray_cos(rays, max_cos) > max_cos) {
          ++rep.skipped_points;
          continue;  // moves with its reference keyframe
        }
      }
      pts.push_back(p);
    }
    std::vector<Eigen::Vector3d> X(pts.size());
    for (std::size_t q = 0; q < pts.size(); ++q) X[q] = X_at(pts[q]);

    auto pose = [&](int k) -> lie::SE3d* {
      if (k >= lo && k <= hi) return &T[k - lo];
      return &fixed.try_emplace(k, S_at(k).to_se3()).first->second;
    };
    // The reprojection terms (C_map-kf of the points C5), built once; the problem is rebuilt
    // per robust round (the Huber threshold is fixed per residual block).
    struct Obs {
      solver::ReprojectionResidual r;
      lie::SE3d* T;
      int q;
    };
    std::vector<Obs> obs;
    for (std::size_t q = 0; q < pts.size(); ++q) {
      for (const auto& [k, oi] : observers_[pts[q]]) {
        if (k > hi && !whole_path) continue;  // keyframes after the window are not corrected yet
        const map::Observation& o = obs_[oi];
        const map::Camera& cam = camera_of(k);
        solver::ReprojectionResidual r{cam.fx, cam.fy, cam.cx, cam.cy, o.pixel};
        Eigen::Matrix<double, 2, 1> e;
        lie::SE3d* Tk = pose(k);
        if (!r(*Tk, X[q], &e)) continue;  // behind the camera now: not a usable observation
        obs.push_back({r, Tk, static_cast<int>(q)});
      }
    }
    std::vector<int> geo;  // correspondences with a geo term: keyframe in the window, observed
    {
      std::vector<char> observed(nw, 0);
      for (const Obs& o : obs)
        if (o.T >= T.data() && o.T < T.data() + nw) observed[o.T - T.data()] = 1;
      for (int j = first; j <= last; ++j) {
        const int k = kf_index_.at(corr_[j].keyframe);
        if (k >= lo && k <= hi && observed[k - lo]) geo.push_back(j);
      }
    }
    const int edges = static_cast<int>(obs.size() + geo.size());
    rep.nodes = nw + static_cast<int>(pts.size());
    rep.edges = edges;
    if (edges == 0) {
      rep.termination = "no observations in the window";
      rep.seconds = seconds_since(t0);
      rep.cpu_seconds = cpu_seconds_since(c0);
      reports_.push_back(rep);
      return;
    }
    std::vector<char> keep(obs.size(), 1);  // pass 2: observations within the χ² gate
    auto solve_with = [&](double huber_px, int max_iterations) {
      solver::Problem problem;
      const solver::RobustLoss huber =
          huber_px > 0 ? solver::RobustLoss::huber(huber_px) : solver::RobustLoss();
      for (std::size_t i = 0; i < obs.size(); ++i)
        if (keep[i]) problem.add_residual_block(obs[i].r, huber, 1.0, obs[i].T, &X[obs[i].q]);
      for (int j : geo) {
        const auto& c = corr_[j];
        const int k = kf_index_.at(c.keyframe);
        if (!problem.has_parameter(&T[k - lo])) continue;  // all its observations gated out
        // The keyframe→view offset in metres at the keyframe's current scale.
        const double s_k = S_at(k).scale();
        const Eigen::Vector3d c_vk = c.T_vk.inverse().translation() / s_k;
        const double sigma = geo_term_sd_m(c, k);
        problem.add_residual_block(GeoViewCentreResidual{c_vk, c.y_w}, solver::RobustLoss(),
                                   1.0 / (sigma * sigma), &T[k - lo]);
      }
      for (auto& [k, Tf] : fixed)
        if (problem.has_parameter(&Tf)) problem.set_constant(&Tf);
      solver::Options lm;
      lm.max_iterations = max_iterations;
      // Relative cost tolerance: ba_cost_tolerance_sd SDs of ½χ² with m scalar residuals.
      const double m = 2.0 * edges;
      lm.function_tolerance = options_.ba_cost_tolerance_sd * std::sqrt(2.0 / m);
      lm.linear_solver = solver::LinearSolverType::kSchur;
      lm.num_threads = options_.num_threads;
      return solver::LevenbergMarquardt(lm).solve(&problem);
    };
    rep.time_setup = seconds_since(t0);
    solver::Summary sum;
    rep.huber_px = options_.ba_huber_px;
    rep.passes = 1;
    if (!options_.ba_two_pass) {
      sum = solve_with(options_.ba_huber_px, options_.ba_max_iterations);
    } else {
      // Pass 1: every observation (plain least squares or a wide Huber). Pass 2, when pass 1
      // left a gross residual: plain least squares on the observations within the χ² gate at
      // pass 1's solution (CorrectorOptions::ba_two_pass); a failed pass 2 keeps pass 1's.
      const solver::Summary s1 =
          solve_with(options_.ba_first_pass_huber_px, options_.ba_max_iterations);
      sum = s1;
      rep.huber_px = options_.ba_first_pass_huber_px;
      if (usable(s1)) {
        const std::vector<lie::SE3d> T_keep = T;
        const std::vector<Eigen::Vector3d> X_keep = X;
        Eigen::Matrix<double, 2, 1> e;
        std::vector<int> kept_per_point(pts.size(), 0);
        for (std::size_t i = 0; i < obs.size(); ++i) {
          keep[i] = obs[i].r(*obs[i].T, X[obs[i].q], &e) && e.norm() <= options_.ba_huber_px;
          kept_per_point[obs[i].q] += keep[i];
        }
        // A point left with one observation has no depth: it stays where pass 1 put it.
        for (std::size_t i = 0; i < obs.size(); ++i)
          if (kept_per_point[obs[i].q] < 2) keep[i] = 0;
        for (std::size_t i = 0; i < obs.size(); ++i) rep.gated_observations += !keep[i];
        // Pass 2 only when pass 1 left a gross residual (an outlier, not the tail of the noise).
        bool gross = false;
        for (std::size_t i = 0; i < obs.size() && !gross; ++i)
          gross = !obs[i].r(*obs[i].T, X[obs[i].q], &e) || e.norm() > options_.ba_outlier_px;
        if (!gross) rep.gated_observations = 0;
        solver::Summary s2 = gross ? solve_with(0.0, options_.ba_max_iterations) : s1;
        if (!gross) {
          sum = s1;
          rep.passes = 1;
          rep.huber_px = options_.ba_first_pass_huber_px;
          rep.pass1_iterations = s1.iterations;
        } else if (usable(s2)) {
          s2.initial_cost = s1.initial_cost;  // of pass 1's loss
          s2.iterations += s1.iterations;
          rep.pass1_iterations = s1.iterations;
          s2.trace.insert(s2.trace.begin(), s1.trace.begin(), s1.trace.end());
          sum = std::move(s2);
          rep.passes = 2;
          rep.huber_px = 0;
        } else {
          std::copy(T_keep.begin(), T_keep.end(), T.begin());
          std::copy(X_keep.begin(), X_keep.end(), X.begin());
        }
      }
    }
    fill(&rep, sum);
    if (usable(sum)) {
      std::vector<lie::Sim3d> S_new(nw);
      for (int i = 0; i < nw; ++i) {
        // Back to Sim3 at the keyframe's scale: [s·R | s·t].
        const double s = S_at(lo + i).scale();
        S_new[i] = lie::Sim3d(T[i].rotation(), s * T[i].translation(), s);
      }
      // Points of the window were optimised directly: overwrite what the update rule moved.
      apply_window_update(lo, hi, S_new);
      for (std::size_t q = 0; q < pts.size(); ++q) set_X(pts[q], X[q]);
    }
    rep.seconds = seconds_since(t0);
    rep.cpu_seconds = cpu_seconds_since(c0);
    reports_.push_back(rep);
  }

  const map::Camera& camera_of(int k) const {
    const auto it = cameras_.find(kfs_[k].camera_id);
    if (it == cameras_.end())
      throw Error("corrector: BA needs the camera of keyframe " + std::to_string(kfs_[k].id));
    return it->second;
  }

  static bool usable(const solver::Summary& s) {
    return s.converged() || s.termination == solver::Termination::kMaxIterations ||
           s.termination == solver::Termination::kNoDecrease;
  }
  static void fill(StepReport* rep, const solver::Summary& s) {
    rep->initial_cost = s.initial_cost;
    rep->final_cost = s.final_cost;
    rep->iterations = s.iterations;
    rep->termination = solver::to_string(s.termination);
    if (!s.message.empty()) rep->termination += ": " + s.message;
    rep->time_evaluate = s.time_evaluate;
    rep->time_assemble = s.time_assemble;
    rep->time_analyze = s.time_analyze;
    rep->time_factorize = s.time_factorize;
    rep->time_solve = s.time_solve;
    rep->linear_solver = s.linear_solver;
    rep->cost_trace.clear();
    for (const auto& t : s.trace) rep->cost_trace.push_back(t.cost);
  }

  CorrectorOptions options_;
  std::unordered_map<int, map::Camera> cameras_;
  std::vector<map::Keyframe> kfs_;
  std::unordered_map<int, int> kf_index_;
  std::vector<lie::Sim3d> S_;  ///< corrected keyframe poses (valid after INIT)
  /// Local log-scale offsets u_k of the keyframes (CorrectorOptions::local_scale_sd; 0 when
  /// unused). A keyframe after the last window carries the last window keyframe's.
  std::vector<double> U_;
  std::vector<map::MapPoint> pts_;
  std::unordered_map<int, int> pt_index_;
  std::vector<Eigen::Vector3d> X_w_;  ///< corrected points (after INIT)
  /// The lazy tail of the window updates: keyframes from index tail_from_ on store S_[i] with
  /// S_true = S_[i]·tail_D_⁻¹, their points X_true = tail_D_·X_w_ (S_at, X_at), and their
  /// local scale offsets u_true = U_[i] + tail_u_.
  static constexpr int kNoTail = std::numeric_limits<int>::max();
  int tail_from_ = kNoTail;
  lie::Sim3d tail_D_, tail_D_inverse_;
  double tail_u_ = 0.0;
  std::vector<std::vector<int>> pts_of_ref_;        ///< kf index -> points it is the reference of
  std::vector<int> ref_of_pt_;                      ///< point -> its reference keyframe's index
  std::vector<std::vector<int>> kf_pts_;            ///< kf index -> points it observes
  std::vector<std::vector<int>> covisible_before_;  ///< kf index b -> every a < b in shared_
  std::vector<std::vector<std::pair<int, int>>> observers_;  ///< point -> (kf index, obs index)
  std::vector<map::Observation> obs_;
  std::map<std::pair<int, int>, int> shared_;  ///< (kf index a < b) -> shared points
  /// point -> its observers' kf indices, for tracks longer than covisibility_max_track
  std::unordered_map<int, std::unordered_set<int>> long_track_observers_;
  std::vector<map::Correspondence> corr_;  ///< in use, in the order they were taken in
  std::unordered_map<int, std::vector<int>> corr_of_kf_;  ///< keyframe id -> corr_ indices
  std::vector<int> corr_dec_;                         ///< decision (received_ index) of corr_[j]
  std::vector<map::Correspondence> received_;         ///< every one received (duplicates aside)
  std::vector<AnchorDecision> decisions_;             ///< what was done with received_[d]
  std::unordered_map<int, AnchorDecision> excluded_;  ///< exclude_correspondence()
  std::vector<std::pair<double, double>> gate_var_;   ///< (fixed, drift) variance of received_[d]
  double drift_factor_ = 1.0;
  int rejected_updates_ = 0;  ///< PGO window updates not applied (max_window_rescale)
  int grown_windows_ = 0;     ///< window steps run again over more keyframes
  bool initialized_ = false;
  int first_window_ = -1;  ///< `first` of the first window after INIT (its correspondences)
  InitResult init_;
  std::string init_message_;
  std::vector<StepReport> reports_;
};

}  // namespace geodrift::correction
