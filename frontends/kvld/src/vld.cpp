// Virtual line descriptor (kvld.md §3.3) and the geometric consistency test (§3.4).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "geodrift/error.hpp"
#include "geodrift/kvld/kvld.hpp"

namespace geodrift::kvld {
namespace {
constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kBinsPerRad = kBinNum / kTwoPi;
constexpr int kRatioBins = kBinNum / kSubdirection;  // 24-bin units per 8-bin unit
static_assert(kBinNum % 2 == 0, "binNum must be even");
static_assert(kBinNum % kSubdirection == 0, "8-bin index is derived from the 24-bin position");
}  // namespace

Vld compute_vld(const ImageScale& scale, double x1, double y1, double x2, double y2) {
  GEODRIFT_CHECK(std::isfinite(x1) && std::isfinite(y1) && std::isfinite(x2) && std::isfinite(y2),
                 "kvld::compute_vld: non-finite endpoint (" << x1 << ", " << y1 << ") -> (" << x2
                                                            << ", " << y2 << ")");
  Vld v;
  const double dx = x2 - x1, dy = y2 - y1;
  v.length = std::hypot(dx, dy);
  // Main angle of the segment in [0, 2π); 0 for a degenerate segment, as the reference.
  double theta = 0.0;
  if (dx != 0.0 || dy != 0.0) {
    theta = std::atan2(dy, dx);
    if (theta < 0.0) theta += kTwoPi;
  }
  const double theta_bins = theta * kBinsPerRad;
  const double radius = std::max(v.length / (kDimension + 1), 2.0);
  v.level = scale.level_for_radius(radius);
  const ScaleLevel& lv = scale.level(v.level);
  const double ratio = lv.ratio;
  const double r = radius / ratio;
  const double r2 = r * r;
  const double inv_s = 1.0 / (4.5 * r2);
  const int w = lv.width, h = lv.height;

  // Separable Gaussian factors: exp(-(dx²+dy²)/s) = exp(-dx²/s)·exp(-dy²/s).
  const int span = static_cast<int>(std::ceil(2.0 * r)) + 2;
  std::vector<double> ex(static_cast<std::size_t>(span)), ey(static_cast<std::size_t>(span));
  double raw_weight_sum = 0.0;
  for (int i = 0; i < kDimension; ++i) {
    const double t = static_cast<double>(i + 1) / (kDimension + 1);
    const double cx = (x1 + t * dx) / ratio;
    const double cy = (y1 + t * dy) / ratio;
    // Pixels strictly inside the one-pixel border: [1, w-2] × [1, h-2].
    const int xa = std::max(1, static_cast<int>(std::ceil(cx - r)));
    const int xb = std::min(w - 2, static_cast<int>(std::floor(cx + r)));
    const int ya = std::max(1, static_cast<int>(std::ceil(cy - r)));
    const int yb = std::min(h - 2, static_cast<int>(std::floor(cy + r)));
    double hist[kBinNum] = {};
    double* desc = v.descriptor.data() + kSubdirection * i;
    if (xa <= xb && ya <= yb) {
      for (int x = xa; x <= xb; ++x) {
        const double d = x - cx;
        ex[static_cast<std::size_t>(x - xa)] = std::exp(-d * d * inv_s);
      }
      for (int y = ya; y <= yb; ++y) {
        const double d = y - cy;
        ey[static_cast<std::size_t>(y - ya)] = std::exp(-d * d * inv_s);
      }
      for (int y = ya; y <= yb; ++y) {
        const double ddy = y - cy;
        const double rem = r2 - ddy * ddy;
        const double gy = ey[static_cast<std::size_t>(y - ya)];
        const float* ang = lv.angle.data() + static_cast<std::size_t>(y) * w;
        const float* mag = lv.magnitude.data() + static_cast<std::size_t>(y) * w;
        for (int x = xa; x <= xb; ++x) {
          const double ddx = x - cx;
          if (ddx * ddx > rem) continue;  // outside the disc
          const float m = mag[x];
          if (m == 0.0f) continue;  // contributes nothing (also the angle == -1 pixels)
          const double wgt = ex[static_cast<std::size_t>(x - xa)] * gy * m;
          double rel = ang[x] * kBinsPerRad - theta_bins;  // relative angle in 24-bin units
          if (rel < 0.0) rel += kBinNum;
          if (rel >= kBinNum) rel -= kBinNum;
          int b = static_cast<int>(rel + 0.5);
          if (b >= kBinNum) b = 0;  // nearest-bin rounding wraps to bin 0
          hist[b] += wgt;
          int s = static_cast<int>(rel / kRatioBins + 0.5);
          if (s >= kSubdirection) s = 0;
          desc[s] += wgt;
        }
      }
    }
    // Main orientation: bin maximising the difference with the opposite bin (first on ties).
    constexpr int half = kBinNum / 2;
    int best = 0;
    double best_val = hist[0] - hist[half];
    for (int b = 1; b < kBinNum; ++b) {
      const double val = hist[b] - hist[(b + half) % kBinNum];
      if (val > best_val) {
        best_val = val;
        best = b;
      }
    }
    v.main_bin[static_cast<std::size_t>(i)] = best;
    v.weight[static_cast<std::size_t>(i)] = best_val;
    raw_weight_sum += best_val;
  }
  double desc_sum = 0.0;
  for (double d : v.descriptor) desc_sum += d;
  if (desc_sum != 0.0) {
    for (double& d : v.descriptor) d /= desc_sum;
  }
  v.contrast = v.length > 0.0 ? raw_weight_sum / (v.length / ratio) : 0.0;
  if (raw_weight_sum != 0.0) {
    for (double& wv : v.weight) wv /= raw_weight_sum;
  }
  return v;
}

double vld_difference(const Vld& a, const Vld& b, double max_contrast) {
  if (!(a.contrast > 0.0) || !(b.contrast > 0.0) || a.contrast > max_contrast ||
      b.contrast > max_contrast) {
    return 128.0;
  }
  double desc = 0.0, orient = 0.0;
  for (std::size_t k = 0; k < a.descriptor.size(); ++k) {
    desc += std::abs(a.descriptor[k] - b.descriptor[k]);
  }
  for (std::size_t i = 0; i < static_cast<std::size_t>(kDimension); ++i) {
    const int d = std::abs(a.main_bin[i] - b.main_bin[i]);
    orient += std::min(d, kBinNum - d) * (a.weight[i] + b.weight[i]);
  }
  return 0.36 * desc + (0.64 / kBinNum) * orient;
}

double geometric_consistency(const Keypoint& a1, const Keypoint& a2, const Keypoint& b1,
                             const Keypoint& b2) {
  const double ax = a1.x - a2.x, ay = a1.y - a2.y;
  const double bx = b1.x - b2.x, by = b1.y - b2.y;
  const double nb = std::hypot(bx, by);
  const auto error = [&](const Keypoint& a, const Keypoint& b) {
    const double rot = b.angle - a.angle;
    const double s = b.scale / a.scale;
    const double c = std::cos(rot), sn = std::sin(rot);
    const double px = s * (c * ax - sn * ay), py = s * (sn * ax + c * ay);
    const double denom = std::min(std::hypot(px, py), nb);
    const double num = std::hypot(px - bx, py - by);
    if (denom == 0.0) return std::numeric_limits<double>::infinity();
    return num / denom;
  };
  return std::min(error(a1, b1), error(a2, b2));
}

}  // namespace geodrift::kvld
