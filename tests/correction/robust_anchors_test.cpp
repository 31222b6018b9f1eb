// Wrong anchors are found and left out without losing correct ones (issue 24, item 3;
// CorrectorOptions::gate_anchors, docs/correction_model.md "Wrong anchors").
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <string>

#include "geodrift/correction/replay.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

using namespace geodrift;

namespace {

sim::SimulatedSequence simulate_02(unsigned seed, int last_frame) {
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const sim::KittiSequence seq = sim::load_kitti_sequence(
      dir + "/poses/02.txt", dir + "/calib_seq00-02.txt", dir + "/times/02.txt");
  sim::SimOptions so = sim::SimOptions::kitti("02", seed);
  so.last_frame = last_frame;
  return sim::simulate(seq, so);
}

struct Run {
  double mean_2d = 0;
  std::vector<correction::AnchorDecision> decisions;
};

Run correct(const sim::SimulatedSequence& s, const std::vector<map::Correspondence>& corr,
            bool gate = true) {
  correction::CorrectorOptions opt;
  opt.mode = correction::Mode::kInitPgo;
  opt.gate_anchors = gate;
  correction::Corrector c(opt);
  correction::replay(s.map, corr, &c);
  REQUIRE(c.initialized());
  std::vector<Eigen::Vector3d> est;
  for (int i = 0; i < c.num_keyframes(); ++i) est.push_back(c.keyframe_center_w(i));
  return {eval::horizontal_errors(est, s.gt_center_w).all.mean, c.anchor_decisions()};
}

}  // namespace

TEST_CASE("Anchors hundreds of metres off are rejected and the path stays near the clean one",
          "[correction][robust]") {
  const sim::SimulatedSequence s = simulate_02(3, 2500);
  const auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 20);
  // Every 10th anchor after INIT's four: 10 % wrong, by 200-1000 m (a retrieval mistake).
  std::vector<int> wrong;
  for (int j = 6; j < static_cast<int>(corr.size()); j += 10) wrong.push_back(j);
  std::vector<map::Correspondence> bad = corr;
  {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> d(200, 1000), ang(0, 2 * M_PI);
    for (int j : wrong) {
      const double r = d(rng), a = ang(rng);
      bad[j].y_w += r * Eigen::Vector3d(std::cos(a), std::sin(a), 0);
    }
  }
  const Run clean = correct(s, corr);
  const Run gated = correct(s, bad);
  const Run blind = correct(s, bad, /*gate=*/false);
  int rejected_wrong = 0, rejected_right = 0;
  for (std::size_t j = 0; j < gated.decisions.size(); ++j) {
    const bool is_wrong = std::find(wrong.begin(), wrong.end(), static_cast<int>(j)) != wrong.end();
    (is_wrong ? rejected_wrong : rejected_right) += !gated.decisions[j].used;
  }
  INFO("mean 2D error: clean " << clean.mean_2d << " m, 10 % wrong with the gate " << gated.mean_2d
                               << " m, without it " << blind.mean_2d << " m; rejected "
                               << rejected_wrong << " of " << wrong.size() << " wrong, "
                               << rejected_right << " correct");
  CHECK(rejected_wrong == static_cast<int>(wrong.size()));
  CHECK(rejected_right <= 2);
  CHECK(gated.mean_2d <= 1.2 * clean.mean_2d);
  CHECK(!(blind.mean_2d < 10 * clean.mean_2d));  // the test has teeth: unguarded, they ruin it
}
