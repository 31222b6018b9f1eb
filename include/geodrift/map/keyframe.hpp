#pragma once

/// @file
/// map::Keyframe: one keyframe of the reconstruction, with its pose T_cw (map frame M -> camera,
/// SE(3), in M's arbitrary unit; ORB-SLAM's convention, DESIGN.md), its video frame index and
/// timestamp (seconds). The camera centre is T_cw⁻¹·0, in M.

#include "geodrift/lie/se3.hpp"

namespace geodrift::map {

/// A keyframe of the reconstruction. `T_cw` maps map-frame (M) points into the camera frame
/// (x right, y down, z forward), as in ORB-SLAM; the camera centre is T_cw⁻¹·0.
struct Keyframe {
  int id = 0;              ///< unique, stable across the session
  int frame_index = 0;     ///< index of the video frame it was made from
  double timestamp = 0.0;  ///< seconds
  lie::SE3d T_cw;          ///< pose in M (world/map -> camera), units of M
  int camera_id = 0;       ///< map::Camera::id

  /// Camera centre in M.
  Eigen::Vector3d center() const { return T_cw.inverse().translation(); }
};

}  // namespace geodrift::map
