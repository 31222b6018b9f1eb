// INIT (paper Sec. 3.4) and the correction residuals' Jacobians.
#include "geodrift/correction/init.hpp"

#include <catch2/catch.hpp>
#include <random>

#include "geodrift/correction/input_checks.hpp"
#include "geodrift/correction/residuals/geo_view_centre.hpp"
#include "geodrift/correction/residuals/init_similarity.hpp"
#include "support/numeric_jacobian.hpp"
#include "support/samples.hpp"

using namespace geodrift;

TEST_CASE("INIT similarity residual Jacobian matches central differences",
          "[correction][jacobian]") {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 300; ++trial) {
    const correction::InitSimilarityResidual res{
        Eigen::Vector3d(300 * u(rng), 300 * u(rng), 10 * u(rng)),
        Eigen::Vector3d(1e3 * u(rng), 1e3 * u(rng), 50 * u(rng))};
    Eigen::Matrix<double, 5, 1> x;
    x << 1e3 * u(rng), 1e3 * u(rng), 2 * u(rng), 3.1 * u(rng), 20 * u(rng);
    Eigen::Vector3d r;
    Eigen::Matrix<double, 3, 5> J;
    res(x, &r, &J);
    const auto f = [&](const Eigen::Matrix<double, 5, 1>& y) {
      Eigen::Vector3d v;
      res(y, &v);
      return Eigen::VectorXd(v);
    };
    INFO("trial " << trial);
    const double h = 1e-6;
    CHECK(test::near(J, test::numeric_jacobian_vector(f, x, h), 1e-6,
                     test::rounding_floor(r.lpNorm<Eigen::Infinity>() + 1e4, h)));
  }
}

TEST_CASE("BA geo-view centre residual Jacobian matches central differences",
          "[correction][jacobian]") {
  std::mt19937 rng(7);
  auto samples = test::group_samples<lie::SE3d>(rng, 300);
  for (std::size_t trial = 0; trial < samples.size(); ++trial) {
    const lie::SE3d& T = samples[trial];
    const correction::GeoViewCentreResidual res{test::random_translation(rng, 2.0),
                                                test::random_translation(rng, 1e3)};
    Eigen::Vector3d r;
    Eigen::Matrix<double, 3, 6> J;
    res(T, &r, &J);
    const auto f = [&](const lie::SE3d& X) {
      Eigen::Vector3d v;
      res(X, &v);
      return Eigen::VectorXd(v);
    };
    INFO("trial " << trial);
    const double h = 1e-6;
    const double scale = r.lpNorm<Eigen::Infinity>() + T.translation().norm();
    CHECK(test::near(J, test::numeric_jacobian(f, T, h), 1e-6, test::rounding_floor(scale, h)));
  }
}

namespace {
/// A tilted, rotated, scaled map: cameras along a bent road, map = S_mw · world.
struct InitScene {
  std::vector<Eigen::Vector3d> centres_m, up_m, anchor_m, anchor_w;
  lie::Sim3d S_wm;
};

InitScene make_scene(std::mt19937& rng, double anchor_noise_m) {
  InitScene s;
  const lie::Sim3d S_wm(lie::SO3d::exp(Eigen::Vector3d(0.3, -0.2, 1.1)),
                        Eigen::Vector3d(120, -40, 7), 3.7);
  s.S_wm = S_wm;
  const lie::Sim3d S_mw = S_wm.inverse();
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    // A flat L-shaped road in W (so the model is exact); camera up is W's +z.
    const double d = i * 1.5;
    const Eigen::Vector3d c_w =
        d < 150 ? Eigen::Vector3d(d, 0, 0) : Eigen::Vector3d(150, d - 150, 0);
    s.centres_m.push_back(S_mw.act(c_w));
    s.up_m.push_back(S_mw.rotation().act(Eigen::Vector3d::UnitZ()));
    if (i % 50 == 49) {
      s.anchor_m.push_back(S_mw.act(c_w));
      s.anchor_w.push_back(c_w + anchor_noise_m * Eigen::Vector3d(n(rng), n(rng), n(rng)));
    }
  }
  return s;
}
}  // namespace

TEST_CASE("INIT recovers a known similarity exactly from noise-free anchors",
          "[correction][init]") {
  std::mt19937 rng(1);
  const InitScene s = make_scene(rng, 0.0);
  const auto res = correction::estimate_init(s.centres_m, s.up_m, s.anchor_m, s.anchor_w);
  INFO(res.message);
  REQUIRE(res.ok);
  CHECK(res.inliers.size() == 4);
  CHECK(res.rms_m < 1e-9);
  CHECK(std::abs(res.S_wm.scale() - s.S_wm.scale()) < 1e-9);
  // Every camera centre maps to its world position within a micrometre.
  double worst = 0;
  for (const auto& c : s.centres_m)
    worst = std::max(worst, (res.S_wm.act(c) - s.S_wm.act(c)).norm());
  CHECK(worst < 1e-6);
}

TEST_CASE("INIT stays within the anchor noise and rejects an outlier anchor",
          "[correction][init]") {
  std::mt19937 rng(2);
  InitScene s = make_scene(rng, 0.5);
  // A fifth anchor 40 m off: RANSAC must drop it.
  s.anchor_m.push_back(s.centres_m[20]);
  s.anchor_w.push_back(s.S_wm.act(s.centres_m[20]) + Eigen::Vector3d(40, 0, 0));
  const auto res = correction::estimate_init(s.centres_m, s.up_m, s.anchor_m, s.anchor_w);
  REQUIRE(res.ok);
  CHECK(res.inliers.size() == 4);
  CHECK(std::find(res.inliers.begin(), res.inliers.end(), 4) == res.inliers.end());
  double worst = 0;
  for (const auto& c : s.centres_m)
    worst = std::max(worst, (res.S_wm.act(c) - s.S_wm.act(c)).head<2>().norm());
  CHECK(worst < 2.0);  // 0.5 m anchor noise over a 300 m path
  CHECK(res.S_wm.scale() > 0);
}

TEST_CASE("INIT reports coincident anchors and too few anchors instead of a transform",
          "[correction][init]") {
  std::mt19937 rng(3);
  InitScene s = make_scene(rng, 0.0);
  for (std::size_t i = 1; i < s.anchor_w.size(); ++i)
    s.anchor_w[i] = s.anchor_w[0] + Eigen::Vector3d(0.1 * static_cast<double>(i), 0, 0);
  auto res = correction::estimate_init(s.centres_m, s.up_m, s.anchor_m, s.anchor_w);
  CHECK_FALSE(res.ok);
  CHECK_THAT(res.message, Catch::Contains("unobservable"));
  CHECK(res.S_wm.scale() == 1.0);

  s = make_scene(rng, 0.0);
  s.anchor_m.resize(3);
  s.anchor_w.resize(3);
  res = correction::estimate_init(s.centres_m, s.up_m, s.anchor_m, s.anchor_w);
  CHECK_FALSE(res.ok);
  CHECK_THAT(res.message, Catch::Contains("3 correspondences, 4 needed"));

  s = make_scene(rng, 0.0);
  s.anchor_w[1].x() = std::nan("");
  CHECK_THROWS_WITH(correction::estimate_init(s.centres_m, s.up_m, s.anchor_m, s.anchor_w),
                    Catch::Contains("correspondence 1"));
}

TEST_CASE("INIT levels a straight road from the camera up vectors", "[correction][init]") {
  // Collinear camera centres: PCA cannot fix the roll about the road; camera up must.
  std::mt19937 rng(4);
  const lie::Sim3d S_wm(lie::SO3d::exp(Eigen::Vector3d(0.4, 0.1, -0.7)), Eigen::Vector3d(5, 6, 7),
                        0.8);
  const lie::Sim3d S_mw = S_wm.inverse();
  std::vector<Eigen::Vector3d> c_m, up_m, a_m, a_w;
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d c_w(2.0 * i, 0, 0);
    c_m.push_back(S_mw.act(c_w));
    up_m.push_back(S_mw.rotation().act(Eigen::Vector3d::UnitZ()));
    if (i % 25 == 0) {
      a_m.push_back(c_m.back());
      a_w.push_back(c_w);
    }
  }
  const auto res = correction::estimate_init(c_m, up_m, a_m, a_w);
  REQUIRE(res.ok);
  CHECK(res.plane_from_camera_up);
  // A point 10 m beside and above the road lands where it should.
  const Eigen::Vector3d p_w(50, 10, 10);
  CHECK((res.S_wm.act(S_mw.act(p_w)) - p_w).norm() < 1e-6);
}

TEST_CASE("planar_diameter is the largest horizontal distance, on hulls of every shape",
          "[correction][init]") {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-100, 100);
  auto brute = [](const std::vector<Eigen::Vector3d>& p) {
    double d = 0;
    for (std::size_t i = 0; i < p.size(); ++i)
      for (std::size_t j = i + 1; j < p.size(); ++j)
        d = std::max(d, (p[i] - p[j]).head<2>().norm());
    return d;
  };
  std::vector<std::vector<Eigen::Vector3d>> sets;
  for (int n : {1, 2, 3, 5, 17, 200}) {  // random clouds
    std::vector<Eigen::Vector3d> p;
    for (int i = 0; i < n; ++i) p.emplace_back(u(rng), u(rng), u(rng));
    sets.push_back(p);
  }
  for (int n : {3, 4, 6, 7, 64, 301}) {  // every point on the hull: regular polygons
    std::vector<Eigen::Vector3d> p;
    const double phase = u(rng);
    for (int i = 0; i < n; ++i) {
      const double a = phase + 2 * M_PI * i / n;
      p.emplace_back(50 * std::cos(a) + 3, 20 * std::sin(a) - 7, i);
    }
    sets.push_back(p);
  }
  std::vector<Eigen::Vector3d> grid, line, same;  // parallel edges, collinear, coincident
  for (int i = 0; i < 9; ++i)
    for (int j = 0; j < 4; ++j) grid.emplace_back(i, 2.5 * j, 0);
  for (int i = 0; i < 50; ++i) line.emplace_back(3 + 0.5 * (i % 7), 1 - 0.25 * (i % 7), i);
  for (int i = 0; i < 5; ++i) same.emplace_back(4, -2, i);
  sets.push_back(grid);
  sets.push_back(line);
  sets.push_back(same);
  for (const auto& p : sets) {
    INFO(p.size() << " points");
    CHECK(correction::detail::planar_diameter(p) == Approx(brute(p)).margin(1e-12));
  }
  CHECK(correction::detail::planar_diameter({}) == 0.0);
}

TEST_CASE("A corrected path turned over by mirrored anchors is told from an upright one",
          "[correction][input_checks]") {
  // A car's camera (OpenCV axes: x right, y down, z forward) driving a left-hand curve in W
  // (z up), 1.5 m per keyframe, with a little roll and pitch.
  std::mt19937 rng(7);
  std::normal_distribution<double> wobble(0.0, 0.03);
  std::vector<lie::SE3d> upright, over, gl, reversing;
  const Eigen::Matrix3d cam_from_body =
      (Eigen::Matrix3d() << 0, -1, 0, 0, 0, -1, 1, 0, 0).finished();  // body x fwd, z up
  for (int i = 0; i < 200; ++i) {
    const double yaw = 0.01 * i;
    const Eigen::Vector3d c(150 * std::sin(yaw), 150 * (1 - std::cos(yaw)), 0);  // radius 150 m
    const Eigen::Matrix3d R_wb = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                                  Eigen::AngleAxisd(wobble(rng), Eigen::Vector3d::UnitX()) *
                                  Eigen::AngleAxisd(wobble(rng), Eigen::Vector3d::UnitY()))
                                     .toRotationMatrix();
    const Eigen::Matrix3d R_cw = cam_from_body * R_wb.transpose();
    upright.emplace_back(lie::SO3d(Eigen::Quaterniond(R_cw)), -R_cw * c);
    // Turned over: the whole path rotated by 180 degrees about W's x axis (what a Sim(3) pose
    // graph does to fit anchors mirrored in y).
    const Eigen::Matrix3d F = Eigen::Vector3d(1, -1, -1).asDiagonal();
    over.emplace_back(lie::SO3d(Eigen::Quaterniond(R_cw * F)), -R_cw * F * (F * c));
    // OpenGL axes (y up, z backwards): the camera rotated by 180 degrees about its x axis.
    const Eigen::Matrix3d G = F * R_cw;
    gl.emplace_back(lie::SO3d(Eigen::Quaterniond(G)), -G * c);
  }
  // Driving backwards, upside down: not the forward signature.
  for (int i = 199; i >= 0; --i) reversing.push_back(over[i]);

  const correction::CameraAttitude a = correction::camera_attitude(upright);
  CHECK(a.keyframes == 200);
  CHECK(a.upside_down == 0);
  CHECK(a.moving == 199);
  CHECK(a.forward == 199);
  CHECK_FALSE(a.turned_over());
  const correction::CameraAttitude b = correction::camera_attitude(over);
  CHECK(b.upside_down == 200);
  CHECK(b.forward == 199);
  CHECK(b.turned_over());
  const correction::CameraAttitude g = correction::camera_attitude(gl);
  CHECK(g.upside_down == 200);  // in OpenCV's reading
  CHECK(g.forward == 0);        // but it moves along -z
  CHECK_FALSE(g.turned_over());
  CHECK_FALSE(correction::camera_attitude(reversing).turned_over());
  CHECK_FALSE(correction::camera_attitude({}).turned_over());
}

TEST_CASE("Implausible drift needs both a large drift factor and a stretched scale",
          "[correction][input_checks]") {
  std::vector<double> s(101);
  for (int i = 0; i <= 100; ++i) s[i] = std::exp(0.05 * i);  // e^0 .. e^5
  // 5th and 95th percentiles: e^0.25 and e^4.75.
  CHECK(correction::scale_spread(s) == Approx(std::exp(4.5)).epsilon(1e-12));
  CHECK(std::isnan(correction::scale_spread({2.0})));
  CHECK(correction::scale_spread({1.0, 3.0}) == Approx(3.0));
  CHECK(correction::implausible_drift(460, 17.2));       // KITTI 02 with T_cw read as T_wc
  CHECK_FALSE(correction::implausible_drift(161, 1.1));  // a 0.7 s clock offset, no drift
  CHECK_FALSE(correction::implausible_drift(8, 30));     // 30 % wrong anchors, a long drift
  CHECK_FALSE(correction::implausible_drift(NAN, 30));
  CHECK_FALSE(correction::implausible_drift(460, NAN));
}
