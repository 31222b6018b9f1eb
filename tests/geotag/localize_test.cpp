// PnP RANSAC + LM localization and the map-world correspondence, on synthetic 2D-3D data.
#include <catch2/catch.hpp>
#include <cmath>
#include <geodrift/correction/localization_covariance.hpp>
#include <geodrift/geo/kitti.hpp>
#include <geodrift/geotag/localize.hpp>
#include <geodrift/geotag/panorama.hpp>
#include <geodrift/geotag/views.hpp>
#include <geodrift/lie/sim3.hpp>
#include <random>

#include "support/kitti.hpp"
#include "support/test_files.hpp"

using namespace geodrift;

namespace {
constexpr double kPi = 3.14159265358979323846;

using test::kitti_camera;

double rotation_angle_deg(const lie::SE3d& a, const lie::SE3d& b) {
  return (a.rotation() * b.rotation().inverse()).log().norm() * 180.0 / kPi;
}

/// Points in front of camera T_cw, projected with Gaussian noise; a fraction replaced by
/// outliers (random pixels).
void make_scene(std::mt19937& rng, const lie::SE3d& T_cw, const map::Camera& cam, int n,
                double noise_px, double outlier_fraction, double depth_scale,
                std::vector<Eigen::Vector3d>* X, std::vector<Eigen::Vector2d>* uv,
                std::vector<bool>* is_outlier) {
  std::uniform_real_distribution<double> ux(0, cam.width), uy(0, cam.height),
      dz(4.0 * depth_scale, 40.0 * depth_scale), u01(0, 1);
  std::normal_distribution<double> nz(0, noise_px);
  const lie::SE3d T_wc = T_cw.inverse();
  for (int i = 0; i < n; ++i) {
    const double x = ux(rng), y = uy(rng), z = dz(rng);
    const Eigen::Vector3d pc((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z);
    X->push_back(T_wc.act(pc));
    const bool out = u01(rng) < outlier_fraction;
    is_outlier->push_back(out);
    uv->push_back(out ? Eigen::Vector2d(ux(rng), uy(rng))
                      : Eigen::Vector2d(x + nz(rng), y + nz(rng)));
  }
}
}  // namespace

TEST_CASE("PnP RANSAC + core LM localizes a view with 50% outliers", "[geotag][localize]") {
  std::mt19937 rng(42);
  const map::Camera cam = kitti_camera();
  double err2 = 0, predicted2 = 0;  // centre error² and the predicted tr Σ_c, summed
  for (int trial = 0; trial < 20; ++trial) {
    const lie::SE3d T_true = test::random_pose(rng, 10.0);
    std::vector<Eigen::Vector3d> X;
    std::vector<Eigen::Vector2d> uv;
    std::vector<bool> out;
    make_scene(rng, T_true, cam, 200, 0.5, 0.5, 0.3, &X, &uv, &out);
    const geotag::LocalizeResult r = geotag::localize_view(X, uv, cam);
    INFO("trial " << trial << ": " << r.reason);
    REQUIRE(r.ok);
    // Pose error: with 100 inliers at 0.5 px noise, the camera centre is known to millimetres
    // (scene depths 1.2-12 units) and the rotation to hundredths of a degree.
    const double dc = (r.T_vm.inverse().translation() - T_true.inverse().translation()).norm();
    CHECK(dc < 0.02);
    CHECK(rotation_angle_deg(r.T_vm, T_true) < 0.05);
    REQUIRE(r.pose_cov.block<3, 3>(3, 3).trace() > 0);
    err2 += dc * dc;
    predicted2 += correction::center_covariance(r.pose_cov, r.T_vm).trace();
    CHECK(r.rms_px < 0.8);
    int wrong = 0;
    for (int i : r.inlier_indices) wrong += out[i] ? 1 : 0;
    // A random outlier pixel falls within 4 px of its true projection with probability
    // ~ pi*16 / (1241*376) per point: none expected.
    CHECK(wrong <= 1);
    int n_in = 0;
    for (bool o : out) n_in += o ? 0 : 1;
    CHECK(r.inliers >= n_in - 2);
  }
  // The pose covariance over the inliers predicts the centre errors: Σ dc² over 20 trials is a
  // χ² with 60 degrees of freedom scaled by the mean tr Σ_c (95 % range 0.68-1.35 of it).
  INFO("sum of centre errors² " << err2 << ", of predicted variances " << predicted2);
  CHECK(err2 / predicted2 > 0.6);
  CHECK(err2 / predicted2 < 1.5);
}

TEST_CASE("Localization rejects too few pairs, pure outliers and degenerate geometry cleanly",
          "[geotag][localize][errors]") {
  std::mt19937 rng(3);
  const map::Camera cam = kitti_camera();
  const lie::SE3d T = test::random_pose(rng, 5.0);
  std::vector<Eigen::Vector3d> X;
  std::vector<Eigen::Vector2d> uv;
  std::vector<bool> out;
  make_scene(rng, T, cam, 10, 0.5, 0.0, 1.0, &X, &uv, &out);
  geotag::LocalizeResult r = geotag::localize_view(X, uv, cam);
  CHECK_FALSE(r.ok);
  CHECK(r.reason.find("need 20") != std::string::npos);

  X.clear(), uv.clear(), out.clear();
  make_scene(rng, T, cam, 150, 0.5, 1.0, 1.0, &X, &uv, &out);  // all outliers
  r = geotag::localize_view(X, uv, cam);
  CHECK_FALSE(r.ok);
  INFO(r.reason);
  CHECK_FALSE(r.reason.empty());

  // All points on one short image segment: the inliers cover a degenerate part of the image.
  X.clear(), uv.clear();
  const lie::SE3d T_wc = T.inverse();
  for (int i = 0; i < 60; ++i) {
    const double x = 600 + i * 0.5, y = 180 + 0.3 * i, z = 10 + 0.1 * i;
    X.push_back(T_wc.act(Eigen::Vector3d((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z)));
    uv.push_back({x, y});
  }
  r = geotag::localize_view(X, uv, cam);
  CHECK_FALSE(r.ok);

  // Malformed input throws.
  std::vector<Eigen::Vector3d> X2(30, Eigen::Vector3d::Ones());
  std::vector<Eigen::Vector2d> uv2(29, Eigen::Vector2d::Ones());
  CHECK_THROWS_AS(geotag::localize_view(X2, uv2, cam), InvalidArgument);
  uv2.push_back(Eigen::Vector2d(std::nan(""), 1.0));
  CHECK_THROWS_AS(geotag::localize_view(X2, uv2, cam), InvalidArgument);
}

TEST_CASE("A localized panorama view gives the correspondence of DESIGN.md, consistent with W",
          "[geotag][localize][correspondence]") {
  // W = the KITTI frame; a panorama at a geo-tag with heading 100 deg, its view k = 3 (heading
  // 235 deg). The map M is W under an unknown similarity (scale 0.2: monocular maps have
  // arbitrary scale).
  const geo::LocalFrame frame = geo::kitti_local_frame();
  const Eigen::Vector3d p_w(120.0, -35.0, 1.5);
  const geo::Geodetic g = frame.to_geodetic(p_w);
  geotag::GeoSource src;
  src.tag.id = 17;
  src.tag.latitude_deg = g.latitude_deg;
  src.tag.longitude_deg = g.longitude_deg;
  src.tag.height = g.height;
  src.tag.heading = 100.0 * kPi / 180.0;
  src.kind = geotag::SourceKind::kPanorama;
  const map::Camera cam = kitti_camera();
  const std::vector<geotag::GeoView> views = geotag::make_views({src}, cam);
  REQUIRE(views.size() == 8);
  const geotag::GeoView& view = views[3];
  CHECK(view.heading == Approx(235.0 * kPi / 180.0).margin(1e-12));

  // The view's pose in W: centre at the geo-tag, optical axis along its heading.
  const lie::SE3d T_vw = geotag::view_pose_world(view, frame);
  CHECK((T_vw.inverse().translation() - p_w).norm() < 1e-6);
  const Eigen::Matrix3d R_wv = T_vw.inverse().rotation().matrix();
  CHECK(frame.camera_heading(R_wv, p_w) == Approx(view.heading).margin(1e-9));
  CHECK(std::abs(R_wv.col(2).z()) < 1e-12);  // level
  CHECK(R_wv.col(1).z() == Approx(-1.0));    // image y points down

  // M = S_mw * W.
  const lie::Sim3d S_mw(lie::SO3d::exp(Eigen::Vector3d(0.1, -0.3, 1.2)),
                        Eigen::Vector3d(4.0, -2.0, 7.0), 0.2);
  // The view's true pose in M: T_vm = T_vw * S_mw^-1 with the scale moved to the translation.
  const auto to_m = [&](const lie::SE3d& T_cw_w) {
    const Eigen::Matrix3d R = T_cw_w.rotation().matrix() * S_mw.rotation().matrix().transpose();
    const Eigen::Vector3d c_w = T_cw_w.inverse().translation();
    const Eigen::Vector3d c_m = S_mw.act(c_w);
    return lie::SE3d(lie::SO3d(R), -R * c_m);
  };
  const lie::SE3d T_vm_true = to_m(T_vw);
  // 2D-3D pairs: points in W in front of the view, expressed in M.
  std::mt19937 rng(5);
  std::vector<Eigen::Vector3d> X_w, X_m;
  std::vector<Eigen::Vector2d> uv;
  std::vector<bool> out;
  make_scene(rng, T_vw, cam, 120, 0.3, 0.3, 1.0, &X_w, &uv, &out);
  for (const Eigen::Vector3d& x : X_w) X_m.push_back(S_mw.act(x));
  const geotag::LocalizeResult r = geotag::localize_view(X_m, uv, cam);
  INFO(r.reason);
  REQUIRE(r.ok);
  // Centre error in W metres (M is 0.2 x W).
  const double dc_w =
      (r.T_vm.inverse().translation() - T_vm_true.inverse().translation()).norm() / 0.2;
  CHECK(dc_w < 0.05);
  CHECK(rotation_angle_deg(r.T_vm, T_vm_true) < 0.05);

  // A keyframe 8 m behind the view in W, looking north.
  const Eigen::Vector3d kc_w = p_w + Eigen::Vector3d(0, -8, 0);
  const Eigen::Matrix3d R_wk = geo::level_camera_rotation(0.5 * kPi);
  map::Keyframe kf;
  kf.id = 42;
  kf.T_cw = to_m(lie::SE3d(lie::SO3d(R_wk.transpose()), -R_wk.transpose() * kc_w));
  const map::Correspondence c = geotag::make_correspondence(5, view, kf, r, frame, 2.0);
  CHECK(c.id == 5);
  CHECK(c.keyframe == 42);
  CHECK(c.geotag_id == 17);
  CHECK(c.inliers == r.inliers);
  CHECK(c.reprojection_rms == r.rms_px);
  CHECK(c.sigma_m == 2.0);
  CHECK(c.pose_cov == r.pose_cov);
  CHECK(c.has_pose_covariance());
  CHECK((c.y_w - p_w).norm() < 1e-6);
  // T_vk composes with the keyframe's pose to the view's pose in M.
  CHECK(test::pose_distance(c.T_vk * kf.T_cw, r.T_vm) < 1e-9);
  // The view's centre in M mapped to W lands on its geo-tag (what PGO's e3 compares).
  const Eigen::Vector3d c_m = (c.T_vk * kf.T_cw).inverse().translation();
  CHECK((S_mw.inverse().act(c_m) - c.y_w).norm() < 0.05);

  geotag::LocalizeResult bad;
  CHECK_THROWS_AS(geotag::make_correspondence(0, view, kf, bad, frame, 2.0), InvalidArgument);
}
