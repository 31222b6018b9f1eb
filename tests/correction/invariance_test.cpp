// The corrected path does not depend on the map's unit, origin or orientation (issue 24, item 1;
// DESIGN.md "Correction" 5): a monocular map's unit is arbitrary, so the same reconstruction
// handed over in another similarity frame must give the same path in W.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <string>

#include "geodrift/correction/replay.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

using namespace geodrift;

namespace {

/// The same reconstruction in the map frame M' = G·M (G: M → M', a similarity of scale k):
/// points X' = G·X; keyframe poses T'_cw = k·T_cw·G⁻¹ (rigid: the camera frame in the new unit);
/// a view's offset to its keyframe T'_vk = k·T_vk·k⁻¹ (translation × k) and its pose covariance
/// in the new unit (ν rows and columns × k).
map::Map transform_map(const map::Map& m, const lie::Sim3d& G) {
  map::Map out = m;
  const double k = G.scale();
  const lie::Sim3d K(lie::SO3d(), Eigen::Vector3d::Zero(), k);
  for (auto& kf : out.keyframes) kf.T_cw = (K * lie::Sim3d(kf.T_cw) * G.inverse()).to_se3();
  for (auto& p : out.points) p.position = G.act(p.position);
  return out;
}

std::vector<map::Correspondence> transform_corr(std::vector<map::Correspondence> corr, double k) {
  for (auto& c : corr) {
    c.T_vk = lie::SE3d(c.T_vk.rotation(), k * c.T_vk.translation());
    c.pose_cov.block<3, 6>(3, 0) *= k;
    c.pose_cov.block<6, 3>(0, 3) *= k;
  }
  return corr;
}

/// Keyframe centres in W after correcting `m` in `mode` (without points: trajectory-only).
std::vector<Eigen::Vector3d> correct(const map::Map& m, const std::vector<map::Correspondence>& c,
                                     correction::Mode mode, bool with_map) {
  correction::CorrectorOptions opt;
  opt.mode = mode;
  opt.edge_weights = correction::CorrectorOptions::EdgeWeights::kDriftModel;
  correction::Corrector corrector(opt);
  if (with_map) {
    correction::replay(m, c, &corrector);
  } else {
    map::Map traj = m;
    traj.points.clear();
    traj.observations.clear();
    correction::replay(traj, c, &corrector);
  }
  REQUIRE(corrector.initialized());
  std::vector<Eigen::Vector3d> out;
  for (int i = 0; i < corrector.num_keyframes(); ++i) out.push_back(corrector.keyframe_center_w(i));
  return out;
}

}  // namespace

TEST_CASE(
    "With drift-model weights the corrected path is the same whatever the map's unit, "
    "origin and orientation",
    "[correction][invariance]") {
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const sim::KittiSequence seq = sim::load_kitti_sequence(
      dir + "/poses/02.txt", dir + "/calib_seq00-02.txt", dir + "/times/02.txt");
  sim::SimOptions so = sim::SimOptions::kitti("02", 5);
  so.last_frame = 1000;
  const sim::SimulatedSequence s = sim::simulate(seq, so);
  const auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 10);

  std::mt19937 rng(24);
  std::uniform_real_distribution<double> u(-1, 1);
  // Map units per former map unit: both ends of the range and two random ones.
  std::vector<double> scales = {1e-3, 1e3, std::pow(10.0, 3 * u(rng)), std::pow(10.0, 3 * u(rng))};
  const auto modes = {correction::Mode::kInitOnly, correction::Mode::kInitPgo,
                      correction::Mode::kInitBa, correction::Mode::kOurs,
                      correction::Mode::kFullBatch};
  for (const bool with_map : {true, false}) {
    for (const auto mode : modes) {
      if (!with_map && mode == correction::Mode::kInitBa) continue;  // BA needs points
      const auto ref = correct(s.map, corr, mode, with_map);
      double extent = 0;
      for (const auto& c : ref) extent = std::max(extent, (c - ref.front()).norm());
      for (const double k : scales) {
        const lie::Sim3d G(lie::SO3d::exp(M_PI * Eigen::Vector3d(u(rng), u(rng), u(rng))),
                           1e3 * k * Eigen::Vector3d(u(rng), u(rng), u(rng)), k);
        const auto out = correct(transform_map(s.map, G), transform_corr(corr, k), mode, with_map);
        REQUIRE(out.size() == ref.size());
        double worst = 0;
        for (std::size_t i = 0; i < ref.size(); ++i)
          worst = std::max(worst, (out[i] - ref[i]).norm());
        INFO("mode " << correction::to_string(mode) << (with_map ? " with map" : " trajectory-only")
                     << ", map scale x" << k << ": largest keyframe difference " << worst
                     << " m over a path of " << extent << " m");
        CHECK(worst <= 1e-6 * extent);
      }
    }
  }
}
