#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "geodrift/correction/pose_refinement.hpp"
#include "geodrift/eval/errors.hpp"
#include "geodrift/geo/kitti.hpp"
#include "geodrift/map/map.hpp"
#include "geodrift/sim/drift_simulator.hpp"
#include "geodrift/sim/kitti_protocol.hpp"
#include "support/test_files.hpp"

using namespace geodrift;

namespace {

const sim::KittiSequence& kitti(const std::string& seq) {
  static const sim::KittiSequence s02 = sim::load_kitti_sequence_from_dir(
      std::string(GEODRIFT_DATA_DIR) + "/kitti_odometry_gt", "02");
  static const sim::KittiSequence s08 = sim::load_kitti_sequence_from_dir(
      std::string(GEODRIFT_DATA_DIR) + "/kitti_odometry_gt", "08");
  return seq == "02" ? s02 : s08;
}

/// Reprojection residuals (pixels, per axis) of every observation in the drifted map.
std::vector<double> reprojection_residuals(const map::Map& m) {
  std::vector<double> r;
  r.reserve(2 * m.observations.size());
  for (const auto& o : m.observations) {
    const auto& kf = m.keyframes[o.keyframe];  // ids are indices in the simulator's output
    const Eigen::Vector3d p = kf.T_cw.act(m.points[o.point].position);
    const Eigen::Vector2d d = m.cameras[0].project(p) - o.pixel;
    r.push_back(d.x());
    r.push_back(d.y());
  }
  return r;
}

double rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / static_cast<double>(v.size()));
}

/// ½ Σ |π(T·X_i) − u_i|².
double reprojection_cost(const lie::SE3d& T, const std::vector<Eigen::Vector3d>& X,
                         const std::vector<Eigen::Vector2d>& u, const map::Camera& cam) {
  double c = 0.0;
  for (std::size_t i = 0; i < X.size(); ++i)
    c += 0.5 * (cam.project(T.act(X[i])) - u[i]).squaredNorm();
  return c;
}

}  // namespace

TEST_CASE("PnP refinement on the core solver recovers the pose and minimises the pixel error",
          "[sim]") {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  std::normal_distribution<double> n01(0.0, 1.0);
  map::Camera cam;
  cam.fx = cam.fy = 718.856;
  cam.cx = 607.1928;
  cam.cy = 185.2157;
  const lie::SE3d T_true =
      lie::SE3d::exp((lie::SE3d::Tangent() << 0.1, -0.3, 0.05, 2.0, -0.5, 10.0).finished());
  std::vector<Eigen::Vector3d> X;
  std::vector<Eigen::Vector2d> u, u_noisy;
  for (int i = 0; i < 80; ++i) {
    const Eigen::Vector3d p(12.0 * uni(rng), 4.0 * uni(rng), 17.5 + 12.5 * uni(rng));
    X.push_back(T_true.inverse().act(p));
    u.push_back(cam.project(p));
    u_noisy.push_back(u.back() + Eigen::Vector2d(n01(rng), n01(rng)));
  }
  const lie::SE3d T_init =
      lie::SE3d::exp((lie::SE3d::Tangent() << 0.03, -0.02, 0.04, 0.3, 0.2, -0.4).finished()) *
      T_true;

  // Exact pixels: the true pose, to machine precision.
  const correction::PnpResult exact = correction::refine_pose_lm(X, u, cam, T_init, 50);
  CHECK(exact.converged);
  CHECK(exact.iterations >= 2);
  CHECK((exact.T_cw * T_true.inverse()).log().norm() < 1e-9);
  CHECK(exact.rms_px < 1e-7);

  // 1 px noise: a minimum of the cost (no small left perturbation lowers it) with the RMS of
  // 2-D noise of 1 px per axis (√2 · √((2n − 6) / 2n) ≈ 1.4 px).
  const correction::PnpResult noisy = correction::refine_pose_lm(X, u_noisy, cam, T_init, 50);
  CHECK(noisy.converged);
  const double c0 = reprojection_cost(noisy.T_cw, X, u_noisy, cam);
  CHECK(noisy.rms_px == Approx(std::sqrt(2.0 * c0 / X.size())).epsilon(1e-9));
  CHECK(noisy.rms_px > 1.1);
  CHECK(noisy.rms_px < 1.7);
  for (int j = 0; j < 6; ++j)
    for (double e : {-1e-4, 1e-4}) {
      const lie::SE3d Tp = lie::SE3d::exp(e * lie::SE3d::Tangent::Unit(j)) * noisy.T_cw;
      CHECK(reprojection_cost(Tp, X, u_noisy, cam) > c0);
    }
  CHECK((noisy.T_cw * T_true.inverse()).log().norm() < 0.05);

  // A point behind the camera at the start: nothing solved.
  std::vector<Eigen::Vector3d> Xb = X;
  Xb[7] = T_init.inverse().act(Eigen::Vector3d(0.0, 0.0, -5.0));
  const correction::PnpResult behind = correction::refine_pose_lm(Xb, u, cam, T_init, 50);
  CHECK_FALSE(behind.converged);
  CHECK(behind.T_cw.is_approx(T_init, 0.0));
  CHECK(std::isnan(behind.rms_px));
  CHECK_THROWS_AS(correction::refine_pose_lm(X, std::vector<Eigen::Vector2d>(3), cam, T_init),
                  InvalidArgument);

  // 10 of 80 matches 40 px off (wrong matches): the Huber loss keeps the pose near the truth,
  // plain least squares is pulled away; rms_px is the raw residual RMS either way.
  std::vector<Eigen::Vector2d> u_bad = u_noisy;
  for (int i = 0; i < 10; ++i) u_bad[7 * i] += Eigen::Vector2d(40.0, -40.0 * (i % 2));
  const correction::PnpResult plain = correction::refine_pose_lm(X, u_bad, cam, T_init, 50);
  const correction::PnpResult huber = correction::refine_pose_lm(X, u_bad, cam, T_init, 50, 2.0);
  const double e_plain = (plain.T_cw * T_true.inverse()).log().norm();
  const double e_huber = (huber.T_cw * T_true.inverse()).log().norm();
  INFO("pose error plain " << e_plain << ", Huber " << e_huber);
  CHECK(huber.converged);
  CHECK(e_huber < 0.5 * e_plain);
  CHECK(e_huber < 0.05);
  CHECK(huber.rms_px ==
        Approx(std::sqrt(2.0 * reprojection_cost(huber.T_cw, X, u_bad, cam) / X.size()))
            .epsilon(1e-12));
  CHECK_THROWS_AS(correction::refine_pose_lm(X, u, cam, T_init, 50, -1.0), InvalidArgument);
}

TEST_CASE("KITTI loader: io's pose reader, times file or nominal 10 Hz, P0/P1 calibration",
          "[sim]") {
  const test::TempDir dir;
  const auto write = [&](const std::string& name, const std::string& text) {
    const std::string f = dir.file(name);
    test::write_text(f, text);
    return f;
  };
  const std::string calib =
      write("calib.txt",
            "P0: 700 0 600 0 0 710 180 0 0 0 1 0\nP1: 700 0 600 -378 0 710 180 0 0 0 1 0\n"
            "P2: 1 2 3\n");
  // cam0 -> world: identity, then 1 m forward, then turned 90 degrees about y.
  const std::string poses12 =
      write("poses.txt",
            "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n\n0 0 1 0.5 0 1 0 0 -1 0 0 2\n");
  const std::string times = write("times.txt", "0.0\n0.1036\n0.2074\n");
  const sim::KittiSequence s = sim::load_kitti_sequence(poses12, calib, times, "xx");
  REQUIRE(s.num_frames() == 3);
  CHECK(s.name == "xx");
  CHECK(s.timestamps == std::vector<double>{0.0, 0.1036, 0.2074});
  CHECK((s.T_K_c[1].translation() - Eigen::Vector3d(0, 0, 1)).norm() < 1e-12);
  CHECK((s.T_K_c[2].translation() - Eigen::Vector3d(0.5, 0, 2)).norm() < 1e-12);
  CHECK((s.T_K_c[2].linear() * Eigen::Vector3d::UnitZ() - Eigen::Vector3d(1, 0, 0)).norm() < 1e-12);
  CHECK(s.camera.fx == 700.0);
  CHECK(s.camera.fy == 710.0);
  CHECK(s.camera.cx == 600.0);
  CHECK(s.camera.cy == 180.0);
  CHECK(s.baseline_m == Approx(0.54));

  // A time column: its times; an integer frame index column: nominal 0.1 s per indexed frame.
  const std::string with_times =
      write("pt.txt", "0 1 0 0 0 0 1 0 0 0 0 1 0\n0.25 1 0 0 0 0 1 0 0 0 0 1 1\n");
  CHECK(sim::load_kitti_sequence(with_times, calib).timestamps == std::vector<double>{0.0, 0.25});
  const std::string with_index =
      write("pi.txt", "0 1 0 0 0 0 1 0 0 0 0 1 0\n4 1 0 0 0 0 1 0 0 0 0 1 1\n");
  const sim::KittiSequence si = sim::load_kitti_sequence(with_index, calib);
  CHECK(si.timestamps == std::vector<double>{0.0, 0.4});
  CHECK(si.T_K_c[1].translation().z() == 1.0);

  // Malformed input names the file.
  CHECK_THROWS_AS(sim::load_kitti_sequence(poses12, calib, write("t2.txt", "0\n0.1\n")),
                  InvalidArgument);
  CHECK_THROWS_AS(sim::load_kitti_sequence(write("bad.txt", "1 0 0 0 0 1 0 0 0 0 1\n"), calib),
                  InvalidArgument);
  CHECK_THROWS_AS(sim::load_kitti_sequence(write("rot.txt", "2 0 0 0 0 1 0 0 0 0 1 0\n"), calib),
                  InvalidArgument);
  CHECK_THROWS_AS(
      sim::load_kitti_sequence(poses12, write("c1.txt", "P0: 700 0 600 0 0 710 180 0 0 0 1 0\n")),
      InvalidArgument);
  CHECK_THROWS_AS(sim::load_kitti_sequence(poses12, calib, dir.file("none.txt")), Error);
}

TEST_CASE("KITTI anchor schedule: INIT frames, then every N from 200 + N, duplicates merged",
          "[sim]") {
  const std::vector<int> a100 = sim::kitti_anchor_frames(4661, 100);
  REQUIRE(a100.size() == 4 + 44);
  CHECK(a100[0] == 50);
  CHECK(a100[3] == 200);
  CHECK(a100[4] == 300);
  CHECK(a100.back() == 4600);
  const std::vector<int> a500 = sim::kitti_anchor_frames(4071, 500);
  CHECK(a500 == std::vector<int>{50, 100, 150, 200, 700, 1200, 1700, 2200, 2700, 3200, 3700});
  const std::vector<int> a50 = sim::kitti_anchor_frames(400, 50);
  CHECK(a50 == std::vector<int>{50, 100, 150, 200, 250, 300, 350});
  CHECK(sim::kitti_anchor_frames(120, 100) == std::vector<int>{50, 100});
  CHECK_THROWS_AS(sim::kitti_anchor_frames(100, 0), InvalidArgument);
}

TEST_CASE("KITTI sequences load with the calibrated intrinsics and baseline", "[sim][data]") {
  const auto& s02 = kitti("02");
  const auto& s08 = kitti("08");
  CHECK(s02.num_frames() == 4661);
  CHECK(s08.num_frames() == 4071);
  CHECK(s02.camera.fx == Approx(718.856));
  CHECK(s02.camera.cy == Approx(185.2157));
  CHECK(s02.baseline_m == Approx(386.1448 / 718.856));
  CHECK(s08.camera.fx == Approx(707.0912));
  CHECK(s08.baseline_m == Approx(379.8145 / 707.0912));
  CHECK(s02.camera.width == 1241);
  CHECK(s02.camera.height == 376);
  CHECK(s02.timestamps.back() == Approx(483.28).margin(0.01));
  CHECK(s02.T_K_c.front().translation().norm() < 1e-9);
  CHECK_THROWS_AS(sim::load_kitti_sequence_from_dir(GEODRIFT_DATA_DIR, "03"), InvalidArgument);
  CHECK_THROWS_AS(sim::load_kitti_sequence("/nonexistent/poses.txt", "/nonexistent/calib.txt"),
                  Error);
}

TEST_CASE("The simulator is deterministic for a seed and differs between seeds", "[sim][data]") {
  sim::SimOptions o = sim::SimOptions::kitti("02", 3);
  o.last_frame = 1200;
  const auto a = sim::simulate(kitti("02"), o);
  const auto b = sim::simulate(kitti("02"), o);
  REQUIRE(a.map.keyframes.size() == b.map.keyframes.size());
  REQUIRE(a.map.points.size() == b.map.points.size());
  REQUIRE(a.map.observations.size() == b.map.observations.size());
  for (std::size_t k = 0; k < a.map.keyframes.size(); ++k)
    REQUIRE(a.map.keyframes[k].T_cw.matrix() == b.map.keyframes[k].T_cw.matrix());
  for (std::size_t i = 0; i < a.map.points.size(); ++i)
    REQUIRE(a.map.points[i].position == b.map.points[i].position);
  for (std::size_t i = 0; i < a.map.observations.size(); ++i)
    REQUIRE(a.map.observations[i].pixel == b.map.observations[i].pixel);
  const auto ca = sim::kitti_correspondences(a, 100);
  const auto cb = sim::kitti_correspondences(b, 100);
  REQUIRE(ca.size() == cb.size());
  for (std::size_t i = 0; i < ca.size(); ++i) {
    CHECK(ca[i].y_w == cb[i].y_w);
    CHECK(ca[i].T_vk.matrix() == cb[i].T_vk.matrix());
  }
  // A geo view does not depend on the anchor schedule it is part of.
  const auto c300 = sim::kitti_correspondences(a, 300);
  REQUIRE(c300.size() >= 5);
  CHECK(c300[4].geotag_id == 500);
  CHECK(ca[6].geotag_id == 500);
  CHECK(c300[4].y_w == ca[6].y_w);

  o.seed = 4;
  const auto c = sim::simulate(kitti("02"), o);
  CHECK((c.map.keyframes.back().center() - a.map.keyframes.back().center()).norm() > 1e-3);
}

TEST_CASE("Noise-free settings give zero drift and exactly localized geo views", "[sim][data]") {
  for (const std::string seq : {"02", "08"}) {
    sim::SimOptions o = sim::SimOptions::noise_free(1);
    o.last_frame = 1500;
    const auto s = sim::simulate(kitti(seq), o);
    INFO("sequence " << seq);
    s.map.validate();
    const auto st = sim::drift_statistics(s);
    REQUIRE(st.global.alignment.ok());
    CHECK(st.global.errors.all.mean < 1e-6);
    CHECK(st.global.alignment.s == Approx(1.0 / o.drift.initial_map_scale).epsilon(1e-9));
    CHECK(st.scale.sd < 1e-9);
    CHECK(rms(reprojection_residuals(s.map)) < 1e-6);

    std::vector<sim::GeoView> views;
    const auto corr = sim::kitti_correspondences(s, 100, &views);
    REQUIRE(views.size() == sim::kitti_anchor_frames(1500, 100).size());
    CHECK(corr.size() == views.size());
    for (const auto& v : views) {
      INFO("frame " << v.frame << ": " << v.failure);
      REQUIRE(v.localized);
      CHECK(v.position_error_m < 1e-3);
      CHECK(v.correspondence.reprojection_rms < 1e-3);
      // Geo view centre mapped into W by the global alignment = geo-tag (no noise) within 1 mm.
      const map::Keyframe& kf = s.map.keyframes[v.correspondence.keyframe];
      const lie::SE3d T_vw = v.correspondence.T_vk * kf.T_cw;
      const Eigen::Vector3d c_w = st.global.alignment.apply(T_vw.inverse().translation());
      CHECK((c_w - v.correspondence.y_w).norm() < 1e-3);
      CHECK(v.correspondence.y_w == v.center_true_w);
    }
  }
}

TEST_CASE("Calibrated drift meets the paper's global Sim3 error and a real VO's roughness",
          "[sim][data]") {
  const auto t0 = std::chrono::steady_clock::now();
  int sims = 0;
  for (const std::string seq : {"02", "08"}) {
    const double target = sim::paper_global_sim3_error_m(seq);
    double sum = 0.0;
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const auto s = sim::simulate(kitti(seq), sim::SimOptions::kitti(seq, seed));
      ++sims;
      const auto st = sim::drift_statistics(s);
      std::printf(
          "sim %s seed %u: %zu keyframes, %zu points, %zu observations; global Sim3 error "
          "%.2f m (paper %.2f); 50-frame scale min %.3f max %.3f sd %.3f step sd %.3f; "
          "beta %.2f gamma %.2f %s\n",
          seq.c_str(), seed, s.map.keyframes.size(), s.map.points.size(), s.map.observations.size(),
          st.global.errors.all.mean, target, st.scale.min, st.scale.max, st.scale.sd,
          st.scale.step_sd, s.scale_drift_amplitude, s.rotation_drift_amplitude, s.message.c_str());
      INFO(seq << " seed " << seed);
      CHECK(s.calibrated);
      CHECK(std::abs(st.global.errors.all.mean - target) <= 0.2 * target);
      CHECK(st.scale.sd >= 0.06);
      CHECK(st.scale.sd <= 0.10);
      CHECK(st.scale.step_sd >= 0.05);
      CHECK(st.scale.step_sd <= 0.09);
      CHECK(st.scale.min >= 0.75);
      CHECK(st.scale.min <= 0.92);
      CHECK(st.scale.max >= 1.12);
      CHECK(st.scale.max <= 1.35);
      // About one frame in three is a keyframe.
      const double ratio = static_cast<double>(s.map.keyframes.size()) / kitti(seq).num_frames();
      CHECK(ratio > 0.25);
      CHECK(ratio < 0.40);
      sum += st.global.errors.all.mean;
    }
    std::printf("sim %s: mean global Sim3 error over seeds 1..5 = %.2f m (paper %.2f m)\n",
                seq.c_str(), sum / 5.0, target);
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("sim: %d full-sequence simulations in %.2f s\n", sims, secs);
  CHECK(secs / sims < 3.0);
}

TEST_CASE("Observations reproject within the pixel noise and covisibility links the path",
          "[sim][data]") {
  const auto s = sim::simulate(kitti("08"), sim::SimOptions::kitti("08", 2));
  s.map.validate();
  const std::vector<double> r = reprojection_residuals(s.map);
  const double r_rms = rms(r);
  double r_max = 0;
  for (double x : r) r_max = std::max(r_max, std::abs(x));
  std::printf("sim 08 seed 2: reprojection RMS per axis %.3f px, max %.2f px over %zu obs\n", r_rms,
              r_max, s.map.observations.size());
  CHECK(r_rms == Approx(1.0).epsilon(0.03));
  CHECK(r_max < 6.0);
  // Every point has >= 2 observations and its reference keyframe observes it.
  std::vector<int> count(s.map.points.size(), 0);
  std::set<std::pair<int, int>> seen;
  for (const auto& o : s.map.observations) {
    ++count[o.point];
    seen.insert({o.keyframe, o.point});
  }
  for (const auto& p : s.map.points) {
    REQUIRE(count[p.id] >= 2);
    REQUIRE(seen.count({p.reference_keyframe, p.id}) == 1);
  }
  // Consecutive keyframes share enough points to be covisible (a connected pose graph).
  const auto cov = map::covisibility(s.map.observations, 15);
  std::set<std::pair<int, int>> pairs;
  for (const auto& c : cov) pairs.insert(c.first);
  int linked = 0;
  for (std::size_t k = 0; k + 1 < s.map.keyframes.size(); ++k)
    linked += pairs.count({static_cast<int>(k), static_cast<int>(k + 1)});
  CHECK(linked >= static_cast<int>(s.map.keyframes.size()) - 1 - 5);
  // Ground truth per keyframe is the true cam0 centre in W.
  for (std::size_t k = 0; k < s.map.keyframes.size(); k += 97)
    CHECK((s.gt_center_w[k] - geo::kitti_point_to_world(
                                  kitti("08").T_K_c[s.map.keyframes[k].frame_index].translation()))
              .norm() < 1e-9);
}

TEST_CASE("Geo views localize in the drifted map with small error", "[sim][data]") {
  for (const std::string seq : {"02", "08"}) {
    const auto& ks = kitti(seq);
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const auto s = sim::simulate(ks, sim::SimOptions::kitti(seq, seed));
      std::vector<sim::GeoView> views;
      const auto corr = sim::kitti_correspondences(s, 100, &views);
      double sum = 0, worst = 0;
      std::vector<double> errs;
      for (const auto& v : views)
        if (v.localized) {
          sum += v.position_error_m;
          worst = std::max(worst, v.position_error_m);
          errs.push_back(v.position_error_m);
        }
      std::sort(errs.begin(), errs.end());
      const double median = errs.empty() ? 0.0 : errs[errs.size() / 2];
      std::printf(
          "sim %s seed %u: %zu/%zu geo views localized, error in the drifted frame mean %.3f "
          "median %.3f max %.3f m\n",
          seq.c_str(), seed, corr.size(), views.size(), sum / std::max<std::size_t>(1, corr.size()),
          median, worst);
      INFO(seq << " seed " << seed);
      CHECK(corr.size() >= views.size() - 1);
      // The four INIT anchors must localize.
      for (int i = 0; i < 4; ++i) CHECK(views[i].localized);
      CHECK(sum / corr.size() < 0.6);
      CHECK(median < 0.5);
      for (std::size_t i = 0; i < corr.size(); ++i) {
        const auto& c = corr[i];
        CHECK(c.id == static_cast<int>(i));
        CHECK(c.keyframe == s.nearest_keyframe(c.geotag_id));
        CHECK(c.sigma_m == 0.05);
        CHECK(c.inliers >= s.options.min_geo_view_points);
        // Geo-tag: right camera centre in W (baseline along cam0's x) plus 5 cm noise.
        const Eigen::Isometry3d T = ks.T_K_c[c.geotag_id];
        const Eigen::Vector3d right_w =
            geo::kitti_point_to_world(T * Eigen::Vector3d(ks.baseline_m, 0, 0));
        CHECK((c.y_w - right_w).norm() < 0.3);
      }
    }
  }
}
