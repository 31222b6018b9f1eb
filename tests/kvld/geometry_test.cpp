// Geometric consistency (kvld.md §3.4) on constructed cases.
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>

#include "geodrift/kvld/kvld.hpp"

namespace kvld = geodrift::kvld;

namespace {
constexpr double kPi = 3.14159265358979323846;

/// Maps a keypoint of image 1 through the similarity p' = s·R(phi)·p + t, carrying its scale
/// and orientation along (what an ideal detector would report in image 2).
kvld::Keypoint warp(const kvld::Keypoint& k, double s, double phi, double tx, double ty) {
  const double c = std::cos(phi), sn = std::sin(phi);
  return {s * (c * k.x - sn * k.y) + tx, s * (sn * k.x + c * k.y) + ty, s * k.scale, k.angle + phi};
}
}  // namespace

TEST_CASE("Matches related by one similarity are geometrically consistent", "[kvld][geometry]") {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> pos(0, 600), ang(-kPi, kPi), sc(1, 30);
  std::uniform_real_distribution<double> s_d(0.5, 2.0), phi_d(-kPi, kPi);
  for (int trial = 0; trial < 200; ++trial) {
    const double s = s_d(rng), phi = phi_d(rng);
    const kvld::Keypoint a1{pos(rng), pos(rng), sc(rng), ang(rng)};
    const kvld::Keypoint a2{pos(rng), pos(rng), sc(rng), ang(rng)};
    const kvld::Keypoint b1 = warp(a1, s, phi, 30, -12), b2 = warp(a2, s, phi, 30, -12);
    INFO("trial " << trial);
    CHECK(kvld::geometric_consistency(a1, a2, b1, b2) < 1e-9);
  }
}

TEST_CASE("Geometric consistency is the relative error of the predicted neighbour vector",
          "[kvld][geometry]") {
  // Match 1 predicts rotation +90° and scale ×2; match 2 predicts no rotation and scale ×1.
  const kvld::Keypoint a1{100, 100, 4, 0.0}, a2{130, 100, 4, 0.3};
  const kvld::Keypoint b1{200, 200, 8, kPi / 2}, b2{200, 260, 4, 0.3};
  // a1 - a2 = (-30, 0). Match 1: rotate 90° → (0, -30), ×2 → (0, -60) = b1 - b2 exactly.
  CHECK(kvld::geometric_consistency(a1, a2, b1, b2) == Approx(0.0).margin(1e-12));
  // Move b2 by 15 px along x: b1 - b2 = (-15, -60). e1 = 15 / min(60, |(-15,60)|) = 0.25;
  // match 2 predicts (-30, 0): e2 = |(-15, 60)| / min(30, 61.85) = 2.06. min = 0.25.
  const kvld::Keypoint b2s{215, 260, 4, 0.3};
  CHECK(kvld::geometric_consistency(a1, a2, b1, b2s) == Approx(0.25).epsilon(1e-12));
  // Symmetric in the two matches (the roles of e1 and e2 swap).
  CHECK(kvld::geometric_consistency(a2, a1, b2s, b1) == Approx(0.25).epsilon(1e-12));
  // Scale only wrong: predicted (0, -60) but actual (0, -20) → e1 = 40/20 = 2; match 2
  // predicts (-30, 0): e2 = |(-30, 20)|/20 = 1.80 → inconsistent (≥ 0.5).
  const kvld::Keypoint b2f{200, 220, 4, 0.3};
  const double expect = std::hypot(30.0, -20.0) / 20.0;
  CHECK(kvld::geometric_consistency(a1, a2, b1, b2f) == Approx(expect).epsilon(1e-12));
  CHECK(kvld::geometric_consistency(a1, a2, b1, b2f) >= 0.5);
}

TEST_CASE("Keypoint orientation errors break geometric consistency", "[kvld][geometry]") {
  const kvld::Keypoint a1{50, 50, 3, 0.1}, a2{90, 70, 3, 1.0};
  // Image 2 = image 1 rotated by 40° about the origin, but both detectors report orientations
  // 90° off: prediction (rotated by 40° + 90°) points 90° away → relative error √2 both ways.
  const double phi = 40 * kPi / 180;
  const kvld::Keypoint b1 = warp(a1, 1, phi, 0, 0), b2 = warp(a2, 1, phi, 0, 0);
  kvld::Keypoint b1w = b1, b2w = b2;
  b1w.angle += kPi / 2;
  b2w.angle += kPi / 2;
  CHECK(kvld::geometric_consistency(a1, a2, b1w, b2w) == Approx(std::sqrt(2.0)).epsilon(1e-9));
  // One detector right is enough (min of the two predictions).
  CHECK(kvld::geometric_consistency(a1, a2, b1, b2w) < 1e-9);
}

TEST_CASE("Coincident points are never geometrically consistent", "[kvld][geometry]") {
  const kvld::Keypoint a1{10, 10, 2, 0}, a2{40, 10, 2, 0}, b1{10, 10, 2, 0};
  const double g = kvld::geometric_consistency(a1, a2, b1, b1);
  CHECK_FALSE(g < 0.5);
}

TEST_CASE("ORB keypoint angles are converted from degrees to radians", "[kvld][geometry]") {
  const std::vector<cv::KeyPoint> cv_kps{cv::KeyPoint(3.5f, 4.5f, 31.0f, 90.0f),
                                         cv::KeyPoint(1, 2, 7, -1)};
  const auto k = kvld::keypoints_from_cv(cv_kps);
  REQUIRE(k.size() == 2);
  CHECK(k[0].x == 3.5);
  CHECK(k[0].y == 4.5);
  CHECK(k[0].scale == 31.0);
  CHECK(k[0].angle == Approx(kPi / 2).epsilon(1e-12));
  CHECK(std::isnan(k[1].angle));
}
