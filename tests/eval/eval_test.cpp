#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "geodrift/eval/associate.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/eval/scale_factor.hpp"
#include "geodrift/eval/umeyama.hpp"

using namespace geodrift;
using Eigen::Vector3d;

namespace {
std::vector<Vector3d> random_points(std::mt19937& rng, int n, double extent) {
  std::uniform_real_distribution<double> u(-extent, extent);
  std::vector<Vector3d> p(n);
  for (auto& x : p) x = Vector3d(u(rng), u(rng), u(rng));
  return p;
}
}  // namespace

TEST_CASE("Umeyama recovers a known similarity exactly from noise-free points", "[eval]") {
  std::mt19937 rng(42);
  for (int trial = 0; trial < 50; ++trial) {
    const auto src = random_points(rng, 3 + trial, 50.0);
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(0.1 + 0.12 * trial, Vector3d(1, 2, 3 - trial).normalized())
            .toRotationMatrix();
    const double s = 0.01 + 0.7 * trial;
    const Vector3d t(1000.0 - trial, -20.0, 3.0 * trial);
    std::vector<Vector3d> dst;
    for (const auto& p : src) dst.push_back(s * R * p + t);
    const eval::Alignment a = eval::umeyama(src, dst, true);
    INFO("trial " << trial);
    REQUIRE(a.ok());
    CHECK(std::abs(a.s - s) <= 1e-10 * s);
    CHECK((a.R - R).norm() < 1e-10);
    CHECK((a.t - t).norm() < 1e-8 * (1 + t.norm()));
    CHECK(a.rmse < 1e-8);
  }
}

TEST_CASE("Umeyama SE3 keeps scale 1 and recovers a rigid motion, also for planar points",
          "[eval]") {
  std::mt19937 rng(7);
  auto src = random_points(rng, 20, 10.0);
  for (auto& p : src) p.z() = 0.0;  // planar: rank 2 is enough
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.5, Vector3d(0.3, -1, 0.2).normalized()).matrix();
  const Vector3d t(3, 4, 5);
  std::vector<Vector3d> dst;
  for (const auto& p : src) dst.push_back(R * p + t);
  const auto a = eval::umeyama(src, dst, false);
  REQUIRE(a.ok());
  CHECK(a.s == 1.0);
  CHECK((a.R - R).norm() < 1e-10);
  CHECK((a.t - t).norm() < 1e-10);
  CHECK(a.R.determinant() == Approx(1.0));
}

TEST_CASE("Umeyama reports degenerate input instead of returning garbage", "[eval]") {
  std::vector<Vector3d> two{{0, 0, 0}, {1, 0, 0}};
  CHECK(eval::umeyama(two, two).status == eval::AlignmentStatus::kTooFew);
  std::vector<Vector3d> same(5, Vector3d(3, 3, 3));
  CHECK(eval::umeyama(same, same).status == eval::AlignmentStatus::kCoincident);
  std::vector<Vector3d> line, line2;
  for (int i = 0; i < 6; ++i) {
    line.push_back(Vector3d(1, 2, 3) * i + Vector3d(5, 5, 5));
    line2.push_back(Vector3d(0, 1, 0) * i);
  }
  const auto a = eval::umeyama(line, line2);
  CHECK(a.status == eval::AlignmentStatus::kCollinear);
  CHECK_FALSE(a.message.empty());
  CHECK(a.s == 1.0);
  CHECK_THROWS_AS(eval::umeyama(line, two), InvalidArgument);
  // Far from the origin (UTM-sized coordinates) with a real 1 m spread: not degenerate.
  std::vector<Vector3d> far{
      {5e5, 5.4e6, 100}, {5e5 + 1, 5.4e6, 100}, {5e5, 5.4e6 + 1, 100}, {5e5, 5.4e6, 101}};
  std::vector<Vector3d> far_dst;
  for (const auto& p : far) far_dst.push_back(p - Vector3d(5e5, 5.4e6, 0));
  const auto af = eval::umeyama(far, far_dst);
  REQUIRE(af.ok());
  CHECK(af.s == Approx(1.0).epsilon(1e-9));
  line[2].x() = std::nan("");
  CHECK_THROWS_AS(eval::umeyama(line, line2), InvalidArgument);
}

TEST_CASE("Horizontal error statistics of a hand-built case", "[eval]") {
  // Errors 3 (3-4-5 in x,y with z ignored), 0, 4 and a keyframe without ground truth.
  const std::vector<Vector3d> est{{3, 4, 100}, {1, 1, 1}, {0, 4, 0}, {9, 9, 9}};
  const std::vector<Vector3d> gt{
      {0, 0, 0}, {1, 1, -50}, {0, 0, 0}, Vector3d::Constant(std::nan(""))};
  const std::vector<int> frames{10, 20, 30, 40};
  const auto r = eval::horizontal_errors(est, gt, frames, 15);
  CHECK(r.all.count == 3);
  CHECK(r.all.mean == Approx(3.0));
  CHECK(r.all.max == Approx(5.0));
  CHECK(r.all.sd == Approx(std::sqrt((4.0 + 9.0 + 1.0) / 3.0)));
  CHECK(r.all.rmse == Approx(std::sqrt(41.0 / 3.0)));
  CHECK(r.after_last_anchor.count == 2);
  CHECK(r.after_last_anchor.mean == Approx(2.0));
  CHECK(std::isnan(r.per_keyframe[3]));
}

TEST_CASE("Global Sim3 error is zero for a similarity-transformed path and sees bending",
          "[eval]") {
  std::vector<Vector3d> gt, est;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Vector3d::UnitZ()).matrix();
  for (int i = 0; i < 100; ++i) {
    gt.emplace_back(i, 0.01 * i * i, 0.1 * std::sin(0.1 * i));
    est.push_back(0.2 * R * gt.back() + Vector3d(5, 6, 7));
  }
  const auto g = eval::global_sim3_error(est, gt);
  REQUIRE(g.alignment.ok());
  CHECK(g.alignment.s == Approx(5.0));
  CHECK(g.errors.all.mean < 1e-9);
  // Bend the estimate: the error is now positive and the ATE after Sim3 alignment agrees with
  // the alignment's own RMS.
  for (int i = 50; i < 100; ++i) est[i] += Vector3d(0, 0.2 * (i - 50), 0);
  const auto g2 = eval::global_sim3_error(est, gt);
  CHECK(g2.errors.all.mean > 0.5);
  CHECK(eval::ate_rmse(est, gt, eval::AteAlignment::kSim3) == Approx(g2.alignment.rmse));
  CHECK(eval::ate_rmse(gt, gt) == 0.0);
}

TEST_CASE("RPE and KITTI segment error of a uniformly scaled path", "[eval]") {
  // Straight line at 1 m per frame; the estimate travels 1.1 m per frame: every relative
  // translation is 10 % too long, rotations are exact.
  std::vector<Eigen::Isometry3d> gt, est;
  for (int i = 0; i < 400; ++i) {
    Eigen::Isometry3d g = Eigen::Isometry3d::Identity(), e = g;
    g.translation() = Vector3d(0, 0, i);
    e.translation() = Vector3d(0, 0, 1.1 * i);
    gt.push_back(g);
    est.push_back(e);
  }
  const auto rpe = eval::relative_pose_error(est, gt, 10, eval::RpeDelta::kFrames);
  CHECK(rpe.translation.count == 390);
  CHECK(rpe.translation.mean == Approx(1.0));
  CHECK(rpe.rotation.max < 1e-12);
  const auto rpe_m = eval::relative_pose_error(est, gt, 20.0, eval::RpeDelta::kMetres);
  CHECK(rpe_m.translation.mean == Approx(2.0));
  const auto k = eval::kitti_segment_error(est, gt, {100.0}, 10);
  CHECK(k.segments == 30);  // start frames 0..290 have a frame beyond +100 m
  // The devkit's end frame is the first with distance > L, i.e. 101 m: error 10.1 m / 100 m.
  CHECK(k.translation_percent == Approx(10.1));
  CHECK(k.rotation_deg_per_m == Approx(0.0).margin(1e-12));
  CHECK_THROWS_AS(eval::kitti_segment_error(est, gt, {}), InvalidArgument);
}

TEST_CASE("Scale factor along the path and windowed scale statistics", "[eval]") {
  // True path: 1 m per keyframe, keyframes every 3 frames. Estimate: scale 2 in the first half,
  // 3 in the second half (map units per metre).
  std::vector<Vector3d> gt, est;
  std::vector<int> frames;
  double x = 0.0;
  for (int i = 0; i < 100; ++i) {
    gt.emplace_back(i, 0, 0);
    est.emplace_back(x, 0, 0);
    x += (i < 50 ? 2.0 : 3.0);
    frames.push_back(3 * i);
  }
  const auto sf = eval::scale_factor_along_path(est, gt, {10, 1.0});
  REQUIRE(sf.size() == 90);
  CHECK(sf.front().factor == Approx(2.0));
  CHECK(sf.back().factor == Approx(3.0));
  CHECK(sf[45].factor == Approx((5 * 2.0 + 5 * 3.0) / 10.0));

  const auto st = eval::windowed_scale_statistics(est, gt, frames, 30, 5.0);
  // 10 keyframes per window; the last window has 9 steps (9 m >= 5 m) -> 10 windows.
  REQUIRE(st.scales.size() == 10);
  CHECK(st.mean_raw == Approx(2.5));
  CHECK(st.min == Approx(0.8));
  CHECK(st.max == Approx(1.2));
  CHECK(st.sd == Approx(0.2));
  // Steps: 0 except one jump of 0.4 -> SD of {0 x8, 0.4} = 0.4·sqrt(8)/9.
  CHECK(st.step_sd == Approx(0.4 * std::sqrt(8.0) / 9.0));
}

namespace {
/// Ground truth at 100 Hz from t0: n stamps.
std::vector<double> stamps_100hz(double t0, int n) {
  std::vector<double> t(n);
  for (int i = 0; i < n; ++i) t[i] = t0 + 0.01 * i;
  return t;
}
}  // namespace

TEST_CASE("Time association pairs exact and jittered stamps with the nearest ground truth",
          "[eval][associate]") {
  const std::vector<double> gt = stamps_100hz(1000.0, 300);
  SECTION("exact matches, every 3rd ground-truth pose") {
    std::vector<double> res;
    for (int i = 0; i < 300; i += 3) res.push_back(gt[i]);
    const eval::Association a = eval::associate_by_time(res, gt);
    REQUIRE(a.matched() == 100);
    CHECK(a.unmatched() == 0);
    for (std::size_t k = 0; k < a.matched(); ++k) {
      CHECK(a.result_index[k] == k);
      CHECK(a.gt_index[k] == 3 * k);
    }
    CHECK(a.max_abs_time_diff_s() == 0.0);
  }
  SECTION("jitter of up to 4 ms picks the intended pose (seeded)") {
    std::mt19937 rng(42);
    std::uniform_real_distribution<double> jitter(-0.004, 0.004);
    std::vector<double> res;
    std::vector<double> applied;
    for (int i = 0; i < 300; i += 3) {
      applied.push_back(jitter(rng));
      res.push_back(gt[i] + applied.back());
    }
    const eval::Association a = eval::associate_by_time(res, gt);
    REQUIRE(a.matched() == 100);
    for (std::size_t k = 0; k < a.matched(); ++k) {
      INFO("k " << k << " jitter " << applied[k]);
      CHECK(a.gt_index[k] == 3 * k);
      CHECK(a.time_diff_s[k] == Approx(-applied[k]).margin(1e-9));
    }
    CHECK(a.max_abs_time_diff_s() <= 0.004 + 1e-9);
  }
  SECTION("beyond the tolerance is unmatched; a tolerance of 0 keeps only exact stamps") {
    // gt is 100 Hz: stamps 1000.00, 1000.01, ...; a result 25 ms past the last gt pose and one
    // 20 ms before the first are out of reach of 10 ms.
    const std::vector<double> res = {999.98, gt[10], gt[20] + 0.003, gt.back() + 0.025};
    const eval::Association a = eval::associate_by_time(res, gt);
    REQUIRE(a.matched() == 2);
    CHECK(a.result_index == std::vector<std::size_t>{1, 2});
    CHECK(a.gt_index == std::vector<std::size_t>{10, 20});
    CHECK(a.unmatched_result == std::vector<std::size_t>{0, 3});
    CHECK(a.lost_to_closer == 0);
    eval::TimeAssociationOptions exact;
    exact.max_time_diff_s = 0.0;
    const eval::Association b = eval::associate_by_time(res, gt, exact);
    CHECK(b.result_index == std::vector<std::size_t>{1});
    // A wider tolerance reaches the first one (20 ms before gt[0]).
    eval::TimeAssociationOptions wide;
    wide.max_time_diff_s = 0.03;
    CHECK(eval::associate_by_time(res, gt, wide).matched() == 4);
  }
}

TEST_CASE("Time association applies the offset to the result's stamps", "[eval][associate]") {
  const std::vector<double> gt = stamps_100hz(50.0, 200);
  // The result's clock runs 10 s behind, plus 2 ms: without the offset every result stamp lies
  // before the ground truth's first one and nothing is within 10 ms.
  std::vector<double> res;
  for (int i = 0; i < 200; i += 4) res.push_back(gt[i] - 10.002);
  const eval::Association none = eval::associate_by_time(res, gt);
  CHECK(none.matched() == 0);
  CHECK(none.unmatched() == 50);
  eval::TimeAssociationOptions o;
  o.time_offset_s = 10.0;
  const eval::Association a = eval::associate_by_time(res, gt, o);
  REQUIRE(a.matched() == 50);
  for (std::size_t k = 0; k < 50; ++k) {
    CHECK(a.result_index[k] == k);
    CHECK(a.gt_index[k] == 4 * k);
    CHECK(a.time_diff_s[k] == Approx(0.002).margin(1e-9));
  }
}

TEST_CASE("Time association uses each ground-truth pose at most once, keeping the nearest",
          "[eval][associate]") {
  // Ground truth at 10 Hz (0 .. 1.9 s), result at 100 Hz (0.001 .. 1.901 s), tolerance 50 ms:
  // every result pose has a gt pose within reach, about ten share each one, and only the one
  // 1 ms after it keeps it.
  std::vector<double> gt, res;
  for (int j = 0; j < 20; ++j) gt.push_back(0.1 * j);
  for (int i = 0; i <= 190; ++i) res.push_back(0.01 * i + 0.001);
  eval::TimeAssociationOptions o;
  o.max_time_diff_s = 0.05;
  const eval::Association a = eval::associate_by_time(res, gt, o);
  REQUIRE(a.matched() == 20);
  CHECK(a.unmatched() == 171);
  CHECK(a.lost_to_closer == 171);
  for (std::size_t k = 0; k < 20; ++k) {
    CHECK(a.gt_index[k] == k);
    CHECK(a.result_index[k] == 10 * k);
    CHECK(a.time_diff_s[k] == Approx(-0.001).margin(1e-9));
  }
  // The pairs increase in both indices, gt indices are unique.
  for (std::size_t k = 1; k < a.matched(); ++k) {
    CHECK(a.result_index[k] > a.result_index[k - 1]);
    CHECK(a.gt_index[k] > a.gt_index[k - 1]);
  }
  // A tie in distance to the shared gt pose goes to the earlier result pose; an exact midpoint
  // between two gt poses goes to the earlier gt pose.
  // (Dyadic stamps, so the two distances are exactly equal.)
  const eval::Association tie = eval::associate_by_time({0.75, 1.25}, {1.0, 3.0}, {0.5, 0.0});
  CHECK(tie.result_index == std::vector<std::size_t>{0});
  CHECK(tie.lost_to_closer == 1);
  const eval::Association mid = eval::associate_by_time({1.5}, {1.0, 2.0}, {0.5, 0.0});
  CHECK(mid.gt_index == std::vector<std::size_t>{0});
}

TEST_CASE("Time association of empty inputs and invalid input", "[eval][associate]") {
  const std::vector<double> gt = stamps_100hz(0.0, 10);
  CHECK(eval::associate_by_time({}, gt).matched() == 0);
  const eval::Association a = eval::associate_by_time({0.0, 0.05}, {});
  CHECK(a.matched() == 0);
  CHECK(a.unmatched_result == std::vector<std::size_t>{0, 1});
  CHECK(eval::associate_by_time({}, {}).unmatched() == 0);

  const auto throws_with = [](const std::vector<double>& r, const std::vector<double>& g,
                              const eval::TimeAssociationOptions& o, const std::string& what) {
    try {
      eval::associate_by_time(r, g, o);
      FAIL("no exception; expected: " << what);
    } catch (const InvalidArgument& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find(what) != std::string::npos);
    }
  };
  throws_with({0.0, 0.02, 0.01}, gt, {}, "result timestamp 2 (0.01 s) does not increase");
  throws_with({0.0, 0.02}, {0.0, 0.0}, {}, "ground-truth timestamp 1 (0 s) does not increase");
  throws_with({0.0, std::nan("")}, gt, {}, "result timestamp 1 is not finite");
  throws_with({0.0}, {std::nan(""), 1.0}, {}, "ground-truth timestamp 0 is not finite");
  throws_with({0.0}, gt, {-0.001, 0.0}, "max_time_diff_s -0.001");
  throws_with({0.0}, gt, {std::numeric_limits<double>::infinity(), 0.0}, "max_time_diff_s");
  throws_with({0.0}, gt, {0.01, std::nan("")}, "time_offset_s");
}

TEST_CASE("Frame association pairs equal frame numbers", "[eval][associate]") {
  const eval::Association a = eval::associate_by_frame({0, 3, 6, 9, 12}, {0, 1, 2, 3, 4, 5, 6, 7});
  CHECK(a.result_index == std::vector<std::size_t>{0, 1, 2});
  CHECK(a.gt_index == std::vector<std::size_t>{0, 3, 6});
  CHECK(a.unmatched_result == std::vector<std::size_t>{3, 4});
  CHECK(a.max_abs_time_diff_s() == 0.0);
  CHECK_THROWS_AS(eval::associate_by_frame({0, 2, 2}, {0, 1, 2}), InvalidArgument);
  CHECK_THROWS_AS(eval::associate_by_frame({0}, {3, 1}), InvalidArgument);
}
