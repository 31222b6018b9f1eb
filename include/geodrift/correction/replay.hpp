#pragma once

/// @file
/// replay(): feeds a complete map::Map and its correspondences to a Corrector in the order a
/// SLAM system would have produced them (keyframes in time order, points after their reference
/// keyframe, correspondences after their keyframe), so `geodrift correct`, the experiment and
/// the tests all see the same stream as `geodrift run`. Everything stays in M as given.

#include <algorithm>
#include <functional>
#include <vector>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/map/map.hpp"

namespace geodrift::correction {

/// Streams a complete reconstruction into a Corrector in the order a SLAM system would have
/// produced it: keyframes in time order; each map point right after its reference keyframe
/// (with the observations of it that exist by then); each later observation with its
/// keyframe; each correspondence right after the keyframe it was localized against. Used by
/// `geodrift correct`, the experiment and the tests, so all of them see the same stream.
///
/// `on_keyframe(i)` (optional) is called after the i-th keyframe and everything attached to it
/// were added (progress display).
/// @throws InvalidArgument when the map or a correspondence is inconsistent (unknown ids).
inline void replay(const map::Map& m, const std::vector<map::Correspondence>& correspondences,
                   Corrector* corrector, const std::function<void(int)>& on_keyframe = {}) {
  m.validate();
  for (const map::Camera& c : m.cameras) corrector->add_camera(c);
  const int nk = static_cast<int>(m.keyframes.size());
  std::unordered_map<int, int> kf_pos;
  for (int i = 0; i < nk; ++i) kf_pos[m.keyframes[i].id] = i;
  std::unordered_map<int, int> pt_pos;
  for (std::size_t p = 0; p < m.points.size(); ++p) pt_pos[m.points[p].id] = static_cast<int>(p);

  // When each point becomes known: with its reference keyframe, or with its first observer if
  // the reference keyframe is unknown to the map (a point must not precede its keyframes).
  std::vector<int> point_time(m.points.size(), nk);
  for (std::size_t p = 0; p < m.points.size(); ++p) {
    const auto it = kf_pos.find(m.points[p].reference_keyframe);
    GEODRIFT_CHECK(it != kf_pos.end(), "map point " << m.points[p].id
                                                    << " names unknown reference keyframe "
                                                    << m.points[p].reference_keyframe);
    point_time[p] = it->second;
  }
  std::vector<std::vector<int>> points_at(nk), obs_at(nk), corr_at(nk);
  for (std::size_t p = 0; p < m.points.size(); ++p)
    points_at[point_time[p]].push_back(static_cast<int>(p));
  for (std::size_t o = 0; o < m.observations.size(); ++o) {
    const auto& ob = m.observations[o];
    const int t = std::max(kf_pos.at(ob.keyframe), point_time[pt_pos.at(ob.point)]);
    obs_at[t].push_back(static_cast<int>(o));
  }
  for (std::size_t j = 0; j < correspondences.size(); ++j) {
    const auto it = kf_pos.find(correspondences[j].keyframe);
    GEODRIFT_CHECK(it != kf_pos.end(), "correspondence " << correspondences[j].id
                                                         << " names unknown keyframe "
                                                         << correspondences[j].keyframe);
    corr_at[it->second].push_back(static_cast<int>(j));
  }
  for (int i = 0; i < nk; ++i) {
    corrector->add_keyframe(m.keyframes[i]);
    for (int p : points_at[i]) corrector->add_point(m.points[p]);
    for (int o : obs_at[i]) corrector->add_observation(m.observations[o]);
    for (int j : corr_at[i]) corrector->add_correspondence(correspondences[j]);
    if (on_keyframe) on_keyframe(i);
  }
  corrector->finish();
}

}  // namespace geodrift::correction
