#pragma once

/// @file
/// KITTI odometry ground truth -> geodrift's world frame W (DESIGN.md "Conventions").
///
/// KITTI poses (poses/XX.txt) are camera -> "KITTI world", where KITTI world is cam0 of frame 0
/// and both use the OpenCV camera convention (x right, y down, z forward). DESIGN.md fixes
///
///     cam0 of frame 0 is W's origin;   E = x,   N = z,   U = -y,
///
/// i.e. a point p_K in KITTI world is p_W = R_W_K · p_K with
///
///            [ 1  0  0 ]      columns: KITTI x -> +x (east)
///     R_W_K = [ 0  0  1 ]               KITTI y -> -z (down)
///            [ 0 -1  0 ]               KITTI z -> +y (north)
///
/// (det = +1, a proper rotation). A KITTI pose T_K_c = [R | t] (camera -> KITTI world) becomes
/// T_W_c = [R_W_K·R | R_W_K·t] (camera -> W); geodrift keeps T_cw = T_W_c⁻¹ in memory. The camera
/// frame itself is unchanged (still OpenCV), only the world axes are renamed.
///
/// For latitude/longitude output on KITTI data one assumed geo origin is used everywhere
/// (simulate, render, eval, demo): see kitti_local_frame().

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include "geodrift/error.hpp"
#include "geodrift/geo/local_frame.hpp"

namespace geodrift::geo {

/// Assumed latitude of KITTI cam0 at frame 0 (degrees): an assumption for display only.
inline constexpr double kKittiOriginLatitudeDeg = 49.0110;
/// Assumed longitude of KITTI cam0 at frame 0 (degrees): an assumption for display only.
inline constexpr double kKittiOriginLongitudeDeg = 8.4170;
/// Assumed ellipsoidal height of KITTI cam0 at frame 0 (m): an assumption for display only.
inline constexpr double kKittiOriginHeight = 160.0;
/// UTM zone of the assumed KITTI origin (zone 32, northern hemisphere).
inline constexpr int kKittiUtmZone = 32;
/// Assumed heading of the frame-0 optical axis in degrees: 0 = "north". With E = x, N = z the
/// frame-0 optical axis is exactly W's +y (GRID north of zone 32), so its TRUE heading is the
/// meridian convergence γ0 ≈ -0.44° at the origin (see kitti_local_frame()).
inline constexpr double kKittiFrame0HeadingDeg = 0.0;
/// One-line statement of the assumption, for the header/metadata of every output that uses it.
inline constexpr const char* kKittiGeoOriginNote =
    "KITTI geo origin is an ASSUMPTION for display: cam0 of frame 0 at 49.0110N 8.4170E, "
    "ellipsoidal height 160 m, UTM zone 32N, frame 0 optical axis = grid north (heading ~0 deg)";

/// R_W_K: KITTI world (x right, y down, z forward of cam0 at frame 0) -> W (east, north, up).
inline Eigen::Matrix3d kitti_to_world_rotation() {
  Eigen::Matrix3d R;
  R << 1.0, 0.0, 0.0,  //
      0.0, 0.0, 1.0,   //
      0.0, -1.0, 0.0;
  return R;
}

/// A point in KITTI world -> W: p_W = R_W_K · p_K (same origin, metres).
/// @throws InvalidArgument if p_K is not finite.
inline Eigen::Vector3d kitti_point_to_world(const Eigen::Vector3d& p_K) {
  GEODRIFT_CHECK(p_K.allFinite(),
                 "kitti_point_to_world: point p_K (" << p_K.transpose() << ") is not finite");
  return kitti_to_world_rotation() * p_K;
}

namespace detail {
/// Checks that a KITTI/W pose is finite with a rotation block orthonormal to 1e-6 and det +1.
inline void check_pose(const Eigen::Isometry3d& T, const char* what) {
  GEODRIFT_CHECK(T.matrix().allFinite(), what << ": pose is not finite:\n" << T.matrix());
  const Eigen::Matrix3d R = T.linear();
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  GEODRIFT_CHECK(orth < 1e-6 && R.determinant() > 0.0,
                 what << ": rotation block is not a rotation (max |R^T R - I| = " << orth
                      << ", det = " << R.determinant() << ")");
}
}  // namespace detail

/// KITTI pose (camera -> KITTI world, as stored in poses/XX.txt) -> camera -> W:
/// T_W_c = [R_W_K · R | R_W_K · t].
/// @throws InvalidArgument if the pose is not finite or its rotation is not orthonormal to 1e-6.
inline Eigen::Isometry3d kitti_pose_to_world(const Eigen::Isometry3d& T_K_c) {
  detail::check_pose(T_K_c, "kitti_pose_to_world");
  Eigen::Isometry3d T_W_c = Eigen::Isometry3d::Identity();
  const Eigen::Matrix3d R_W_K = kitti_to_world_rotation();
  T_W_c.linear() = R_W_K * T_K_c.linear();
  T_W_c.translation() = R_W_K * T_K_c.translation();
  return T_W_c;
}

/// Inverse of kitti_pose_to_world(): camera -> W pose to camera -> KITTI world.
/// @throws InvalidArgument as kitti_pose_to_world().
inline Eigen::Isometry3d world_pose_to_kitti(const Eigen::Isometry3d& T_W_c) {
  detail::check_pose(T_W_c, "world_pose_to_kitti");
  Eigen::Isometry3d T_K_c = Eigen::Isometry3d::Identity();
  const Eigen::Matrix3d R_K_W = kitti_to_world_rotation().transpose();
  T_K_c.linear() = R_K_W * T_W_c.linear();
  T_K_c.translation() = R_K_W * T_W_c.translation();
  return T_K_c;
}

/// KITTI pose (camera -> KITTI world) -> T_cw (W -> camera), the in-memory keyframe pose
/// convention of geodrift.
/// @throws InvalidArgument as kitti_pose_to_world().
inline Eigen::Isometry3d kitti_pose_to_T_cw(const Eigen::Isometry3d& T_K_c) {
  return kitti_pose_to_world(T_K_c).inverse(Eigen::Isometry);
}

/// The LocalFrame of the ASSUMED KITTI geo origin, an assumption for display only (KITTI's
/// odometry ground truth carries no geo-reference): cam0 of frame 0 at 49.0110°N, 8.4170°E,
/// ellipsoidal height 160 m, W = UTM zone 32N shifted to that point, frame-0 heading 0° (north).
///
/// Because DESIGN.md maps KITTI z to N exactly, "north" for the frame-0 optical axis means W's
/// +y, i.e. GRID north of zone 32. Its true heading is heading_from_grid_yaw(π/2, 0) = γ0 mod 2π,
/// with γ0 ≈ -0.44° the meridian convergence at the origin (8.417°E is west of the zone's
/// central meridian 9°E): the axis points about 0.44° west of true north. Every output that uses
/// this frame must state the assumption (kKittiGeoOriginNote).
inline LocalFrame kitti_local_frame() {
  return LocalFrame::from_geodetic(kKittiOriginLatitudeDeg, kKittiOriginLongitudeDeg,
                                   kKittiOriginHeight, kKittiUtmZone);
}

}  // namespace geodrift::geo
