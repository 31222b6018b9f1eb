// KITTI/OpenCV camera convention -> W (DESIGN.md: E = x, N = z, U = -y) and the assumed KITTI
// geo origin.

#include "geodrift/geo/kitti.hpp"

#include <GeographicLib/Geodesic.hpp>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>

#include "geo_test_util.hpp"

using geodrift::geo::LocalFrame;
using geodrift::test::require_invalid_argument;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

Eigen::Isometry3d pose(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}

// Rotation about the camera's y axis (down): positive angles turn the optical axis towards +x
// (to the right, i.e. clockwise seen from above).
Eigen::Matrix3d turn_right(double angle) {
  return Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()).toRotationMatrix();
}

}  // namespace

TEST_CASE("R_W_K maps KITTI x to east, z to north and y to down", "[geo][kitti]") {
  const Eigen::Matrix3d R = geodrift::geo::kitti_to_world_rotation();
  CHECK(R.determinant() == Approx(1.0).margin(1e-15));
  CHECK((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-15);
  CHECK((R * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitX()).norm() == 0.0);  // x -> E
  CHECK((R * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitY()).norm() == 0.0);  // z -> N
  CHECK((R * Eigen::Vector3d::UnitY() + Eigen::Vector3d::UnitZ()).norm() == 0.0);  // y -> -U
  CHECK((geodrift::geo::kitti_point_to_world(Eigen::Vector3d(1, 2, 3)) - Eigen::Vector3d(1, 3, -2))
            .norm() == 0.0);
}

TEST_CASE("A KITTI camera moving forward goes north, moving along +x goes east", "[geo][kitti]") {
  const LocalFrame frame = geodrift::geo::kitti_local_frame();
  const GeographicLib::Geodesic& geod = GeographicLib::Geodesic::WGS84();
  const double gamma0 = frame.meridian_convergence(Eigen::Vector3d::Zero());
  const double k0 = frame.scale_factor(Eigen::Vector3d::Zero());

  // Forward along KITTI z with identity rotation: +y in W, i.e. grid north.
  const Eigen::Isometry3d T_W_fwd = geodrift::geo::kitti_pose_to_world(
      pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 100)));
  CHECK((T_W_fwd.translation() - Eigen::Vector3d(0, 100, 0)).norm() < 1e-12);
  // On the ellipsoid the step goes along azimuth γ0 (grid north), 100/k0 metres long.
  const geodrift::geo::Geodetic o = frame.origin_geodetic();
  const geodrift::geo::Geodetic g = frame.to_geodetic(T_W_fwd.translation());
  double s12 = 0.0, azi1 = 0.0, azi2 = 0.0;
  geod.Inverse(o.latitude_deg, o.longitude_deg, g.latitude_deg, g.longitude_deg, s12, azi1, azi2);
  CHECK(g.latitude_deg > o.latitude_deg);
  CHECK(s12 == Approx(100.0 / k0).margin(1e-6));
  CHECK(azi1 * kDeg == Approx(gamma0).margin(1e-7));
  CHECK(g.height == Approx(160.0).margin(1e-12));

  // Along KITTI +x: +x in W, grid east, azimuth 90° + γ0.
  const Eigen::Isometry3d T_W_right = geodrift::geo::kitti_pose_to_world(
      pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(100, 0, 0)));
  CHECK((T_W_right.translation() - Eigen::Vector3d(100, 0, 0)).norm() < 1e-12);
  const geodrift::geo::Geodetic ge = frame.to_geodetic(T_W_right.translation());
  geod.Inverse(o.latitude_deg, o.longitude_deg, ge.latitude_deg, ge.longitude_deg, s12, azi1, azi2);
  CHECK(ge.longitude_deg > o.longitude_deg);
  CHECK(azi1 * kDeg == Approx(kPi / 2 + gamma0).margin(1e-7));

  // Along KITTI +y (down): height decreases.
  const Eigen::Isometry3d T_W_down = geodrift::geo::kitti_pose_to_world(
      pose(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 5, 0)));
  CHECK(frame.to_geodetic(T_W_down.translation()).height == Approx(155.0).margin(1e-9));
}

TEST_CASE("The frame-0 optical axis points north and turning right increases the heading",
          "[geo][kitti]") {
  const LocalFrame frame = geodrift::geo::kitti_local_frame();
  const double gamma0 = frame.meridian_convergence(Eigen::Vector3d::Zero());
  // The origin is west of zone 32's central meridian (9°E): γ0 = (8.417 - 9)·sin(49.011°) ≈
  // -0.44°.
  CHECK(gamma0 / kDeg == Approx(-0.44).margin(0.01));

  const Eigen::Isometry3d T_W_0 = geodrift::geo::kitti_pose_to_world(Eigen::Isometry3d::Identity());
  CHECK(geodrift::geo::optical_axis_grid_yaw(T_W_0.linear()) == Approx(kPi / 2).margin(1e-15));
  const double heading0 = frame.camera_heading(T_W_0.linear(), Eigen::Vector3d::Zero());
  // Heading 0° (north) up to the convergence: exactly γ0 mod 360°.
  CHECK(std::abs(geodrift::geo::detail::wrap_to_pi(heading0)) < 0.5 * kDeg);
  CHECK(geodrift::geo::detail::wrap_to_pi(heading0 - gamma0) == Approx(0.0).margin(1e-12));
  // The frame-0 camera is level: its x axis is east, its y axis is down.
  CHECK((T_W_0.linear() - geodrift::geo::level_camera_rotation(kPi / 2)).norm() < 1e-15);

  // Turning right (clockwise from above) by 30° gives heading 30° + γ0.
  const Eigen::Isometry3d T_W_r =
      geodrift::geo::kitti_pose_to_world(pose(turn_right(30.0 * kDeg), Eigen::Vector3d::Zero()));
  const double heading_r = frame.camera_heading(T_W_r.linear(), Eigen::Vector3d::Zero());
  CHECK(geodrift::geo::detail::wrap_to_pi(heading_r - (30.0 * kDeg + gamma0)) ==
        Approx(0.0).margin(1e-12));
}

TEST_CASE("KITTI poses convert to W and T_cw consistently", "[geo][kitti]") {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-500.0, 500.0);
  const Eigen::Matrix3d R_W_K = geodrift::geo::kitti_to_world_rotation();
  for (int i = 0; i < 200; ++i) {
    const Eigen::Isometry3d T_K_c =
        pose(random_rotation(rng), Eigen::Vector3d(u(rng), u(rng), u(rng)));
    const Eigen::Vector3d p_c(u(rng), u(rng), u(rng));
    const Eigen::Isometry3d T_W_c = geodrift::geo::kitti_pose_to_world(T_K_c);
    INFO("sample " << i);
    // The same physical point, expressed in W either way.
    CHECK((T_W_c * p_c - R_W_K * (T_K_c * p_c)).norm() < 1e-9);
    // Inverse mapping.
    CHECK((geodrift::geo::world_pose_to_kitti(T_W_c).matrix() - T_K_c.matrix()).norm() < 1e-12);
    // T_cw takes the W point back into the camera; the camera centre maps to zero.
    const Eigen::Isometry3d T_cw = geodrift::geo::kitti_pose_to_T_cw(T_K_c);
    CHECK((T_cw * (T_W_c * p_c) - p_c).norm() < 1e-9);
    CHECK((T_cw * T_W_c.translation()).norm() < 1e-9);
  }
}

TEST_CASE("The assumed KITTI geo origin is 49.0110N 8.4170E, 160 m, zone 32N", "[geo][kitti]") {
  const LocalFrame frame = geodrift::geo::kitti_local_frame();
  CHECK(frame.zone() == 32);
  CHECK(frame.northp());
  CHECK(frame.zone_string() == "32N");
  const geodrift::geo::Geodetic o = frame.to_geodetic(Eigen::Vector3d::Zero());
  CHECK(o.latitude_deg == Approx(49.0110).margin(1e-11));
  CHECK(o.longitude_deg == Approx(8.4170).margin(1e-11));
  CHECK(o.height == 160.0);
  CHECK(frame.height0() == 160.0);
  CHECK(std::string(geodrift::geo::kKittiGeoOriginNote).find("ASSUMPTION") != std::string::npos);
}

TEST_CASE("KITTI helpers reject non-finite or non-rotation poses", "[geo][kitti][errors]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::Isometry3d bad = Eigen::Isometry3d::Identity();
  bad.translation().x() = nan;
  require_invalid_argument([&] { geodrift::geo::kitti_pose_to_world(bad); },
                           {"kitti_pose_to_world", "not finite"});
  Eigen::Isometry3d scaled = Eigen::Isometry3d::Identity();
  scaled.linear() *= 1.01;
  require_invalid_argument([&] { geodrift::geo::kitti_pose_to_T_cw(scaled); }, {"not a rotation"});
  Eigen::Isometry3d mirrored = Eigen::Isometry3d::Identity();
  mirrored.linear()(0, 0) = -1.0;
  require_invalid_argument([&] { geodrift::geo::world_pose_to_kitti(mirrored); },
                           {"world_pose_to_kitti", "det"});
  require_invalid_argument([&] { geodrift::geo::kitti_point_to_world(Eigen::Vector3d(0, nan, 0)); },
                           {"p_K", "not finite"});
}

TEST_CASE("LocalFrame describes itself for file headers", "[geo][local_frame]") {
  const LocalFrame frame = LocalFrame::from_utm(32, true, 457367.4012, 5428842.3259, 160.0);
  CHECK(frame.description() ==
        "W = UTM 32N grid shifted to E0 457367.401 N0 5428842.326 h0 160.000 (x east, y north, "
        "z up ellipsoidal; metres)");
}
