#pragma once

/// @file
/// The rendered street world of geodrift::render: a procedural street (asphalt road with lane
/// markings, parking strips, curbs, paved sidewalks, textured buildings on both sides with gaps
/// and varying setbacks and heights, poles with signs, trees, parked cars) laid along a
/// ground-truth camera path (a KITTI pose file), and the two appearances it is seen in (the
/// "video" and the "street view" panoramas, which differ the way Street View imagery differs
/// from a drive).
///
/// Frames and units (DESIGN.md): everything is in the world frame W of the KITTI sequence,
/// x = east, y = north, z = up, metres, with KITTI cam0 of frame 0 at the origin
/// (geo::kitti_pose_to_world). Camera poses are T_cw (W -> camera, OpenCV camera axes x right,
/// y down, z forward). The ground under the route is `camera_height_m` (1.65 m, KITTI's cam0
/// height) below the camera centre at the nearest route point, so it follows the route's height.
///
/// Street layout (metres, lateral offset d from the route, positive to the right of travel; the
/// route is the road's centre line):
///   |d| < 0.075, dashed 3 m on / 6 m off   centre line
///   |d| in [3.425, 3.575]                   solid lane edge lines
///   3.575 < |d| < 5.5                       parking strips (bay lines every 6 m, parked cars)
///   5.5 <= |d| < 5.7                        curb (light stone with a dark joint)
///   5.7 <= |d| < 9.5                        paved sidewalk (0.5 m slabs), poles at 6.2, trees
///                                           at 8.3
///   |d| >= 9.5                              building plots: facade setback 0..5 m, gaps,
///                                           grass/gravel between buildings
///
/// Determinism: the world and every image are pure functions of (poses, WorldOptions, the
/// render call's arguments): the same seed gives bit-identical images with any thread count.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/lie/se3.hpp"

namespace geodrift::render {

/// Lighting and content variant an image is rendered in.
///
/// The two fixed appearances (documented settings; the geo-tag pipeline relies on them):
///   video():        sun at azimuth 135 deg (clockwise from grid north, i.e. south-east),
///                   elevation 40 deg; sun 0.75, ambient 0.45; neutral white balance
///                   (1, 1, 1); the video's facades and parked cars.
///   street_view():  sun at azimuth 235 deg, elevation 58 deg (direction changed by ~75 deg);
///                   sun brightness x1.4 (+40 %), ambient x0.8 (-20 %); colour temperature
///                   shifted warm, white balance (R, G, B) = (1.10, 1.00, 0.85); 20 % of the
///                   building faces carry a different facade (other style, colours and window
///                   layout: hash of (seed, face) < 0.2); parked cars: 40 % unchanged, 35 % moved
///                   along the kerb by 1.5..5 m (either way), 25 % gone, and new cars in 15 % of
///                   the empty bays.
struct Appearance {
  Eigen::Vector3d sun_direction = Eigen::Vector3d(0.541675, -0.541675, 0.642788);  ///< unit, W
  double sun_intensity = 0.75;                               ///< diffuse sun scale
  double ambient_intensity = 0.45;                           ///< ambient (sky) light scale
  Eigen::Vector3d white_balance = Eigen::Vector3d(1, 1, 1);  ///< RGB gains (colour temp.)
  bool street_view_content = false;  ///< replaced facades + moved parked cars (street view)

  /// The video's appearance (see the struct comment).
  static Appearance video();
  /// The panoramas' appearance (see the struct comment).
  static Appearance street_view();
  /// Sun direction (unit vector towards the sun, W) from an azimuth clockwise from grid north
  /// and an elevation above the horizon, both in degrees.
  static Eigen::Vector3d sun_from_azimuth_elevation(double azimuth_deg, double elevation_deg);
};

/// Options of the world built along a route.
struct WorldOptions {
  std::uint64_t seed = 1;  ///< every random choice of the world derives from it
  /// Route frames the world is built around (inclusive; indices of the sequence's poses).
  /// last_frame < 0 means the last pose. Objects are generated along the route from
  /// margin_m before first_frame to margin_m after last_frame.
  int first_frame = 0;
  int last_frame = -1;
  double margin_m = 150.0;        ///< route length generated beyond the frame range, metres
  double camera_height_m = 1.65;  ///< camera centre above the ground (KITTI cam0), metres
};

/// What a ray hit (for tests and depth maps).
enum class SurfaceKind : int { kSky = 0, kGround, kBuilding, kCar, kPole, kSign, kTrunk, kCanopy };

/// Result of World::trace().
struct RayHit {
  double t = std::numeric_limits<double>::infinity();  ///< distance along the unit ray, metres
  SurfaceKind kind = SurfaceKind::kSky;
  int object = -1;  ///< index of the object (building index for kBuilding), -1 for sky/ground
  int face = -1;    ///< box face 0..5 (-x, +x, -y, +y, bottom, top in the object's frame)
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();  ///< unit surface normal in W
};

/// A building as placed in the world (for tests and documentation): a box standing on the
/// ground, axis-aligned in its own frame whose x axis runs along the street.
struct BuildingInfo {
  Eigen::Vector2d centre;        ///< footprint centre in W (x, y)
  double yaw = 0;                ///< angle of the building's x axis from W's +x (rad)
  double half_length = 0;        ///< along x (m)
  double half_depth = 0;         ///< along y (m)
  double base_z = 0, top_z = 0;  ///< W heights of the ground floor and the roof (m)
  /// The four footprint corners at ground level (W), counter-clockwise from (-x, -y).
  std::vector<Eigen::Vector3d> corners() const;
};

/// Nearest route point to a horizontal position.
struct RoutePoint {
  double s = 0;         ///< arclength along the whole sequence's route from frame 0 (m)
  double d = 0;         ///< signed lateral offset, positive right of travel (m)
  double camera_z = 0;  ///< W height of the camera path at s (m); ground = camera_z - 1.65
  Eigen::Vector2d tangent = Eigen::Vector2d(1, 0);  ///< unit direction of travel (x, y)
};

/// The street world. Immutable after construction; all methods are thread-safe; cheap to copy
/// (shared state).
class World {
 public:
  /// Builds the world along a route given as camera -> W poses of the whole sequence (one per
  /// frame; W as in the file comment).
  /// @throws InvalidArgument for fewer than 2 poses, a non-finite pose, a frame range outside
  ///         the poses or with first > last, a negative margin or non-positive camera height,
  ///         or a frame range whose route is shorter than 1 m.
  World(const std::vector<Eigen::Isometry3d>& T_W_c, const WorldOptions& options);

  /// Builds the world from KITTI poses (camera -> KITTI world, as in poses/XX.txt).
  static World from_kitti(const std::vector<Eigen::Isometry3d>& T_K_c, const WorldOptions& options);

  const WorldOptions& options() const;
  int frame_count() const;  ///< number of poses of the sequence
  /// T_cw (W -> camera) of sequence frame i. @throws InvalidArgument out of range.
  lie::SE3d frame_T_cw(int i) const;
  /// Arclength of sequence frame i along the route (m). @throws InvalidArgument out of range.
  double frame_arclength(int i) const;
  /// Route position (camera path) at arclength s (clamped to the route): x, y, camera z in W.
  Eigen::Vector3d route_point(double s) const;
  /// Unit horizontal direction of travel at arclength s (central chord over +-2 m).
  Eigen::Vector2d route_tangent(double s) const;
  /// Nearest route point to (x, y) (exact near the route, approximate > 40 m away).
  RoutePoint nearest_route_point(double x, double y) const;
  /// W height of the ground at (x, y): camera_z of the nearest route point minus the camera
  /// height.
  double ground_height(double x, double y) const;

  /// Traces a ray from `origin` along unit direction `dir` (W) in the given appearance.
  RayHit trace(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir,
               const Appearance& appearance) const;

  /// Buildings of the world (index = RayHit::object for kBuilding).
  std::vector<BuildingInfo> buildings() const;
  /// Counts of generated objects (for reports): buildings, cars (video), cars (street view),
  /// trees, poles.
  std::string summary() const;

  /// The geo frame of W: the assumed KITTI geo origin (geo::kitti_local_frame()).
  const geo::LocalFrame& local_frame() const;

  struct Impl;  ///< implementation (src/world.cpp)
  const Impl& impl() const { return *impl_; }

 private:
  std::shared_ptr<const Impl> impl_;
};

}  // namespace geodrift::render
