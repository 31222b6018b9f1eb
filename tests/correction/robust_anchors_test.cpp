// Wrong anchors are found and left out without losing correct ones (issue 24, item 3;
// CorrectorOptions::gate_anchors and correction/screening.hpp, docs/correction_model.md
// "Wrong anchors").
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <tuple>
#include <unordered_map>

#include "geodrift/correction/replay.hpp"
#include "geodrift/correction/screening.hpp"
#include "geodrift/correction/time_offset.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"
#include "support/kitti_sim.hpp"

using namespace geodrift;

namespace {

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
  const sim::SimulatedSequence s = test::simulate_kitti("02", 3, 2500);
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

// ---- screening: every anchor against all the others (correction/screening.hpp) -------------

namespace {

/// Shifts anchors `which` horizontally by d(rng) metres in a random direction.
std::vector<map::Correspondence> shifted(std::vector<map::Correspondence> corr,
                                         const std::vector<int>& which, double lo, double hi,
                                         unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(lo, hi), ang(0, 2 * M_PI);
  for (int j : which) {
    const double r = d(rng), a = ang(rng);
    corr[j].y_w += r * Eigen::Vector3d(std::cos(a), std::sin(a), 0);
  }
  return corr;
}

/// INIT+PGO over the anchors the screening keeps (by geo-tag: screen_anchors_by_geotag).
Run correct_screened(const sim::SimulatedSequence& s, const std::vector<map::Correspondence>& corr,
                     correction::AnchorScreening* screening, bool by_geotag = false) {
  *screening = by_geotag ? correction::screen_anchors_by_geotag(s.map.keyframes, corr)
                         : correction::screen_anchors(s.map.keyframes, corr);
  REQUIRE(screening->ok);
  correction::CorrectorOptions opt;
  opt.mode = correction::Mode::kInitPgo;
  correction::Corrector c(opt);
  correction::apply_screening(*screening, corr, &c);
  correction::replay(s.map, corr, &c);
  REQUIRE(c.initialized());
  std::vector<Eigen::Vector3d> est;
  for (int i = 0; i < c.num_keyframes(); ++i) est.push_back(c.keyframe_center_w(i));
  return {eval::horizontal_errors(est, s.gt_center_w).all.mean, c.anchor_decisions()};
}

/// (left out among `wrong`, left out among the others).
std::pair<int, int> left_out(const correction::AnchorScreening& s, const std::vector<int>& wrong) {
  int w = 0, r = 0;
  for (std::size_t j = 0; j < s.anchors.size(); ++j) {
    const bool is_wrong = std::find(wrong.begin(), wrong.end(), static_cast<int>(j)) != wrong.end();
    (is_wrong ? w : r) += !s.anchors[j].used;
  }
  return {w, r};
}

}  // namespace

TEST_CASE("Screening's cost on a clean run, over seeds", "[correction][robust]") {
  // The simulated drift is heavier-tailed than the drift model in turns: there the screening
  // may leave out a correct anchor or two, and the path near it is worse for the longer gap.
  // Over the whole sequences (docs/RESULTS.md) the cost is within 4 %; this turn-heavy stretch
  // is its worst case measured: 1.11x over 5 seeds (known, documented; the bound guards it).
  double sum_screened = 0, sum_unscreened = 0;
  for (unsigned seed = 1; seed <= 5; ++seed) {
    const sim::SimulatedSequence s = test::simulate_kitti("02", seed, 2500);
    const auto corr = sim::kitti_correspondences(s, 100);
    correction::AnchorScreening sc;
    const Run unscreened = correct(s, corr, /*gate=*/false);
    const Run screened = correct_screened(s, corr, &sc);
    INFO("seed " << seed << ": mean 2D error " << screened.mean_2d << " m (unscreened "
                 << unscreened.mean_2d << " m), drift factor " << sc.drift_factor << ", left out "
                 << sc.num_left_out() << " of " << corr.size());
    CHECK(sc.num_left_out() <= 2);
    sum_screened += screened.mean_2d;
    sum_unscreened += unscreened.mean_2d;
  }
  INFO("mean over 5 seeds: screened " << sum_screened / 5 << " m, unscreened " << sum_unscreened / 5
                                      << " m");
  CHECK(sum_screened <= 1.15 * sum_unscreened);
}

TEST_CASE("Screening leaves out wrong anchors, INIT's among them, and keeps the right ones",
          "[correction][robust]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 3, 2500);
  const auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 20);
  correction::AnchorScreening sc;
  // Wrong anchors are measured against the screened clean run (the screening's own cost on
  // clean anchors is the test case above) and against the right anchors alone.
  const Run clean = correct_screened(s, corr, &sc);
  // What knowing the wrong anchors would give: the correction over the right ones alone.
  auto oracle = [&](const std::vector<int>& wrong) {
    std::vector<map::Correspondence> right;
    for (int j = 0; j < static_cast<int>(corr.size()); ++j)
      if (std::find(wrong.begin(), wrong.end(), j) == wrong.end()) right.push_back(corr[j]);
    return correct(s, right, /*gate=*/false).mean_2d;
  };

  SECTION("10 % by 200-1000 m, one of them among INIT's four") {
    std::vector<int> wrong{1};
    for (int j = 6; j < static_cast<int>(corr.size()); j += 10) wrong.push_back(j);
    const std::vector<map::Correspondence> bad = shifted(corr, wrong, 200, 1000, 7);
    const Run r = correct_screened(s, bad, &sc);
    const auto [w, right] = left_out(sc, wrong);
    INFO("mean 2D error " << r.mean_2d << " m (clean " << clean.mean_2d << " m); left out " << w
                          << " of " << wrong.size() << " wrong, " << right << " correct");
    CHECK(w == static_cast<int>(wrong.size()));
    CHECK(right <= 2);
    CHECK(r.mean_2d <= 1.2 * clean.mean_2d);
    for (int j : wrong) {
      CHECK(!r.decisions[j].used);  // the Corrector honoured it
      // The reason quotes the last solve, without the anchor: its innovation is the shift
      // (within the few metres the path is uncertain there), not the first round's
      // linearised figure with the shifted anchor still bending the path.
      const double shift = (bad[j].y_w - corr[j].y_w).norm();
      const correction::ScreenedAnchor& a = sc.anchors[j];
      INFO("anchor " << j << " shifted by " << shift << " m: " << a.why);
      CHECK(std::abs(a.innovation_m - shift) < 10.0);
      std::ostringstream quoted;
      quoted.precision(3);
      quoted << a.innovation_m << " m from where";
      CHECK(a.why.find(quoted.str()) != std::string::npos);
      CHECK(a.statistic > sc.threshold);
    }
  }
  SECTION("30 % by 20-60 m") {
    std::vector<int> idx;
    for (int j = 4; j < static_cast<int>(corr.size()); ++j) idx.push_back(j);
    std::shuffle(idx.begin(), idx.end(), std::mt19937(11));
    const std::vector<int> wrong(idx.begin(), idx.begin() + (3 * idx.size() + 5) / 10);
    const Run r = correct_screened(s, shifted(corr, wrong, 20, 60, 13), &sc);
    const auto [w, right] = left_out(sc, wrong);
    const double floor = oracle(wrong);
    // Without 30 % of its anchors the path is worse than the clean one however well they are
    // found (the gaps between the rest are longer): the screening's yardstick is the oracle.
    INFO("mean 2D error " << r.mean_2d << " m (clean " << clean.mean_2d
                          << " m, right anchors alone " << floor << " m); left out " << w << " of "
                          << wrong.size() << " wrong, " << right << " correct");
    CHECK(w == static_cast<int>(wrong.size()));
    CHECK(right <= 2);
    CHECK(r.mean_2d <= 1.05 * floor);
  }
}

TEST_CASE("Screening leaves out a run of anchors off together, and nothing on clean runs",
          "[correction][robust]") {
  // GNSS multipath along a street canyon: consecutive fixes off by the same offset vouch for
  // each other, and one by one none stands out (before the run test: none left out, mean 2D
  // error several times the clean run's on our VO; docs/correcting_slam.md).
  const sim::SimulatedSequence s = test::simulate_kitti("02", 3, 2500);
  std::vector<map::Correspondence> corr = sim::kitti_correspondences(s, 20);
  REQUIRE(corr.size() >= 100);
  std::mt19937 rng(17);
  std::normal_distribution<double> noise(0.0, 2.0);
  for (auto& c : corr) {  // fixes with 2 m of noise, as stated
    c.y_w += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    c.sigma_m = 2.0;
  }
  correction::AnchorScreening sc;
  const Run clean = correct_screened(s, corr, &sc);
  int in_runs = 0;
  for (const auto& a : sc.anchors) in_runs += a.run_length > 0;
  INFO("clean: mean 2D error " << clean.mean_2d << " m, left out " << sc.num_left_out());
  CHECK(in_runs == 0);
  CHECK(sc.num_left_out() <= 2);
  const int n = static_cast<int>(corr.size());
  // Mid-path, and at the path's start (a receiver's cold start) and end, where a run has one
  // edge only.
  for (const auto& [first, length, offset] :
       {std::tuple<int, int, Eigen::Vector3d>{40, 8, {25, 15, 0}},
        std::tuple<int, int, Eigen::Vector3d>{60, 15, {-20, 30, 0}},
        std::tuple<int, int, Eigen::Vector3d>{0, 6, {30, -10, 0}},
        std::tuple<int, int, Eigen::Vector3d>{n - 10, 10, {-15, -25, 0}}}) {
    std::vector<map::Correspondence> bad = corr;
    std::vector<int> run;
    for (int j = first; j < first + length; ++j) {
      bad[j].y_w += offset;
      run.push_back(j);
    }
    const Run r = correct_screened(s, bad, &sc);
    const auto [w, right] = left_out(sc, run);
    std::vector<map::Correspondence> rest;
    for (int j = 0; j < static_cast<int>(corr.size()); ++j)
      if (j < first || j >= first + length) rest.push_back(corr[j]);
    const double floor = correct(s, rest, /*gate=*/false).mean_2d;
    INFO("run of " << length << " off by " << offset.norm() << " m: mean 2D error " << r.mean_2d
                   << " m (clean " << clean.mean_2d << " m, without the run " << floor
                   << " m); left out " << w << " of the run, " << right << " others; "
                   << sc.anchors[first].why);
    CHECK(w == length);
    CHECK(right <= 2);
    CHECK(r.mean_2d <= 1.05 * floor);
    CHECK(sc.anchors[first].run_length >= 2);
    CHECK(std::abs(sc.anchors[first].run_offset_m - offset.norm()) < 5.0);
    CHECK(sc.anchors[first].why.find("consecutive anchors off together") != std::string::npos);
  }
}

TEST_CASE("Anchors declared noisier than they are: the drift level settles before any leaves",
          "[correction][robust]") {
  // Exact positions (the simulator's 5 cm) declared with a GNSS-like σ: at the first solve
  // the path follows every anchor to well within σ, the median statistic says k = min_factor,
  // and single anchors used to be left out at that k, round after round, before k was
  // estimated again (σ 1 m: 3 left out and the 60-round cap; through `geodrift correct`, σ
  // 0.5 m: 150 of 233 left out and the run refused).
  const sim::SimulatedSequence s = test::simulate_kitti("02", 1, 2500);
  const std::vector<map::Correspondence> exact = sim::kitti_correspondences(s, 10);
  REQUIRE(exact.size() >= 200);
  for (const double sigma : {0.5, 1.0, 2.0}) {
    std::vector<map::Correspondence> corr = exact;
    for (auto& c : corr) c.sigma_m = sigma;
    const correction::AnchorScreening sc = correction::screen_anchors(s.map.keyframes, corr);
    INFO("sigma " << sigma << " m: " << sc.num_left_out() << " of " << corr.size()
                  << " left out in " << sc.rounds << " rounds, k " << sc.drift_factor << " "
                  << sc.message);
    REQUIRE(sc.ok);
    CHECK(sc.message.empty());      // not stopped by max_rounds
    CHECK(sc.num_left_out() <= 2);  // as on the clean runs above
  }
}

TEST_CASE("Cross-covariances of the screening's tree equal the factor's solves",
          "[correction][robust]") {
  // The run test's pairs of views through the keyframes' chain (Σ_ac = Σ_ab·Σ_bb⁻¹·Σ_bc on a
  // tree) against the Covariance's own solves for off-pattern pairs, on a chain of 60 Sim(3)
  // keyframes with 0 to 3 views each, geo-tagged or not, and a view left without a prior.
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-1, 1);
  const int nk = 60;
  std::vector<lie::Sim3d> S(nk), V;
  std::vector<int> kf_of;
  std::vector<Eigen::Vector3d> tag;
  for (int i = 0; i < nk; ++i) {
    const Eigen::Vector3d c(10.0 * i + 3 * u(rng), 40 * std::sin(0.1 * i), 2 * u(rng));
    const lie::SO3d R = lie::SO3d::exp(Eigen::Vector3d(0.1 * u(rng), 0.3 * u(rng), 0.1 * u(rng)));
    const double s = std::exp(0.2 * u(rng));
    S[i] = lie::Sim3d(R, -s * (R.matrix() * c), s);  // T_cw with centre c
    const int views = i % 4 == 1 ? 0 : 1 + (i % 3 == 0) + (i % 7 == 0);
    for (int v = 0; v < views; ++v) {
      const Eigen::Vector3d cv = c + Eigen::Vector3d(u(rng), u(rng), 0.2 * u(rng));
      const lie::SO3d Rv = lie::SO3d::exp(Eigen::Vector3d(0.1 * u(rng), u(rng), 0.1 * u(rng)));
      V.emplace_back(Rv, -s * (Rv.matrix() * cv), s);
      kf_of.push_back(i);
      tag.push_back(cv + Eigen::Vector3d(u(rng), u(rng), u(rng)));
    }
  }
  solver::Problem problem;
  const solver::RobustLoss trivial;
  auto info = [&](double sd) {
    Eigen::Matrix<double, 7, 7> A;
    for (int r = 0; r < 7; ++r)
      for (int c = 0; c < 7; ++c) A(r, c) = (r == c) + 0.3 * u(rng);
    return Eigen::Matrix<double, 7, 7>(A * A.transpose() / (sd * sd));
  };
  for (int i = 0, j = 0; i < nk; ++i) {
    for (; j < static_cast<int>(V.size()) && kf_of[j] == i; ++j) {
      if (j != 5)  // one view without its geo-tag
        problem.add_residual_block(solver::CameraCentrePriorResidual<lie::Sim3d>{tag[j]}, trivial,
                                   1.0 / 4.0, &V[j]);
      problem.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{V[j] * S[i].inverse()},
                                 trivial, info(0.05), &S[i], &V[j]);
    }
    if (i > 0)
      problem.add_residual_block(
          solver::RelativePoseResidual<lie::Sim3d>{S[i] * S[i - 1].inverse()}, trivial, info(0.02),
          &S[i - 1], &S[i]);
  }
  std::vector<const void*> blocks;
  std::vector<solver::Covariance::Pair> pairs;
  correction::detail::TreeCrossCovariance::request(S, V, kf_of, &blocks, &pairs);
  const int nv = static_cast<int>(V.size());
  for (int a = 0; a < nv; ++a)
    for (int b = a + 1; b < nv; ++b) pairs.emplace_back(&V[a], &V[b]);
  solver::Covariance cov;
  std::string why;
  REQUIRE(cov.compute(problem, blocks, pairs, &why));
  correction::detail::TreeCrossCovariance tree;
  REQUIRE(tree.build(cov, S, V, kf_of, &why));
  double worst = 0, largest = 0;  // |difference|, |correlation| (NaN shows in worst)
  auto keep_worst = [&](double d) { worst = !(d <= worst) ? d : worst; };
  std::vector<correction::detail::TreeCrossCovariance::Mat7> row;
  for (int a = 0; a < nv; ++a) {
    std::vector<int> bs;
    for (int b = a + 1; b < nv; ++b) bs.push_back(b);
    tree.row(a, bs, &row);
    for (int b = 0; b < nv; ++b) {
      if (b == a) continue;
      const Eigen::MatrixXd want = cov.block(&V[a], &V[b]);
      const Eigen::MatrixXd scale =
          (cov.block(&V[a]).diagonal() * cov.block(&V[b]).diagonal().transpose()).cwiseSqrt();
      keep_worst(((tree(a, b) - want).array() / scale.array()).abs().maxCoeff());
      if (b > a) keep_worst(((row[b - a - 1] - want).array() / scale.array()).abs().maxCoeff());
      largest = std::max(largest, (want.array() / scale.array()).abs().maxCoeff());
    }
  }
  INFO(nv << " views on " << nk << " keyframes; largest correlation " << largest
          << ", largest difference " << worst);
  CHECK(nv > 60);
  CHECK(largest > 0.1);  // the views are correlated through the chain
  CHECK(worst < 1e-9);   // relative to the SDs: a correlation's difference
}

TEST_CASE("Screening does not depend on the map's unit, origin or orientation",
          "[correction][robust]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 2, 1500);
  auto corr = sim::kitti_correspondences(s, 100);
  corr = shifted(corr, {5, 9}, 50, 100, 3);
  const auto a = correction::screen_anchors(s.map.keyframes, corr);
  REQUIRE(a.ok);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (double scale : {1e-3, 1e3}) {
    // p_M' = scale·R·p_M + t: T_cw' = T_cw·T⁻¹ with translations scaled; T_vk scaled alike.
    const Eigen::Vector3d w(u(rng), u(rng), u(rng)), t(100 * u(rng), 100 * u(rng), 100 * u(rng));
    const lie::SE3d G(lie::SO3d::exp(w), t);  // M -> M' before scaling
    std::vector<map::Keyframe> kfs = s.map.keyframes;
    for (auto& k : kfs) {
      lie::SE3d T = k.T_cw * G.inverse();
      k.T_cw = lie::SE3d(T.rotation(), scale * T.translation());
    }
    auto corr2 = corr;
    for (auto& c : corr2) {
      c.T_vk = lie::SE3d(c.T_vk.rotation(), scale * c.T_vk.translation());
      // The PnP covariance (ω, ν) in M units: ν rows and columns scale with the map.
      c.pose_cov.block<3, 3>(0, 3) *= scale;
      c.pose_cov.block<3, 3>(3, 0) *= scale;
      c.pose_cov.block<3, 3>(3, 3) *= scale * scale;
    }
    const auto b = correction::screen_anchors(kfs, corr2);
    REQUIRE(b.ok);
    CHECK(b.drift_factor == Approx(a.drift_factor).epsilon(1e-6));
    for (std::size_t j = 0; j < corr.size(); ++j) {
      INFO("scale " << scale << ", anchor " << j);
      CHECK(b.anchors[j].used == a.anchors[j].used);
      CHECK(b.anchors[j].statistic == Approx(a.anchors[j].statistic).epsilon(1e-6).margin(1e-9));
    }
  }
}

TEST_CASE("Screening reports what it cannot test and rejects what it cannot read",
          "[correction][robust]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 1, 600);
  auto corr = sim::kitti_correspondences(s, 100);
  REQUIRE(corr.size() >= 3);
  corr.resize(2);
  const auto r = correction::screen_anchors(s.map.keyframes, corr);
  CHECK(!r.ok);
  CHECK(r.message.find("fewer than 3") != std::string::npos);
  CHECK(r.num_left_out() == 0);
  corr[1].keyframe = 1 << 30;
  CHECK_THROWS_WITH(correction::screen_anchors(s.map.keyframes, corr),
                    Catch::Contains("unknown keyframe"));
  corr[1].keyframe = corr[0].keyframe;
  corr[1].y_w.x() = std::nan("");
  CHECK_THROWS_WITH(correction::screen_anchors(s.map.keyframes, corr),
                    Catch::Contains("not finite"));
  corr[1].y_w.x() = 0.0;
  auto kfs = s.map.keyframes;
  kfs[7].T_cw = lie::SE3d(kfs[7].T_cw.rotation(), Eigen::Vector3d(1e300, 0, 0));
  CHECK_THROWS_WITH(correction::screen_anchors(kfs, corr),
                    Catch::Contains("keyframe " + std::to_string(kfs[7].id) + " translation") &&
                        Catch::Contains("exceeds 1e+12"));
}

// ---- geo-tags localized from several keyframes (`geodrift run`) ----------------------------

namespace {

/// Every geo-tag of `corr` localized from its keyframe and the keyframes `offsets` away, as
/// `geodrift run` localizes a panorama from each keyframe that retrieves it: the same view
/// pose in M, the same geo-tag position and id. Ids are renumbered in order.
std::vector<map::Correspondence> with_siblings(const sim::SimulatedSequence& s,
                                               const std::vector<map::Correspondence>& corr,
                                               std::vector<int>* tag_of) {
  const auto& kfs = s.map.keyframes;
  std::unordered_map<int, int> kf_pos;
  for (std::size_t i = 0; i < kfs.size(); ++i) kf_pos[kfs[i].id] = static_cast<int>(i);
  std::vector<map::Correspondence> out;
  tag_of->clear();
  for (std::size_t t = 0; t < corr.size(); ++t) {
    const map::Correspondence& c = corr[t];
    const int i = kf_pos.at(c.keyframe);
    const lie::SE3d T_vm = c.T_vk * kfs[i].T_cw;
    for (int d : {-3, 0, 3}) {
      const int k = i + d;
      if (k < 0 || k >= static_cast<int>(kfs.size())) continue;
      map::Correspondence x = c;
      x.id = static_cast<int>(out.size());
      x.keyframe = kfs[k].id;
      x.T_vk = T_vm * kfs[k].T_cw.inverse();
      x.inliers = c.inliers - std::abs(d);  // the anchor's own keyframe sees it best
      out.push_back(x);
      tag_of->push_back(static_cast<int>(t));
    }
  }
  return out;
}

}  // namespace

TEST_CASE("Geo-tags seen from several keyframes: a wrong one leaves with all its localizations",
          "[correction][robust]") {
  const sim::SimulatedSequence s = test::simulate_kitti("02", 3, 2500);
  const auto tags = sim::kitti_correspondences(s, 100);
  REQUIRE(tags.size() >= 20);
  // 10 % of the geo-tags off by 50-200 m (one of them among the first four), in every
  // localization of them.
  std::vector<int> wrong_tags{2};
  for (int t = 7; t < static_cast<int>(tags.size()); t += 10) wrong_tags.push_back(t);
  std::vector<int> tag_of;
  const auto clean = with_siblings(s, tags, &tag_of);
  const auto bad = with_siblings(s, shifted(tags, wrong_tags, 50, 200, 17), &tag_of);
  REQUIRE(clean.size() == bad.size());
  // And one localization of a correct geo-tag made against the wrong keyframe, 40 keyframes
  // on (a view matched to another place): its view lands tens of metres off.
  int misplaced = -1;
  for (std::size_t j = 0; j < bad.size() && misplaced < 0; ++j)
    if (tag_of[j] == 12 && bad[j].keyframe != tags[12].keyframe) misplaced = static_cast<int>(j);
  REQUIRE(misplaced >= 0);
  auto bad2 = bad;
  for (std::size_t i = 0; i + 40 < s.map.keyframes.size(); ++i)
    if (s.map.keyframes[i].id == bad2[misplaced].keyframe) {
      bad2[misplaced].keyframe = s.map.keyframes[i + 40].id;
      break;
    }
  REQUIRE(bad2[misplaced].keyframe != bad[misplaced].keyframe);

  auto is_wrong = [&](int j) {
    return std::find(wrong_tags.begin(), wrong_tags.end(), tag_of[j]) != wrong_tags.end();
  };
  auto count = [&](const correction::AnchorScreening& sc, int* w, int* r) {
    *w = *r = 0;
    for (std::size_t j = 0; j < sc.anchors.size(); ++j)
      if (static_cast<int>(j) != misplaced)
        (is_wrong(static_cast<int>(j)) ? *w : *r) += !sc.anchors[j].used;
  };
  int num_wrong = 0;
  for (std::size_t j = 0; j < bad.size(); ++j) num_wrong += is_wrong(static_cast<int>(j));

  // Screened one by one, a wrong geo-tag's localizations vouch for each other.
  const auto naive = correction::screen_anchors(s.map.keyframes, bad2);
  REQUIRE(naive.ok);
  int naive_w = 0, naive_r = 0;
  count(naive, &naive_w, &naive_r);
  // By geo-tag, all of them go; so does the misplaced localization, and its geo-tag stays.
  correction::AnchorScreening sc_clean, sc;
  const double e_clean = correct_screened(s, clean, &sc_clean, /*by_geotag=*/true).mean_2d;
  const double e_bad = correct_screened(s, bad2, &sc, /*by_geotag=*/true).mean_2d;
  // The floor of any screening: the correct geo-tags alone.
  std::vector<map::Correspondence> correct_only;
  for (std::size_t j = 0; j < clean.size(); ++j)
    if (!is_wrong(static_cast<int>(j))) correct_only.push_back(clean[j]);
  correction::AnchorScreening sc_floor;
  const double e_floor = correct_screened(s, correct_only, &sc_floor, /*by_geotag=*/true).mean_2d;
  int w = 0, r = 0;
  count(sc, &w, &r);
  int siblings_kept = 0, siblings = 0;
  for (std::size_t j = 0; j < bad2.size(); ++j)
    if (tag_of[j] == 12 && static_cast<int>(j) != misplaced) {
      ++siblings;
      siblings_kept += sc.anchors[j].used;
    }
  INFO("one by one: left out " << naive_w << " of " << num_wrong << " wrong localizations, "
                               << naive_r << " correct; by geo-tag: " << w << " wrong, " << r
                               << " correct, misplaced one used " << sc.anchors[misplaced].used
                               << "; mean 2D error " << e_bad << " m (clean, by geo-tag: "
                               << e_clean << " m, " << sc_clean.num_left_out()
                               << " left out; the correct geo-tags alone: " << e_floor << " m)");
  // The test has teeth: one by one, a wrong geo-tag's localizations agree with each other and
  // vouch for each other, and the screening pays for them in correct ones. Since the drift
  // level settles before single anchors leave at it (2026-12-07, evening) it finds all 9 wrong
  // localizations one by one, but loses 18 correct ones against the test by geo-tag's 6 (with
  // the bracket alone it found 2 of 9 and lost 5; before it, k cycled and it lost over 3x).
  CHECK(naive_r > 2 * r);
  CHECK(w == num_wrong);
  CHECK(r <= 6);  // two geo-tags' worth
  CHECK(!sc.anchors[misplaced].used);
  CHECK(siblings_kept == siblings);
  CHECK(sc_clean.num_left_out() <= 6);
  // Against the floor of any screening (the correct geo-tags alone), not the clean run: the
  // clean run also has the 10 % of geo-tags that are wrong here, and no screening gets their
  // information back. With windows adapted to their anchors (2026-12-07, night) every run here
  // gained 0.7-0.8 m (clean 2.22 -> 1.50 m, bad 2.63 -> 1.82 m) and the ratio to the clean run
  // went from 1.18x to 1.21x; to the floor (1.73 m) it is 1.05x.
  CHECK(e_bad <= 1.05 * e_floor);
  for (std::size_t j = 0; j < bad2.size(); ++j)
    if (is_wrong(static_cast<int>(j))) {
      INFO("localization " << j << ": " << sc.anchors[j].why);
      CHECK(sc.anchors[j].why.find("geo-tag") != std::string::npos);
    }
}

namespace {

/// KITTI 02 (4661 poses, 483 s, shipped in data/kitti) as a drifting monocular VO would see it:
/// the ground-truth steps turned by a heading random walk (5e-5 rad per step) and scaled by a
/// log-scale random walk (5e-4 per step), in map units of `unit` per metre; and anchors every
/// 50 frames at the ground-truth centre `offset` seconds after the frame's time (so the
/// trajectory's time = anchor time + offset), 0.3 m noise per axis; a fraction `wrong` of them
/// shifted 20–60 m in a random horizontal direction (wrong geo-tags).
struct ClockScene {
  std::vector<double> times, anchor_times;
  std::vector<Eigen::Vector3d> vo, anchors;
};
ClockScene clock_scene(double offset, double unit, unsigned seed, double wrong = 0.0) {
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const io::Trajectory gt = io::read_trajectory(dir + "/poses/02.txt");
  std::ifstream tf(dir + "/times/02.txt");
  ClockScene sc;
  std::vector<Eigen::Vector3d> c;
  for (const io::TrajectoryPose& p : gt.poses) {
    double t;
    REQUIRE(static_cast<bool>(tf >> t));
    sc.times.push_back(t);
    c.push_back(p.T_cw.inverse().translation());
  }
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  double yaw = 0.0, log_scale = 0.0;
  sc.vo.push_back(Eigen::Vector3d::Zero());
  for (std::size_t k = 1; k < c.size(); ++k) {
    yaw += 5e-5 * n01(rng);
    log_scale += 5e-4 * n01(rng);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
    sc.vo.push_back(sc.vo.back() + unit * std::exp(log_scale) * (R * (c[k] - c[k - 1])));
  }
  for (std::size_t k = 50; k + 50 < c.size(); k += 50) {
    sc.anchor_times.push_back(sc.times[k]);
    const Eigen::Vector3d noise(n01(rng), n01(rng), n01(rng));
    sc.anchors.push_back(correction::detail::centre_at(sc.times, c, sc.times[k] + offset) +
                         0.3 * noise);
    if (std::uniform_real_distribution<double>(0.0, 1.0)(rng) < wrong) {
      const double a = std::uniform_real_distribution<double>(0.0, 2 * M_PI)(rng);
      const double d = std::uniform_real_distribution<double>(20.0, 60.0)(rng);
      sc.anchors.back() += d * Eigen::Vector3d(std::cos(a), 0.0, std::sin(a));  // KITTI: y down
    }
  }
  return sc;
}

correction::TimeOffsetEstimate estimate(const ClockScene& sc, double max_offset = 0.0) {
  return correction::estimate_anchor_time_offset(sc.times, sc.vo, sc.anchor_times, sc.anchors,
                                                 max_offset);
}

}  // namespace

TEST_CASE("The anchors' clock offset is found from the path's turns, in any map unit",
          "[correction][time_offset]") {
  for (const double offset : {0.7, -0.3, -18.0}) {  // a logging latency; GPS time against UTC
    const ClockScene sc = clock_scene(offset, 1.0, 3);
    const correction::TimeOffsetEstimate e = estimate(sc);
    INFO("true " << offset << " s: estimate " << e.offset << " ± " << e.sd << " s, statistic "
                 << e.statistic << ", windowed RMS " << e.rms_at_zero << " -> " << e.rms_at_estimate
                 << " m over " << e.windows << " windows");
    REQUIRE(e.estimated);
    CHECK(e.searched == Approx(20.0));
    CHECK(std::abs(e.offset - offset) < 0.05);
    CHECK(std::abs(e.offset - offset) < 4.0 * e.sd);
    CHECK(e.sd < 0.05);
    CHECK(e.significant);
    CHECK_FALSE(e.at_edge);
    CHECK(e.rms_at_estimate < 0.5 * e.rms_at_zero);
    // The map's unit does not matter: one similarity per window.
    const correction::TimeOffsetEstimate m = estimate(clock_scene(offset, 1e-3, 3));
    CHECK(std::abs(m.offset - e.offset) < 1e-6);
    CHECK(m.statistic == Approx(e.statistic).epsilon(1e-6));
  }
}

TEST_CASE("The clock offset is found among wrong geo-tags, and none is made up by them",
          "[correction][time_offset]") {
  // 20 % of the anchors 20–60 m off: each window is fitted without its worst anchor, and a
  // window with two or more wrong ones is left out.
  for (unsigned seed : {3u, 4u, 5u}) {
    const correction::TimeOffsetEstimate e = estimate(clock_scene(0.7, 1.0, seed, 0.2));
    const correction::TimeOffsetEstimate z = estimate(clock_scene(0.0, 1.0, seed, 0.2));
    INFO("seed " << seed << ": 0.7 s estimated " << e.offset << " ± " << e.sd << " s, "
                 << e.windows_left_out << " windows left out; none: " << z.offset << " ± " << z.sd
                 << " s, statistic " << z.statistic);
    REQUIRE(e.estimated);
    CHECK(e.windows_left_out > 0);
    CHECK(std::abs(e.offset - 0.7) < 0.05);
    CHECK(e.significant);
    REQUIRE(z.estimated);
    CHECK_FALSE(z.significant);
  }
}

TEST_CASE("No clock offset is reported where there is none or where it cannot be seen",
          "[correction][time_offset]") {
  for (unsigned seed : {3u, 4u, 5u}) {  // the same clock: estimate near 0, not significant
    const correction::TimeOffsetEstimate e = estimate(clock_scene(0.0, 1.0, seed));
    INFO("seed " << seed << ": estimate " << e.offset << " ± " << e.sd << " s, statistic "
                 << e.statistic);
    REQUIRE(e.estimated);
    CHECK(std::abs(e.offset) < 0.05);
    CHECK_FALSE(e.significant);
  }
  // Just outside the searched ±T: the best offset sits at the edge and says so.
  const correction::TimeOffsetEstimate edge = estimate(clock_scene(0.7, 1.0, 3), 0.5);
  REQUIRE(edge.estimated);
  CHECK(edge.offset == Approx(0.5).margin(0.01));
  CHECK(edge.at_edge);
  CHECK_FALSE(estimate(clock_scene(0.7, 1.0, 3), 1.0).at_edge);
  // A straight road at constant speed: an offset is a shift along it, not observable.
  ClockScene line;
  for (int k = 0; k < 600; ++k) {
    line.times.push_back(0.1 * k);
    line.vo.push_back(Eigen::Vector3d(0.0, 0.0, 0.5 * k));
  }
  for (int k = 50; k < 550; k += 25) {
    line.anchor_times.push_back(0.1 * k);
    line.anchors.push_back(Eigen::Vector3d(10.0 * (0.1 * k + 0.7), 0.0, 0.0));
  }
  const correction::TimeOffsetEstimate s = estimate(line);
  CHECK_FALSE(s.estimated);
  CHECK(s.reason.find("straight") != std::string::npos);
  // Too few anchors: 9, two windows of 5 are needed.
  ClockScene few = clock_scene(0.7, 1.0, 3);
  few.anchor_times.resize(9);
  few.anchors.resize(9);
  const correction::TimeOffsetEstimate f = estimate(few);
  CHECK_FALSE(f.estimated);
  CHECK(f.reason.find("10 are needed") != std::string::npos);
  // Timestamps that do not increase, non-finite input.
  ClockScene back = clock_scene(0.7, 1.0, 3);
  back.times[100] = back.times[98];
  CHECK_FALSE(estimate(back).estimated);
  CHECK(estimate(back).reason.find("do not increase") != std::string::npos);
  back = clock_scene(0.7, 1.0, 3);
  back.anchors[2].x() = std::nan("");
  CHECK_THROWS_WITH(estimate(back), Catch::Contains("anchor 2 is not finite"));
}
