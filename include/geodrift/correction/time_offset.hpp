#pragma once

/// @file
/// A constant offset between the anchors' clock and the trajectory's, estimated from the path's
/// shape (what a surveyor checks first when GNSS fixes and camera frames come from two devices:
/// a logging latency of a fraction of a second, or GPS time against UTC, 18 s since 2017).
///
/// An anchor stamped t_a by its own clock was taken when the trajectory's clock read t_a + τ.
/// With the wrong τ, every anchor is compared with the camera where it was τ seconds earlier or
/// later: on a straight road at constant speed that is a shift along the road, which the
/// correction absorbs as drift; where the path turns or the speed changes it is not. Hence:
/// the anchors are cut into disjoint windows of kTimeOffsetWindow consecutive anchors; within a
/// window the VO path differs from the true one by a similarity (its drift over a few hundred
/// metres is small against a turn); F(τ) is the sum over windows of the squared residuals of the
/// best 3D similarity (Umeyama) from the VO camera centres at t_a + τ (linear in time between
/// poses) to the anchors, each window fitted without the one anchor whose leaving out fits best
/// (a wrong geo-tag in the window); a window whose best fit over all τ stays above 3× the median
/// window's RMS (two or more wrong anchors) is left out. τ̂ minimises F over ±T (a grid of step
/// T/100, then a golden-section refinement); the residual variance s² = F(τ̂)/dof holds the drift
/// inside the windows and the anchors' noise alike; the test statistic (F(0) − F(τ̂))/s² is a
/// likelihood ratio for τ = 0 (one parameter), and sd(τ̂) = √(2·s²/F''(τ̂)). Windows whose VO centres
/// are collinear at some τ of the grid (a straight road: the fit's rotation about it is free) are
/// left out; a path with none left has no observable offset.
///
/// Frames: VO camera centres in the trajectory's own frame and unit (any; a similarity per
/// window removes both), anchor positions in W [m].

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/eval/umeyama.hpp"

namespace geodrift::correction {

/// Anchors per window: the best-fitting 4 of them enter the fit, whose 12 coordinates leave 5
/// residual degrees of freedom to a 3D similarity's 7.
inline constexpr int kTimeOffsetWindow = 5;
/// The likelihood-ratio statistic above which the offset is reported: 25, a 5σ departure (the
/// windows' residuals are not white, the drift inside them is correlated, so the nominal 1e-6
/// false-alarm rate of χ²₁ is not claimed).
inline constexpr double kTimeOffsetSignificance = 25.0;
/// Default search half-width: at most this many seconds, and at most an eighth of the
/// trajectory's duration (the anchors within T of either end are left out of the estimate).
inline constexpr double kTimeOffsetMaxSearch = 20.0;

struct TimeOffsetEstimate {
  bool estimated = false;  ///< false: too few usable anchors or windows; `reason` says why
  std::string reason;
  double offset = 0.0;  ///< τ̂ [s]: trajectory time = anchor time + τ̂ fits best
  double sd = std::numeric_limits<double>::infinity();  ///< of τ̂ [s]
  double searched = 0.0;                                ///< T: τ was searched in [−T, T] [s]
  int anchors = 0;  ///< anchors in the windows' fits (4 of each window's 5)
  int windows = 0;
  /// Windows left out because even their best fit is far off (two or more wrong anchors).
  int windows_left_out = 0;
  double rms_at_zero = std::numeric_limits<double>::quiet_NaN();  ///< √(F(0)/(3·anchors)) [m]
  double rms_at_estimate = std::numeric_limits<double>::quiet_NaN();  ///< √(F(τ̂)/(3·anchors))
  double statistic = 0.0;                                             ///< (F(0) − F(τ̂))/s²
  /// statistic > kTimeOffsetSignificance and |τ̂| above half the median pose interval (an
  /// offset within one frame moves no anchor by more than the path moves in a frame).
  bool significant = false;
  /// τ̂ at the edge of the search: the offset may be larger still. An offset far beyond ±T
  /// leaves no trace at the edge: F's minimum over ±T is then wherever the misplaced anchors
  /// happen to fit best (measured: −18 s searched over ±10 s gave an interior minimum).
  bool at_edge = false;
};

namespace detail {
/// Linear interpolation of the centres at time t ∈ [times.front(), times.back()].
inline Eigen::Vector3d centre_at(const std::vector<double>& times,
                                 const std::vector<Eigen::Vector3d>& centres, double t) {
  const auto hi = std::upper_bound(times.begin(), times.end(), t);
  if (hi == times.end()) return centres.back();
  if (hi == times.begin()) return centres.front();
  const std::size_t j = static_cast<std::size_t>(hi - times.begin());
  const double f = (t - times[j - 1]) / (times[j] - times[j - 1]);
  return (1.0 - f) * centres[j - 1] + f * centres[j];
}
}  // namespace detail

/// Estimates the anchors' clock offset (see the file comment).
/// @param pose_times strictly increasing trajectory times [s], one per centre.
/// @param centres the VO camera centres.
/// @param anchor_times, anchor_positions the anchors placed by time (any order), in W.
/// @param max_offset T [s]; ≤ 0 for the default min(kTimeOffsetMaxSearch, duration/8).
/// @throws InvalidArgument on mismatched sizes or non-finite values.
inline TimeOffsetEstimate estimate_anchor_time_offset(
    const std::vector<double>& pose_times, const std::vector<Eigen::Vector3d>& centres,
    const std::vector<double>& anchor_times, const std::vector<Eigen::Vector3d>& anchor_positions,
    double max_offset = 0.0) {
  GEODRIFT_CHECK(pose_times.size() == centres.size(),
                 "estimate_anchor_time_offset: " << pose_times.size() << " times but "
                                                 << centres.size() << " centres");
  GEODRIFT_CHECK(anchor_times.size() == anchor_positions.size(),
                 "estimate_anchor_time_offset: " << anchor_times.size() << " anchor times but "
                                                 << anchor_positions.size() << " positions");
  TimeOffsetEstimate out;
  const std::size_t np = pose_times.size();
  if (np < 2) {
    out.reason = "fewer than 2 poses";
    return out;
  }
  for (std::size_t i = 0; i < np; ++i) {
    GEODRIFT_CHECK(std::isfinite(pose_times[i]) && centres[i].allFinite(),
                   "estimate_anchor_time_offset: pose " << i << " is not finite");
    if (i > 0 && !(pose_times[i] > pose_times[i - 1])) {
      out.reason = "the trajectory's timestamps do not increase";
      return out;
    }
  }
  const double t0 = pose_times.front(), t1 = pose_times.back();
  const double T = max_offset > 0.0 ? max_offset : std::min(kTimeOffsetMaxSearch, (t1 - t0) / 8);
  out.searched = T;
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < anchor_times.size(); ++i) {
    GEODRIFT_CHECK(std::isfinite(anchor_times[i]) && anchor_positions[i].allFinite(),
                   "estimate_anchor_time_offset: anchor " << i << " is not finite");
    if (anchor_times[i] - T >= t0 && anchor_times[i] + T <= t1) order.push_back(i);
  }
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return anchor_times[a] < anchor_times[b]; });
  const std::size_t w = kTimeOffsetWindow;
  if (order.size() < 2 * w) {
    out.reason = std::to_string(order.size()) + " anchors with a timestamp at least " +
                 std::to_string(T) + " s from the trajectory's ends, " + std::to_string(2 * w) +
                 " are needed";
    return out;
  }
  std::vector<std::vector<std::size_t>> windows;
  for (std::size_t k = 0; k + w <= order.size(); k += w)
    windows.emplace_back(order.begin() + static_cast<std::ptrdiff_t>(k),
                         order.begin() + static_cast<std::ptrdiff_t>(k + w));
  // Per window at offset tau: the residual sum of squares of the best fit that leaves one anchor
  // out (a wrong anchor in the window is that one), or NaN if the centres are collinear.
  const auto window_ssr = [&](const std::vector<std::size_t>& win, double tau) {
    std::vector<Eigen::Vector3d> src_all;
    for (std::size_t i : win)
      src_all.push_back(detail::centre_at(pose_times, centres, anchor_times[i] + tau));
    double best = std::numeric_limits<double>::quiet_NaN();
    std::vector<Eigen::Vector3d> src, dst;
    for (std::size_t out_k = 0; out_k < win.size(); ++out_k) {
      src.clear();
      dst.clear();
      for (std::size_t k = 0; k < win.size(); ++k) {
        if (k == out_k) continue;
        src.push_back(src_all[k]);
        dst.push_back(anchor_positions[win[k]]);
      }
      const eval::Alignment a = eval::umeyama(src, dst, true);
      if (!a.ok()) return std::numeric_limits<double>::quiet_NaN();
      double ssr = 0.0;
      for (std::size_t k = 0; k < src.size(); ++k) ssr += (dst[k] - a.apply(src[k])).squaredNorm();
      if (!(ssr >= best)) best = ssr;  // also replaces the initial NaN
    }
    return best;
  };
  constexpr int kGrid = 100;  // grid points on each side of 0
  const double step = T / kGrid;
  std::vector<bool> keep(windows.size(), true);
  std::vector<std::vector<double>> grid(windows.size(), std::vector<double>(2 * kGrid + 1));
  for (std::size_t k = 0; k < windows.size(); ++k)
    for (int g = -kGrid; g <= kGrid && keep[k]; ++g) {
      grid[k][static_cast<std::size_t>(g + kGrid)] = window_ssr(windows[k], g * step);
      keep[k] = std::isfinite(grid[k][static_cast<std::size_t>(g + kGrid)]);
    }
  // A window whose best fit over every offset stays far above the others' holds two or more
  // wrong anchors: left out (RMS above 3× the median window's, and above 1 mm).
  {
    std::vector<double> best_ssr(windows.size(), 0.0), kept_best;
    for (std::size_t k = 0; k < windows.size(); ++k)
      if (keep[k]) {
        best_ssr[k] = *std::min_element(grid[k].begin(), grid[k].end());
        kept_best.push_back(best_ssr[k]);
      }
    if (!kept_best.empty()) {
      std::nth_element(kept_best.begin(),
                       kept_best.begin() + static_cast<std::ptrdiff_t>(kept_best.size() / 2),
                       kept_best.end());
      const double limit = std::max(9.0 * kept_best[kept_best.size() / 2], 1e-6 * 3 * (w - 1));
      for (std::size_t k = 0; k < windows.size(); ++k)
        if (keep[k] && best_ssr[k] > limit) {
          keep[k] = false;
          ++out.windows_left_out;
        }
    }
  }
  std::vector<std::vector<std::size_t>> used;
  for (std::size_t k = 0; k < windows.size(); ++k)
    if (keep[k]) used.push_back(windows[k]);
  out.windows = static_cast<int>(used.size());
  out.anchors = static_cast<int>(used.size() * (w - 1));
  if (used.size() < 2) {
    out.reason = std::to_string(used.size()) + " of " + std::to_string(windows.size()) +
                 " windows of " + std::to_string(w) +
                 " anchors where the path is not straight, 2 are needed (on a straight road at "
                 "constant speed a clock offset is a shift along it, not observable)";
    return out;
  }
  const auto F = [&](double tau) {
    double s = 0.0;
    for (const auto& win : used) s += window_ssr(win, tau);
    return s;
  };
  int best = 0;
  double f_best = std::numeric_limits<double>::infinity();
  for (int g = -kGrid; g <= kGrid; ++g) {
    double s = 0.0;
    for (std::size_t k = 0; k < windows.size(); ++k)
      if (keep[k]) s += grid[k][static_cast<std::size_t>(g + kGrid)];
    if (s < f_best) f_best = s, best = g;
  }
  // Golden-section refinement in the grid cell on either side of the best grid point.
  double a = (best - 1) * step, b = (best + 1) * step;
  a = std::max(a, -T);
  b = std::min(b, T);
  const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
  double c = b - phi * (b - a), d = a + phi * (b - a), fc = F(c), fd = F(d);
  for (int it = 0; it < 40; ++it) {
    if (fc < fd) {
      b = d, d = c, fd = fc;
      c = b - phi * (b - a);
      fc = F(c);
    } else {
      a = c, c = d, fc = fd;
      d = a + phi * (b - a);
      fd = F(d);
    }
  }
  double tau = 0.5 * (a + b), f_tau = F(tau);
  if (f_best < f_tau) tau = best * step, f_tau = f_best;  // the grid point, if the cell was flat
  const double f0 = F(0.0);
  const double dof = static_cast<double>(used.size() * (3 * (w - 1) - 7)) - 1.0;
  const double s2 = std::max(f_tau / dof, 1e-12 * (f0 / dof + 1e-300));
  const double delta = 0.25 * step;
  const double f2 = (F(tau + delta) - 2.0 * f_tau + F(tau - delta)) / (delta * delta);
  out.estimated = true;
  out.offset = tau;
  out.sd = f2 > 0.0 ? std::sqrt(2.0 * s2 / f2) : std::numeric_limits<double>::infinity();
  out.rms_at_zero = std::sqrt(f0 / (3.0 * out.anchors));
  out.rms_at_estimate = std::sqrt(f_tau / (3.0 * out.anchors));
  out.statistic = std::max(0.0, f0 - f_tau) / s2;
  std::vector<double> dt;
  for (std::size_t i = 1; i < np; ++i) dt.push_back(pose_times[i] - pose_times[i - 1]);
  std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(dt.size() / 2), dt.end());
  const double frame_dt = dt[dt.size() / 2];
  out.at_edge = std::abs(tau) >= T - step;
  out.significant = out.statistic > kTimeOffsetSignificance && std::abs(tau) > 0.5 * frame_dt;
  return out;
}

}  // namespace geodrift::correction
