#pragma once

/// @file
/// map::Map: a whole reconstruction in its own frame M (arbitrary scale and orientation):
/// cameras, keyframes (T_cw, M -> camera), points (in M) and observations (pixels). Also
/// covisibility() (keyframe pairs that share points). This is the interchange type between a
/// front end, io/ (COLMAP text model) and the Corrector, which copies it and never rewrites it.

#include <algorithm>
#include <map>
#include <unordered_map>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/map/camera.hpp"
#include "geodrift/map/correspondence.hpp"
#include "geodrift/map/geotag.hpp"
#include "geodrift/map/keyframe.hpp"
#include "geodrift/map/map_point.hpp"

namespace geodrift::map {

/// A reconstruction in its own frame M (arbitrary scale): cameras, keyframes, points,
/// observations. This is what the front end (ours or a user's SLAM, through io/) hands to the
/// Corrector; the Corrector copies it and never rewrites the front end's map.
/// Keyframes are kept in the order they were added (= time order).
struct Map {
  std::vector<Camera> cameras;
  std::vector<Keyframe> keyframes;
  std::vector<MapPoint> points;
  std::vector<Observation> observations;

  /// Index of keyframe `id` in `keyframes`, or -1.
  int keyframe_index(int id) const {
    for (std::size_t i = 0; i < keyframes.size(); ++i)
      if (keyframes[i].id == id) return static_cast<int>(i);
    return -1;
  }

  /// Checks ids are unique and every observation names an existing keyframe and point, and
  /// every value is finite. @throws InvalidArgument naming the first offending element.
  void validate() const {
    std::unordered_map<int, int> kf, pt, cam;
    for (const Camera& c : cameras) {
      c.validate();
      GEODRIFT_CHECK(cam.emplace(c.id, 0).second, "camera id " << c.id << " appears twice");
    }
    for (const Keyframe& k : keyframes) {
      GEODRIFT_CHECK(kf.emplace(k.id, 0).second, "keyframe id " << k.id << " appears twice");
      GEODRIFT_CHECK(cam.count(k.camera_id) || cameras.empty(),
                     "keyframe " << k.id << " names unknown camera " << k.camera_id);
      GEODRIFT_CHECK(k.T_cw.matrix().allFinite(), "keyframe " << k.id << " pose is not finite");
    }
    for (const MapPoint& p : points) {
      GEODRIFT_CHECK(pt.emplace(p.id, 0).second, "map point id " << p.id << " appears twice");
      GEODRIFT_CHECK(p.position.allFinite(), "map point " << p.id << " position is not finite");
    }
    for (const Observation& o : observations) {
      GEODRIFT_CHECK(kf.count(o.keyframe), "observation of point " << o.point
                                                                   << " names unknown keyframe "
                                                                   << o.keyframe);
      GEODRIFT_CHECK(pt.count(o.point), "observation in keyframe "
                                            << o.keyframe << " names unknown point " << o.point);
      GEODRIFT_CHECK(o.pixel.allFinite(), "observation (keyframe " << o.keyframe << ", point "
                                                                   << o.point
                                                                   << ") pixel not finite");
    }
  }
};

/// Covisibility: keyframe pairs (id_a < id_b) that observe at least `min_shared_points` common
/// map points (DESIGN.md; ORB-SLAM's essential graph uses 100), with the shared count.
/// O(observations · mean covisible degree).
inline std::vector<std::pair<std::pair<int, int>, int>> covisibility(
    const std::vector<Observation>& observations, int min_shared_points = 15) {
  GEODRIFT_CHECK(min_shared_points >= 1,
                 "min_shared_points " << min_shared_points << " must be >= 1");
  std::unordered_map<int, std::vector<int>> seen_by;  // point -> keyframes
  for (const Observation& o : observations) seen_by[o.point].push_back(o.keyframe);
  std::map<std::pair<int, int>, int> shared;
  for (auto& [point, kfs] : seen_by) {
    std::sort(kfs.begin(), kfs.end());
    kfs.erase(std::unique(kfs.begin(), kfs.end()), kfs.end());
    for (std::size_t a = 0; a < kfs.size(); ++a)
      for (std::size_t b = a + 1; b < kfs.size(); ++b) ++shared[{kfs[a], kfs[b]}];
  }
  std::vector<std::pair<std::pair<int, int>, int>> out;
  for (const auto& [pair, n] : shared)
    if (n >= min_shared_points) out.push_back({pair, n});
  return out;
}

}  // namespace geodrift::map
