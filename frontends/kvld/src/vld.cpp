// Virtual line descriptor (kvld.md §3.3) and the geometric consistency test (§3.4).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/kvld/kvld.hpp"

namespace geodrift::kvld {
namespace {
constexpr double kTwoPi = 6.283185307179586476925286766559;
constexpr double kBinsPerRad = kBinNum / kTwoPi;
constexpr int kRatioBins = kBinNum / kSubdirection;  // 24-bin units per 8-bin unit
static_assert(kRatioBins == 3, "the descriptor folding below sums three 24-bins per 8-bin");
static_assert(kBinNum % 2 == 0, "binNum must be even");
static_assert(kBinNum % kSubdirection == 0, "8-bin index is derived from the 24-bin position");
}  // namespace

Vld compute_vld(const ImageScale& scale, double x1, double y1, double x2, double y2) {
  GEODRIFT_CHECK(std::isfinite(x1) && std::isfinite(y1) && std::isfinite(x2) && std::isfinite(y2),
                 "kvld::compute_vld: non-finite endpoint (" << x1 << ", " << y1 << ") -> (" << x2
                                                            << ", " << y2 << ")");
  Vld v;
  const double dx = x2 - x1, dy = y2 - y1;
  v.length = std::sqrt(dx * dx + dy * dy);
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

  // Separable Gaussian factors: exp(-(dx²+dy²)/s) = exp(-dx²/s)·exp(-dy²/s). Small discs
  // (the usual case) use the stack.
  const int span = static_cast<int>(std::ceil(2.0 * r)) + 2;
  constexpr int kStack = 96;
  float ex_stack[2 * kStack];  // Gaussian column factors, then (x - cx)²
  std::vector<float> ex_heap;
  float* ex = ex_stack;
  if (span > kStack) {
    ex_heap.resize(2 * static_cast<std::size_t>(span));
    ex = ex_heap.data();
  }
  float* dx2 = ex + std::max(span, kStack);
  float wbuf[kStack];
  const auto theta_f = static_cast<float>(theta_bins);
  int bbuf[kStack];
  const double q = std::exp(-2.0 * inv_s);
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
    // Accumulators split by x mod 4: neighbouring pixels usually share a bin, and a single
    // array would serialise the read-modify-write chain through memory.
    constexpr int kLanes = 4;
    double hist_l[kLanes][kBinNum] = {};
    if (xa <= xb && ya <= yb) {
      // Gaussian factors on the integer grid by the recurrence
      // e(x+1) = e(x)·g(x), g(x+1) = g(x)·q with g(x) = exp(-(2(x-c)+1)/s), q = exp(-2/s):
      // three exp() per axis and disc instead of one per column and row.
      {
        const double d = xa - cx;
        double e = std::exp(-d * d * inv_s), g = std::exp(-(2.0 * d + 1.0) * inv_s);
        for (int x = xa; x <= xb; ++x) {
          ex[x - xa] = static_cast<float>(e);
          dx2[x - xa] = static_cast<float>((x - cx) * (x - cx));
          e *= g;
          g *= q;
        }
      }
      const double dy0 = ya - cy;
      double gy = std::exp(-dy0 * dy0 * inv_s), gstep = std::exp(-(2.0 * dy0 + 1.0) * inv_s);
      for (int y = ya; y <= yb; ++y, gy *= gstep, gstep *= q) {
        const double ddy = y - cy;
        const auto rem = static_cast<float>(r2 - ddy * ddy);
        if (rem < 0.0f) continue;
        const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
        const float* ang = lv.angle_bins.data() + row;
        const float* mag = lv.magnitude.data() + row;
        // Whole bounding-box rows with a 0/1 disc mask: branch-free and vectorised; the
        // pixels outside the disc then add 0 to the histogram.
        for (int c0 = xa; c0 <= xb; c0 += kStack) {
          const int len = std::min(kStack, xb - c0 + 1);
          const float* exr = ex + (c0 - xa);
          const float* dxr = dx2 + (c0 - xa);
          const float* angr = ang + c0;
          const float* magr = mag + c0;
          const auto gyf = static_cast<float>(gy);
          // Single precision here, as the reference (float orientations and main angle).
          for (int k = 0; k < len; ++k) {
            const float inside = static_cast<float>(dxr[k] <= rem);
            wbuf[k] = inside * exr[k] * gyf * magr[k];  // 0 outside the disc or where |∇I| = 0
            float rel = angr[k] - theta_f;              // relative angle in 24-bin units, (-24, 24)
            rel += static_cast<float>(kBinNum) * static_cast<float>(rel < 0.0f);  // branch-free
            const int b = static_cast<int>(rel + 0.5f);
            bbuf[k] = b - kBinNum * (b >= kBinNum);  // nearest-bin rounding wraps to bin 0
          }
          for (int k = 0; k < len; ++k) {
            hist_l[k & (kLanes - 1)][bbuf[k]] += wbuf[k];
          }
        }
      }
    }
    double hist[kBinNum];
    for (int b = 0; b < kBinNum; ++b) {
      hist[b] = (hist_l[0][b] + hist_l[1][b]) + (hist_l[2][b] + hist_l[3][b]);
    }
    // The 8-bin index is a function of the 24-bin one: round(rel/3) = s exactly when
    // round(rel) ∈ {3s−1, 3s, 3s+1} (mod 24), so each descriptor bin sums three 24-bins.
    double* desc = v.descriptor.data() + kSubdirection * i;
    for (int sb = 0; sb < kSubdirection; ++sb) {
      const int c = kRatioBins * sb;
      desc[sb] = hist[(c + kBinNum - 1) % kBinNum] + hist[c] + hist[c + 1];
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
  const double nb = std::sqrt(bx * bx + by * by);
  const auto error = [&](const Keypoint& a, const Keypoint& b) {
    const double rot = b.angle - a.angle;
    const double s = b.scale / a.scale;
    const double c = std::cos(rot), sn = std::sin(rot);
    const double px = s * (c * ax - sn * ay), py = s * (sn * ax + c * ay);
    const double denom = std::min(std::sqrt(px * px + py * py), nb);
    const double num = std::sqrt((px - bx) * (px - bx) + (py - by) * (py - by));
    if (denom == 0.0) return std::numeric_limits<double>::infinity();
    return num / denom;
  };
  return std::min(error(a1, b1), error(a2, b2));
}

}  // namespace geodrift::kvld
