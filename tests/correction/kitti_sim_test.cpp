// The Corrector on the simulated KITTI 02 drift (issue 4, item 7): shipped data in data/kitti.
#include "support/kitti_sim.hpp"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>

#include "geodrift/correction/local_scale.hpp"
#include "geodrift/correction/replay.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/eval/scale_factor.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

using namespace geodrift;

namespace {
struct Outcome {
  double mean_2d = 0;
  double reprojection_rms_px = 0;
  std::vector<Eigen::Vector3d> centres;
};

bool reduced() {
  const char* ci = std::getenv("CI");
  const char* r = std::getenv("GEODRIFT_REDUCED");
  return (ci && std::string(ci) == "true") || (r && std::string(r) == "1");
}

Outcome run(const sim::SimulatedSequence& s, const std::vector<map::Correspondence>& corr,
            correction::Mode mode, bool ba_two_pass = true) {
  correction::CorrectorOptions opt;
  opt.mode = mode;
  opt.ba_two_pass = ba_two_pass;
  correction::Corrector c(opt);
  correction::replay(s.map, corr, &c);
  REQUIRE(c.initialized());
  Outcome o;
  for (int i = 0; i < c.num_keyframes(); ++i) o.centres.push_back(c.keyframe_center_w(i));
  o.mean_2d = eval::horizontal_errors(o.centres, s.gt_center_w).all.mean;
  double sse = 0;
  const map::Camera& cam = s.map.cameras.front();
  for (const auto& ob : s.map.observations) {
    const Eigen::Vector3d p =
        c.keyframe_pose_w(c.keyframe_index(ob.keyframe)).act(c.point_w(c.point_index(ob.point)));
    sse += (cam.project(p) - ob.pixel).squaredNorm();
  }
  o.reprojection_rms_px = std::sqrt(sse / static_cast<double>(s.map.observations.size()));
  return o;
}
}  // namespace

TEST_CASE("On simulated KITTI 02 at interval 100, PGO corrects the drift and BA refines it",
          "[correction][sim]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 1);
  std::vector<sim::GeoView> views;
  const auto corr = sim::kitti_correspondences(s, 100, &views);
  REQUIRE(corr.size() >= 40);

  const Outcome init = run(s, corr, correction::Mode::kInitOnly);
  const Outcome pgo = run(s, corr, correction::Mode::kInitPgo);
  const Outcome ours = run(s, corr, correction::Mode::kOurs);
  INFO("mean 2D error: INIT " << init.mean_2d << " m, INIT+PGO " << pgo.mean_2d << " m, Ours "
                              << ours.mean_2d << " m; reprojection RMS: PGO "
                              << pgo.reprojection_rms_px << " px, Ours " << ours.reprojection_rms_px
                              << " px");
  CHECK(init.mean_2d / pgo.mean_2d >= 5.0);
  CHECK(ours.mean_2d < pgo.mean_2d);
  CHECK(ours.reprojection_rms_px < pgo.reprojection_rms_px);
  // The simulated pixels carry 1 px noise per axis: a refined map reprojects near sqrt(2) px.
  CHECK(ours.reprojection_rms_px < 3.0);

  // Scale factor (corrected / true distance over 10 keyframes) along the PGO-corrected path.
  const auto sf = eval::scale_factor_along_path(pgo.centres, s.gt_center_w);
  std::vector<double> dev;
  for (const auto& x : sf) dev.push_back(std::abs(x.factor - 1.0));
  std::sort(dev.begin(), dev.end());
  const double median = dev[dev.size() / 2], p90 = dev[dev.size() * 9 / 10];
  const auto sf_init = eval::scale_factor_along_path(init.centres, s.gt_center_w);
  std::vector<double> dev_init;
  for (const auto& x : sf_init) dev_init.push_back(std::abs(x.factor - 1.0));
  std::sort(dev_init.begin(), dev_init.end());
  INFO("|scale factor - 1|: PGO median " << median << ", 90th percentile " << p90
                                         << "; INIT median " << dev_init[dev_init.size() / 2]);
  CHECK(median < 0.05);
  CHECK(median < dev_init[dev_init.size() / 2]);
}

TEST_CASE("On a simulated stretch of KITTI 08 at interval 300, BA after PGO does not undo PGO",
          "[correction][sim]") {
  // The failure this guards against: the sliding-window BA clamped to keyframes that only INIT
  // had placed, turning the heading and bending the path by tens of metres between anchors
  // (Ours 9.1 m against INIT+PGO 5.6 m on this stretch before the first window reached back
  // to keyframe 0). It is a regression check on this stretch, not a general guarantee: on
  // frames 0-1500 of the same seed Ours measured 5.93 m against INIT+PGO 4.95 m (+20 %), with
  // full batch also above PGO (the simulator's pixels come from the drifted map, so BA pulls
  // toward the drifted shape between anchors; docs/RESULTS.md).
  const sim::SimulatedSequence s = test::simulate_kitti("08", 21, 2000);
  const auto corr = sim::kitti_correspondences(s, 300);
  REQUIRE(corr.size() >= 9);

  const Outcome pgo = run(s, corr, correction::Mode::kInitPgo);
  const Outcome ours = run(s, corr, correction::Mode::kOurs);
  const Outcome batch = run(s, corr, correction::Mode::kFullBatch);
  INFO("mean 2D error: INIT+PGO " << pgo.mean_2d << " m, Ours " << ours.mean_2d << " m, full batch "
                                  << batch.mean_2d << " m");
  // BA refines what PGO corrected: at most 5 % worse than PGO alone, and the sliding window
  // within 5 % of one BA over the whole stretch with every anchor.
  CHECK(ours.mean_2d <= 1.05 * pgo.mean_2d);
  CHECK(ours.mean_2d <= 1.05 * batch.mean_2d);
  CHECK(ours.reprojection_rms_px < pgo.reprojection_rms_px);
}

TEST_CASE("On simulated KITTI 08 at interval 100, INIT+BA follows the anchors with the two-pass BA",
          "[correction][sim][slow]") {
  // INIT+BA (BA with the geo term, no PGO): each window starts with keyframes chained 80 m
  // past the last anchor, 3-30 m from the next geo-tag. With Huber at √5.991 px throughout,
  // the σ = 5 cm geo term tears the anchored keyframe off its (correct) observations instead
  // of bending the map, and the path diverges (whole sequence, seed 1: 48 m). The two-pass BA
  // (plain least squares, χ² gate, least squares; CorrectorOptions::ba_two_pass) follows the
  // anchors. Reduced (CI): frames 0-1500 of the same seed (1.8 m against 38 m; on that stretch
  // seed 2 still diverges with both: INIT+BA stays fragile, 22.6 m against 28.6 m).
  const sim::SimulatedSequence s =
      test::simulate_kitti("08", 1, reduced() ? 1500 : std::numeric_limits<int>::max());
  const auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 14);

  const Outcome one = run(s, corr, correction::Mode::kInitBa, /*ba_two_pass=*/false);
  const Outcome two = run(s, corr, correction::Mode::kInitBa, /*ba_two_pass=*/true);
  INFO("INIT+BA mean 2D error: one pass (Huber) " << one.mean_2d << " m, two passes " << two.mean_2d
                                                  << " m");
  CHECK(two.mean_2d < 2.5);
  CHECK(one.mean_2d > 10.0 * two.mean_2d);
}

TEST_CASE("Cross-validation gives the pose graph a local scale where the VO's scale comes and goes",
          "[correction][sim][local_scale]") {
  // The simulator's scale drift has a mean-reverting part (SD 0.08 over ~25 m) on top of a slow
  // random walk: the paper's chain alone (local scale SD 0) cannot follow it between anchors
  // every 100 frames without a map (docs/RESULTS.md, trajectory only: 1.47 m against 1.08 m for
  // a similarity per segment, seeds 1-5).
  const sim::SimulatedSequence s = test::simulate_kitti("02", 1);
  map::Map traj = s.map;
  traj.points.clear();
  traj.observations.clear();
  const auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 40);
  correction::CorrectorOptions opt;
  opt.mode = correction::Mode::kInitPgo;
  const correction::LocalScaleChoice choice = correction::choose_local_scale(traj, corr, opt);
  INFO(choice.message);
  REQUIRE(choice.cross_validated);
  REQUIRE(choice.rms_m.size() == choice.candidates.size());
  CHECK(choice.held_out >= 15);
  CHECK(choice.sd > 0);
  CHECK(choice.candidates.front() == 0);
  CHECK(choice.rms_m.front() > 0);  // the held-out error of the chain alone
  // The chosen SD is the candidate with the lowest held-out error.
  const auto best = std::min_element(choice.rms_m.begin(), choice.rms_m.end());
  CHECK(choice.sd == choice.candidates[static_cast<std::size_t>(best - choice.rms_m.begin())]);
  CHECK(*best < choice.rms_m.front());
  auto error_with = [&](double sd) {
    correction::CorrectorOptions o = opt;
    o.local_scale_sd = sd;
    correction::Corrector c(o);
    correction::replay(traj, corr, &c);
    REQUIRE(c.initialized());
    std::vector<Eigen::Vector3d> centres;
    for (int i = 0; i < c.num_keyframes(); ++i) centres.push_back(c.keyframe_center_w(i));
    return eval::horizontal_errors(centres, s.gt_center_w).all.mean;
  };
  const double chain = error_with(0.0), chosen = error_with(choice.sd);
  INFO("local scale SD " << choice.sd << ": mean 2D error " << chosen << " m, chain alone " << chain
                         << " m");
  CHECK(chosen <= 0.85 * chain);

  // Too few anchors to split: the options' value stands, and the message says why.
  const std::vector<map::Correspondence> few(corr.begin(), corr.begin() + 10);
  opt.local_scale_sd = 0.02;
  const correction::LocalScaleChoice kept = correction::choose_local_scale(traj, few, opt);
  CHECK_FALSE(kept.cross_validated);
  CHECK(kept.sd == 0.02);
  CHECK(kept.message.find("too few") != std::string::npos);
  // Not above the size limits (10 corrections would cost minutes there).
  const correction::LocalScaleChoice big =
      correction::choose_local_scale(traj, corr, opt, correction::default_local_scale_candidates(),
                                     4, static_cast<int>(corr.size()) - 1);
  CHECK_FALSE(big.cross_validated);
  CHECK(big.message.find("not cross-validated") != std::string::npos);
  // Not with the weights or modes that do not use the offsets.
  opt.edge_weights = correction::CorrectorOptions::EdgeWeights::kDriftModel;
  CHECK_FALSE(correction::choose_local_scale(traj, corr, opt).cross_validated);
  opt.edge_weights = correction::CorrectorOptions::EdgeWeights::kPaperMetric;
  opt.mode = correction::Mode::kPiecewise2D;
  CHECK_FALSE(correction::choose_local_scale(traj, corr, opt).cross_validated);
}
