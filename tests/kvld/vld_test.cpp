// The VLD against an independent, straightforward computation of kvld.md §3.2–3.3.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <opencv2/core.hpp>
#include <vector>

#include "geodrift/kvld/kvld.hpp"

namespace kvld = geodrift::kvld;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// A smooth, non-periodic test pattern with gradients in every direction.
std::vector<double> pattern(int w, int h) {
  std::vector<double> img(static_cast<std::size_t>(w * h));
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      img[static_cast<std::size_t>(y * w + x)] = 120.0 + 50.0 * std::sin(0.31 * x + 0.17 * y) +
                                                 30.0 * std::cos(0.23 * y - 0.13 * x) +
                                                 20.0 * std::sin(0.011 * x * y) + 0.4 * x;
    }
  }
  return img;
}

/// Straightforward reference: downsample by exact pixel-overlap area averaging, central
/// differences, disc loops over the whole bounding box, histograms, main bins, normalisation.
struct HandVld {
  std::vector<double> desc = std::vector<double>(80, 0.0);
  std::vector<int> bins = std::vector<int>(10, 0);
  std::vector<double> weights = std::vector<double>(10, 0.0);
  double contrast = 0;
  int level = 0;
};

HandVld hand_vld(const std::vector<double>& img, int W, int H, double x1, double y1, double x2,
                 double y2) {
  HandVld out;
  // Levels: floor(log2(max(W,H)/5)) + 1; level k radius band (5·√2^k, 5·√2^(k+1)].
  const int levels = static_cast<int>(std::floor(std::log2(std::max(W, H) / 5.0))) + 1;
  const double L = std::hypot(x2 - x1, y2 - y1);
  const double rho = std::max(L / 11.0, 2.0);
  int k = 0;
  while (k < levels - 1 && rho > 5.0 * std::pow(std::sqrt(2.0), k + 1)) ++k;
  out.level = k;
  const double ratio = std::pow(std::sqrt(2.0), k);
  // The level image: area average over [i·ratio, (i+1)·ratio)² of the unit-square pixels.
  const int w = static_cast<int>(W / ratio), h = static_cast<int>(H / ratio);
  std::vector<double> lv(static_cast<std::size_t>(w * h), 0.0);
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      const double x0 = i * ratio, xe = (i + 1) * ratio, y0 = j * ratio, ye = (j + 1) * ratio;
      double sum = 0;
      for (int v = 0; v < H; ++v) {
        const double oy = std::min<double>(v + 1, ye) - std::max<double>(v, y0);
        if (oy <= 0) continue;
        for (int u = 0; u < W; ++u) {
          const double ox = std::min<double>(u + 1, xe) - std::max<double>(u, x0);
          if (ox <= 0) continue;
          sum += ox * oy * img[static_cast<std::size_t>(v * W + u)];
        }
      }
      lv[static_cast<std::size_t>(j * w + i)] = sum / (ratio * ratio);
    }
  }
  const auto at = [&](int x, int y) { return lv[static_cast<std::size_t>(y * w + x)]; };
  const double theta = std::fmod(std::atan2(y2 - y1, x2 - x1) + 2 * kPi, 2 * kPi);
  const double r = rho / ratio;
  double wsum = 0;
  for (int d = 0; d < 10; ++d) {
    const double cx = (x1 + (d + 1) / 11.0 * (x2 - x1)) / ratio;
    const double cy = (y1 + (d + 1) / 11.0 * (y2 - y1)) / ratio;
    std::vector<double> hist(24, 0.0);
    for (int y = 1; y <= h - 2; ++y) {
      for (int x = 1; x <= w - 2; ++x) {
        const double dist = std::hypot(x - cx, y - cy);
        if (dist > r) continue;
        const double gx = at(x + 1, y) - at(x - 1, y);
        const double gy = at(x, y + 1) - at(x, y - 1);
        const double mag = std::hypot(gx, gy);
        if (mag == 0) continue;
        double alpha = std::atan2(gy, gx) - theta;
        while (alpha < 0) alpha += 2 * kPi;
        while (alpha >= 2 * kPi) alpha -= 2 * kPi;
        const double wgt = std::exp(-dist * dist / (4.5 * r * r)) * mag;
        hist[static_cast<std::size_t>(static_cast<int>(alpha * 24 / (2 * kPi) + 0.5) % 24)] += wgt;
        out.desc[static_cast<std::size_t>(8 * d + static_cast<int>(alpha * 8 / (2 * kPi) + 0.5) %
                                                      8)] += wgt;
      }
    }
    int best = 0;
    double bv = hist[0] - hist[12];
    for (int b = 1; b < 24; ++b) {
      const double v =
          hist[static_cast<std::size_t>(b)] - hist[static_cast<std::size_t>((b + 12) % 24)];
      if (v > bv) {
        bv = v;
        best = b;
      }
    }
    out.bins[static_cast<std::size_t>(d)] = best;
    out.weights[static_cast<std::size_t>(d)] = bv;
    wsum += bv;
  }
  double dsum = 0;
  for (double v : out.desc) dsum += v;
  for (double& v : out.desc) v /= dsum;
  out.contrast = wsum / (L / ratio);
  for (double& v : out.weights) v /= wsum;
  return out;
}

void compare(const kvld::Vld& v, const HandVld& ref) {
  CHECK(v.level == ref.level);
  CHECK(v.contrast == Approx(ref.contrast).epsilon(1e-5));
  for (int d = 0; d < 10; ++d) {
    INFO("disc " << d);
    CHECK(v.main_bin[static_cast<std::size_t>(d)] == ref.bins[static_cast<std::size_t>(d)]);
    CHECK(v.weight[static_cast<std::size_t>(d)] ==
          Approx(ref.weights[static_cast<std::size_t>(d)]).margin(1e-6));
    for (int b = 0; b < 8; ++b) {
      INFO("bin " << b);
      CHECK(v.descriptor[static_cast<std::size_t>(8 * d + b)] ==
            Approx(ref.desc[static_cast<std::size_t>(8 * d + b)]).margin(1e-6));
    }
  }
}

}  // namespace

TEST_CASE("A VLD matches a hand computation of the formulas bin by bin", "[kvld][vld]") {
  const int W = 64, H = 64;
  const std::vector<double> img = pattern(W, H);
  cv::Mat m(H, W, CV_64F);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) m.at<double>(y, x) = img[static_cast<std::size_t>(y * W + x)];
  const kvld::ImageScale scale(m);
  // floor(log2(64/5)) + 1 = 4 levels.
  REQUIRE(scale.num_levels() == 4);
  CHECK(scale.level(1).width == 45);  // floor(64/√2)

  SECTION("level 0 (short segment, disc radius 2..5 px)") {
    const double x1 = 12.3, y1 = 20.7, x2 = 47.9, y2 = 38.2;
    const kvld::Vld v = kvld::compute_vld(scale, x1, y1, x2, y2);
    const HandVld ref = hand_vld(img, W, H, x1, y1, x2, y2);
    REQUIRE(ref.level == 0);
    compare(v, ref);
  }
  SECTION("level 1 (long diagonal, box-averaged pyramid level)") {
    const double x1 = 4.2, y1 = 58.6, x2 = 60.1, y2 = 3.4;  // L ≈ 78.6 → ρ ≈ 7.1 → level 1
    const kvld::Vld v = kvld::compute_vld(scale, x1, y1, x2, y2);
    const HandVld ref = hand_vld(img, W, H, x1, y1, x2, y2);
    REQUIRE(ref.level == 1);
    compare(v, ref);
  }
  SECTION("a very short segment uses the minimum disc radius of 2 px") {
    const kvld::Vld v = kvld::compute_vld(scale, 30, 30, 36, 33);
    compare(v, hand_vld(img, W, H, 30, 30, 36, 33));
  }
}

TEST_CASE("The raw float buffer and the cv::Mat constructors build the same scale space",
          "[kvld][vld]") {
  const int W = 50, H = 37;
  const std::vector<double> img = pattern(W, H);
  std::vector<float> buf(static_cast<std::size_t>(64 * H), -1.0f);  // stride 64 > width
  cv::Mat m8(H, W, CV_8U);
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const auto v = static_cast<unsigned char>(
          std::clamp(img[static_cast<std::size_t>(y * W + x)], 0.0, 255.0));
      m8.at<unsigned char>(y, x) = v;
      buf[static_cast<std::size_t>(y * 64 + x)] = v;
    }
  }
  const kvld::ImageScale a(m8), b(buf.data(), W, H, 64);
  REQUIRE(a.num_levels() == b.num_levels());
  for (int k = 0; k < a.num_levels(); ++k) {
    CHECK(a.level(k).magnitude == b.level(k).magnitude);
    CHECK(a.level(k).angle == b.level(k).angle);
  }
}

TEST_CASE("Scale-space level selection follows the sqrt(2) radius bands", "[kvld][vld]") {
  const kvld::ImageScale s(cv::Mat(400, 640, CV_8U, cv::Scalar(7)));
  CHECK(s.num_levels() == 8);  // floor(log2(640/5)) + 1 = 7 + 1
  CHECK(s.level_for_radius(2.0) == 0);
  CHECK(s.level_for_radius(5.0) == 0);
  CHECK(s.level_for_radius(5.01) == 0);
  CHECK(s.level_for_radius(7.07) == 0);  // 5·√2 = 7.0711
  CHECK(s.level_for_radius(7.08) == 1);
  CHECK(s.level_for_radius(10.0) == 1);
  CHECK(s.level_for_radius(10.01) == 2);
  CHECK(s.level_for_radius(1e6) == 7);  // clamped to the last level
  CHECK(s.level(3).ratio == Approx(std::pow(std::sqrt(2.0), 3)));
}

TEST_CASE("The VLD difference combines descriptor and orientation terms", "[kvld][vld]") {
  kvld::Vld a, b;
  a.contrast = b.contrast = 10.0;
  for (int d = 0; d < 10; ++d) {
    a.descriptor[static_cast<std::size_t>(8 * d)] = 0.1;
    b.descriptor[static_cast<std::size_t>(8 * d + 1)] = 0.1;
    a.weight[static_cast<std::size_t>(d)] = b.weight[static_cast<std::size_t>(d)] = 0.1;
  }
  a.main_bin[0] = 1;
  b.main_bin[0] = 23;  // circular distance 2
  a.main_bin[1] = 0;
  b.main_bin[1] = 12;  // distance 12
  // 0.36·(20·0.1) + 0.64/24·(2·0.2 + 12·0.2)
  CHECK(kvld::vld_difference(a, b) == Approx(0.36 * 2.0 + 0.64 / 24.0 * 2.8).epsilon(1e-12));
  CHECK(kvld::vld_difference(a, a) == 0.0);
  b.contrast = 300.5;
  CHECK(kvld::vld_difference(a, b) == 128.0);
  b.contrast = 0.0;
  CHECK(kvld::vld_difference(a, b) == 128.0);
}

TEST_CASE("A VLD is unchanged when image and segment are rotated by 90 degrees", "[kvld][vld]") {
  const int W = 80, H = 60;
  const std::vector<double> img = pattern(W, H);
  cv::Mat m(H, W, CV_32F);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      m.at<float>(y, x) = static_cast<float>(img[static_cast<std::size_t>(y * W + x)]);
  cv::Mat rot;
  cv::rotate(m, rot, cv::ROTATE_90_CLOCKWISE);  // (x, y) -> (H-1-y, x)
  const kvld::ImageScale s1(m), s2(rot);
  const double x1 = 15, y1 = 12, x2 = 55, y2 = 40;  // level 0 (ρ ≈ 4.4)
  const kvld::Vld v1 = kvld::compute_vld(s1, x1, y1, x2, y2);
  const kvld::Vld v2 = kvld::compute_vld(s2, H - 1 - y1, x1, H - 1 - y2, x2);
  CHECK(v1.contrast == Approx(v2.contrast).epsilon(1e-5));
  CHECK(kvld::vld_difference(v1, v2) < 1e-5);
  CHECK(v1.main_bin == v2.main_bin);
}
