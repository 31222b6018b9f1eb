#pragma once

/// @file
/// Choosing CorrectorOptions::local_scale_sd, the SD of a VO's local, mean-reverting scale
/// error, from the run's own anchors: two-fold cross-validation.
///
/// The size of that error is a property of the VO (its tracker, the scene's depth structure),
/// differs by an order of magnitude between VOs (docs/correction_model.md), and cannot be read
/// from the VO's output alone. The anchors can tell it: a model that describes the VO's drift
/// predicts an anchor it was not given from its neighbours better than one that does not. The
/// anchors after INIT's are split by alternate order into two folds; each candidate SD is
/// run (INIT + sliding-window PGO, the mode's pose graph) on the anchors outside one fold and
/// scored by where its corrected path puts each anchor of that fold (horizontal distance to the
/// geo-tag, RMS over both folds). Only anchors that lie between two anchors of the run count:
/// beyond the last one the path is extrapolated, which scores the tail, not the model. The
/// candidate with the lowest RMS is chosen; on a tie the smaller SD (the simpler model).
///
/// The folds have twice the anchor spacing of the full run, so the choice describes the VO at
/// that spacing; the drift model's parameters do not depend on the spacing.

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/correction/replay.hpp"
#include "geodrift/error.hpp"
#include "geodrift/map/map.hpp"

namespace geodrift::correction {

/// What choose_local_scale() decided, and from what.
struct LocalScaleChoice {
  double sd = 0.0;                 ///< the chosen CorrectorOptions::local_scale_sd
  bool cross_validated = false;    ///< false: `sd` is the options' value, `message` says why
  std::vector<double> candidates;  ///< SDs tried
  std::vector<double> rms_m;       ///< held-out horizontal RMS per candidate [m] (NaN: failed)
  int held_out = 0;                ///< anchors predicted per candidate (both folds)
  std::string message;
};

/// The candidate SDs tried by default: off, then 1-8 % (a car-mounted monocular VO's local
/// scale error ranges from well under 1 % to ~8 % over 50 m, docs/correction_model.md).
inline std::vector<double> default_local_scale_candidates() {
  return {0.0, 0.01, 0.02, 0.04, 0.08};
}

/// Chooses CorrectorOptions::local_scale_sd for `options` on map `m` with the anchors in use
/// `anchors` (after any screening; the order does not matter). Needs the metric weights and a
/// mode with a pose graph (ours, init+pgo, batch), and at least `min_held_out` anchors that can
/// be predicted; otherwise returns options.local_scale_sd with the reason. Runs
/// 2 × candidates corrections (INIT + PGO, no BA), so it is skipped (with the reason) above
/// `max_anchors` anchors or `max_keyframes` keyframes, where it would cost minutes: with anchors
/// that dense the path is pinned by them and the drift model between them matters little; a
/// fixed --local-scale SD can still be given.
inline LocalScaleChoice choose_local_scale(
    const map::Map& m, const std::vector<map::Correspondence>& anchors,
    const CorrectorOptions& options,
    std::vector<double> candidates = default_local_scale_candidates(), int min_held_out = 4,
    int max_anchors = 2000, int max_keyframes = 20000) {
  LocalScaleChoice out;
  out.sd = options.local_scale_sd;
  out.candidates = candidates;
  if (options.edge_weights != CorrectorOptions::EdgeWeights::kPaperMetric) {
    out.message = "local scale offsets are used with the metric weights only";
    return out;
  }
  if (!uses_pose_graph(options.mode)) {
    out.message = std::string("mode ") + to_string(options.mode) + " has no pose graph";
    return out;
  }
  if (static_cast<int>(anchors.size()) > max_anchors ||
      static_cast<int>(m.keyframes.size()) > max_keyframes) {
    out.message = std::to_string(anchors.size()) + " anchors on " +
                  std::to_string(m.keyframes.size()) + " keyframes: more than " +
                  std::to_string(max_anchors) + " / " + std::to_string(max_keyframes) +
                  ", not cross-validated (it runs 10 corrections)";
    return out;
  }
  // Anchors in keyframe order (the order replay() hands them over); INIT's first four are
  // never held out (INIT needs them), the rest alternate between the folds.
  std::unordered_map<int, int> kf_pos;
  for (std::size_t i = 0; i < m.keyframes.size(); ++i)
    kf_pos[m.keyframes[i].id] = static_cast<int>(i);
  std::vector<std::pair<int, int>> order;  // (keyframe position, anchor index)
  for (std::size_t j = 0; j < anchors.size(); ++j) {
    const auto it = kf_pos.find(anchors[j].keyframe);
    if (it != kf_pos.end()) order.emplace_back(it->second, static_cast<int>(j));
  }
  std::stable_sort(order.begin(), order.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  constexpr int kInitAnchors = 4;
  const int n = static_cast<int>(order.size());
  if (n - kInitAnchors < 2 * min_held_out + 2) {
    out.message = std::to_string(n) + " anchors: too few to cross-validate (need " +
                  std::to_string(kInitAnchors + 2 * min_held_out + 2) + ")";
    return out;
  }
  CorrectorOptions o = options;
  o.mode = Mode::kInitPgo;
  o.gate_anchors = false;  // the caller's screening already decided which anchors are in use
  std::vector<double> sum(candidates.size(), 0.0);
  std::vector<int> count(candidates.size(), 0);
  std::vector<bool> failed(candidates.size(), false);
  for (std::size_t c = 0; c < candidates.size(); ++c) {
    o.local_scale_sd = candidates[c];
    for (int fold = 0; fold < 2; ++fold) {
      std::vector<map::Correspondence> train;
      std::vector<int> test;
      int last_train = -1;
      for (int i = 0; i < n; ++i) {
        const bool held = i >= kInitAnchors && (i - kInitAnchors) % 2 == fold;
        if (held) {
          test.push_back(i);
        } else {
          train.push_back(anchors[order[i].second]);
          last_train = order[i].first;
        }
      }
      Corrector corrector(o);
      try {
        replay(m, train, &corrector);
      } catch (const Error&) {
        failed[c] = true;
        break;
      }
      if (!corrector.initialized()) {
        failed[c] = true;
        break;
      }
      for (int i : test) {
        if (order[i].first >= last_train) continue;  // extrapolated: not scored
        const map::Correspondence& a = anchors[order[i].second];
        const lie::Sim3d S_k = corrector.keyframe_sim3(order[i].first);
        const Eigen::Vector3d centre = (lie::Sim3d(a.T_vk) * S_k).inverse().translation();
        const Eigen::Vector2d e = (centre - a.y_w).head<2>();
        if (!e.allFinite()) {
          failed[c] = true;
          break;
        }
        sum[c] += e.squaredNorm();
        ++count[c];
      }
      if (failed[c]) break;
    }
  }
  out.rms_m.assign(candidates.size(), std::numeric_limits<double>::quiet_NaN());
  int best = -1;
  for (std::size_t c = 0; c < candidates.size(); ++c) {
    if (failed[c] || count[c] == 0) continue;
    out.rms_m[c] = std::sqrt(sum[c] / count[c]);
    out.held_out = count[c];
    if (best < 0 || out.rms_m[c] < out.rms_m[best] ||
        (out.rms_m[c] == out.rms_m[best] && candidates[c] < candidates[best]))
      best = static_cast<int>(c);
  }
  if (best < 0 || out.held_out < min_held_out) {
    out.message = "cross-validation predicted " + std::to_string(out.held_out) + " anchors (need " +
                  std::to_string(min_held_out) + "); kept " +
                  std::to_string(options.local_scale_sd);
    return out;
  }
  out.sd = candidates[best];
  out.cross_validated = true;
  return out;
}

}  // namespace geodrift::correction
