#pragma once

/// @file
/// map::MapPoint (a triangulated point in the map frame M, M's unit, with its reference
/// keyframe) and map::Observation (a point seen in a keyframe, pixels of its undistorted
/// image). A point moves with its reference keyframe's correction (DESIGN.md).

#include <Eigen/Core>

namespace geodrift::map {

/// A triangulated map point in M. It moves with its reference keyframe's correction
/// (DESIGN.md: X' = S_new⁻¹ · S_old · X).
struct MapPoint {
  int id = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  ///< in M
  int reference_keyframe = -1;                         ///< Keyframe::id
};

/// One measurement of a map point in a keyframe, in pixels of that keyframe's (undistorted)
/// camera.
struct Observation {
  int keyframe = -1;  ///< Keyframe::id
  int point = -1;     ///< MapPoint::id
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

}  // namespace geodrift::map
