// Association of result poses with ground-truth poses before evaluation: by timestamp (nearest
// ground-truth time within a tolerance, as evo does for TUM files) or by frame number.
// Conventions: times in seconds; the offset is added to the RESULT's timestamps (evo's
// --t_offset); inputs are plain vectors in file order, indices in the output point into them.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <iterator>
#include <limits>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::eval {

/// How result poses were paired with ground-truth poses.
struct Association {
  /// Matched pairs (result_index[k], gt_index[k]); both strictly increasing in k, so the matched
  /// sequence keeps the order of both trajectories.
  std::vector<std::size_t> result_index;
  std::vector<std::size_t> gt_index;
  /// Per pair: gt_time − (result_time + offset), seconds (0 for frame association).
  std::vector<double> time_diff_s;
  /// Result poses left without ground truth, increasing.
  std::vector<std::size_t> unmatched_result;
  /// Of those, how many had a ground-truth pose within the tolerance that a closer result pose
  /// took (time association only; 0 otherwise).
  std::size_t lost_to_closer = 0;

  std::size_t matched() const { return result_index.size(); }
  std::size_t unmatched() const { return unmatched_result.size(); }
  /// Largest |time_diff_s|, 0 when nothing matched.
  double max_abs_time_diff_s() const {
    double m = 0.0;
    for (double d : time_diff_s) m = std::max(m, std::abs(d));
    return m;
  }
};

/// Options of associate_by_time().
struct TimeAssociationOptions {
  /// Largest |gt_time − (result_time + offset)| accepted, seconds (evo's default --t_max_diff).
  double max_time_diff_s = 0.01;
  /// Added to every result timestamp before matching, seconds (evo's --t_offset).
  double time_offset_s = 0.0;
};

namespace detail {
/// Throws unless every time is finite and the sequence strictly increases; `what` names it.
inline void check_increasing_times(const std::vector<double>& t, const char* what) {
  for (std::size_t i = 0; i < t.size(); ++i) {
    GEODRIFT_CHECK(std::isfinite(t[i]), what << " timestamp " << i << " is not finite");
    GEODRIFT_CHECK(i == 0 || t[i] > t[i - 1], what << " timestamp " << i << " (" << t[i]
                                                   << " s) does not increase (previous " << t[i - 1]
                                                   << " s)");
  }
}
}  // namespace detail

/// Pairs each result pose with the ground-truth pose nearest in time.
///
/// Rule (order-independent, deterministic):
///  1. For result pose i, let τ = result_t[i] + time_offset_s and j(i) the ground-truth pose
///     whose time is nearest to τ (on an exact tie, the earlier one).
///  2. The candidate (i, j(i)) is kept only if |gt_t[j(i)] − τ| ≤ max_time_diff_s.
///  3. Each ground-truth pose is used at most once: when several result poses have the same
///     j, the one nearest in time keeps it (on a tie, the earlier result pose); the others are
///     unmatched (counted in lost_to_closer) and are NOT re-paired with their second-nearest
///     ground truth.
/// Unlike evo, which searches from the shorter trajectory, the search always runs from the
/// result, so every result pose is either matched or counted as unmatched.
/// Since both inputs increase, j(i) is non-decreasing and the kept pairs increase in both
/// indices. Cost O(n log m).
///
/// @param result_t result timestamps, seconds, strictly increasing, finite (may be empty).
/// @param gt_t     ground-truth timestamps, seconds, strictly increasing, finite (may be empty).
/// @throws InvalidArgument for a non-finite or non-increasing timestamp (naming the index), a
///         max_time_diff_s that is negative or not finite, or a non-finite time_offset_s.
inline Association associate_by_time(const std::vector<double>& result_t,
                                     const std::vector<double>& gt_t,
                                     const TimeAssociationOptions& opt = {}) {
  GEODRIFT_CHECK(std::isfinite(opt.max_time_diff_s) && opt.max_time_diff_s >= 0.0,
                 "max_time_diff_s " << opt.max_time_diff_s << " must be finite and >= 0");
  GEODRIFT_CHECK(std::isfinite(opt.time_offset_s),
                 "time_offset_s " << opt.time_offset_s << " is not finite");
  detail::check_increasing_times(result_t, "result");
  detail::check_increasing_times(gt_t, "ground-truth");

  constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
  const std::size_t n = result_t.size();
  // Steps 1-2: nearest ground truth within the tolerance.
  std::vector<std::size_t> cand(n, kNone);
  std::vector<double> diff(n, 0.0);
  for (std::size_t i = 0; i < n && !gt_t.empty(); ++i) {
    const double tau = result_t[i] + opt.time_offset_s;
    const auto it = std::lower_bound(gt_t.begin(), gt_t.end(), tau);  // first gt >= tau
    std::size_t j = static_cast<std::size_t>(std::distance(gt_t.begin(), it));
    if (j == gt_t.size() || (j > 0 && tau - gt_t[j - 1] <= gt_t[j] - tau)) --j;
    const double d = gt_t[j] - tau;
    if (std::abs(d) <= opt.max_time_diff_s) {
      cand[i] = j;
      diff[i] = d;
    }
  }
  // Step 3: candidates sharing a j are adjacent (j(i) is non-decreasing); keep the nearest.
  Association a;
  std::size_t i = 0;
  while (i < n) {
    if (cand[i] == kNone) {
      a.unmatched_result.push_back(i);
      ++i;
      continue;
    }
    std::size_t end = i, best = i;
    while (end < n && cand[end] == cand[i]) {
      if (std::abs(diff[end]) < std::abs(diff[best])) best = end;
      ++end;
    }
    for (std::size_t k = i; k < end; ++k) {
      if (k == best) {
        a.result_index.push_back(k);
        a.gt_index.push_back(cand[k]);
        a.time_diff_s.push_back(diff[k]);
      } else {
        a.unmatched_result.push_back(k);
        ++a.lost_to_closer;
      }
    }
    i = end;
  }
  return a;
}

/// Pairs result and ground-truth poses with equal frame numbers (KITTI: leading index or line
/// order). Frame numbers must strictly increase on each side.
/// @throws InvalidArgument naming the index of a frame number that does not increase.
inline Association associate_by_frame(const std::vector<int>& result_frame,
                                      const std::vector<int>& gt_frame) {
  for (std::size_t i = 1; i < result_frame.size(); ++i)
    GEODRIFT_CHECK(result_frame[i] > result_frame[i - 1],
                   "result frame " << result_frame[i] << " at index " << i
                                   << " does not increase (previous " << result_frame[i - 1]
                                   << ")");
  for (std::size_t j = 1; j < gt_frame.size(); ++j)
    GEODRIFT_CHECK(gt_frame[j] > gt_frame[j - 1], "ground-truth frame "
                                                      << gt_frame[j] << " at index " << j
                                                      << " does not increase (previous "
                                                      << gt_frame[j - 1] << ")");
  Association a;
  std::size_t j = 0;
  for (std::size_t i = 0; i < result_frame.size(); ++i) {
    while (j < gt_frame.size() && gt_frame[j] < result_frame[i]) ++j;
    if (j < gt_frame.size() && gt_frame[j] == result_frame[i]) {
      a.result_index.push_back(i);
      a.gt_index.push_back(j);
      a.time_diff_s.push_back(0.0);
    } else {
      a.unmatched_result.push_back(i);
    }
  }
  return a;
}

}  // namespace geodrift::eval
