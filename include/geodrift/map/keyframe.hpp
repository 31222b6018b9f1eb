#pragma once

/// @file
/// map::Keyframe: one keyframe of the reconstruction, with its pose T_cw (map frame M -> camera,
/// SE(3), in M's arbitrary unit; ORB-SLAM's convention, DESIGN.md), its video frame index and
/// timestamp (seconds). The camera centre is T_cw⁻¹·0, in M.

#include <sstream>
#include <string>

#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"

namespace geodrift::map {

/// Largest |coordinate| accepted in M (keyframe translations, map points), in map units. M's
/// unit is arbitrary, but beyond 1e12 a double resolves at best 1e-4 units, so a trajectory
/// that moves by metres there has already lost its shape; in practice such values are a corrupt
/// file or a unit mix-up, and letting them in overflows the pose graph's weights.
inline constexpr double kMaxMapCoordinate = 1e12;

/// @throws InvalidArgument "<who>: <noun> <id> <field> (x y z) ..." when `v` is not finite or one
/// of its
///         coordinates exceeds kMaxMapCoordinate in magnitude.
template <typename Derived>
void check_map_coordinates(const Eigen::MatrixBase<Derived>& v, const std::string& who,
                           const char* noun, int id, const char* field) {
  if (v.allFinite() && v.cwiseAbs().maxCoeff() <= kMaxMapCoordinate) return;
  std::ostringstream os;
  os << who << ": " << noun << " " << id << " " << field << " (" << v.transpose() << ") ";
  if (!v.allFinite())
    os << "is not finite";
  else
    os << "exceeds " << kMaxMapCoordinate
       << " map units in magnitude (a corrupt value or a unit mix-up?)";
  ::geodrift::detail::throw_invalid_argument(os.str());
}

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
