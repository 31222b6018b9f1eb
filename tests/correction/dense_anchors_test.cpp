// The Corrector with dense anchors (street-view panoramas every few metres localize every 1-3
// keyframes): the paper's window of the newest three correspondences then spans a few
// keyframes only; CorrectorOptions::min_window_keyframes lengthens it.
#include <catch2/catch.hpp>

#include "geodrift/correction/replay.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"
#include "support/kitti_sim.hpp"

using namespace geodrift;

namespace {
double mean_2d_error(const sim::SimulatedSequence& s, const std::vector<map::Correspondence>& corr,
                     correction::Mode mode, int min_window_keyframes) {
  correction::CorrectorOptions opt;
  opt.mode = mode;
  opt.min_window_keyframes = min_window_keyframes;
  correction::Corrector c(opt);
  correction::replay(s.map, corr, &c);
  REQUIRE(c.initialized());
  std::vector<Eigen::Vector3d> centres;
  for (int i = 0; i < c.num_keyframes(); ++i) centres.push_back(c.keyframe_center_w(i));
  return eval::horizontal_errors(centres, s.gt_center_w).all.mean;
}
}  // namespace

TEST_CASE("With an anchor every 10 frames the window is lengthened and PGO follows the anchors",
          "[correction][sim]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 3, 1200);
  const auto corr = sim::kitti_correspondences(s, 10);
  REQUIRE(corr.size() >= 90);

  const double paper = mean_2d_error(s, corr, correction::Mode::kInitPgo, 0);
  const double longer = mean_2d_error(s, corr, correction::Mode::kInitPgo, 30);
  const double ours = mean_2d_error(s, corr, correction::Mode::kOurs, 30);
  const double batch = mean_2d_error(s, corr, correction::Mode::kFullBatch, 30);
  INFO("mean 2D error: INIT+PGO paper window " << paper << " m, >= 30 keyframes " << longer
                                               << " m, Ours " << ours << " m, batch " << batch
                                               << " m");
  CHECK(longer < 0.5 * paper);
  CHECK(ours < 0.5 * paper);
  CHECK(ours < 2.0 * batch);
}
