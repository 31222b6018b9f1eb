// Panorama cutting against an analytic equirectangular image.
#include <catch2/catch.hpp>
#include <cmath>
#include <geodrift/geo/local_frame.hpp>
#include <geodrift/geotag/panorama.hpp>
#include <opencv2/core.hpp>

#include "support/kitti.hpp"

using namespace geodrift;

namespace {
constexpr double kPi = 3.14159265358979323846;

using test::kitti_camera;

// A smooth function of the viewing direction (bearing relative to the panorama heading,
// elevation), periodic in bearing.
double radiance(double bearing, double elevation) {
  return 128.0 + 60.0 * std::sin(3.0 * bearing + 0.5) * std::cos(4.0 * elevation) +
         40.0 * std::cos(2.0 * bearing) * std::sin(5.0 * elevation);
}

cv::Mat analytic_panorama(int W, int H) {
  cv::Mat p(H, W, CV_32F);
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const double b = 2.0 * kPi * ((u + 0.5) / W - 0.5);
      const double el = 0.5 * kPi - kPi * (v + 0.5) / H;
      p.at<float>(v, u) = static_cast<float>(radiance(b, el));
    }
  return p;
}
/// Largest difference (grey levels, every 7th pixel) between `view` and the radiance along its
/// pixels' rays, for a level camera whose axis has bearing `offset` relative to the heading.
/// Independent ray: the core's level_camera_rotation in a frame with x = east', y = north'
/// (grid yaw = pi/2 - bearing).
double max_error_vs_analytic(const cv::Mat& view, const map::Camera& cam, double offset) {
  const Eigen::Matrix3d R_wc = geo::level_camera_rotation(0.5 * kPi - offset);
  double max_err = 0;
  for (int y = 0; y < cam.height; y += 7)
    for (int x = 0; x < cam.width; x += 7) {
      const Eigen::Vector3d d =
          R_wc * Eigen::Vector3d((x - cam.cx) / cam.fx, (y - cam.cy) / cam.fy, 1.0);
      const double b = std::atan2(d.x(), d.y());
      const double el = std::atan2(d.z(), std::hypot(d.x(), d.y()));
      max_err = std::max(max_err, std::abs(view.at<float>(y, x) - radiance(b, el)));
    }
  return max_err;
}
}  // namespace

TEST_CASE("Cut views of an analytic panorama sample the right directions (all 8, across the seam)",
          "[geotag][panorama]") {
  const map::Camera cam = kitti_camera();
  const cv::Mat pano = analytic_panorama(2048, 1024);
  for (int k = 0; k < geotag::kViewsPerPanorama; ++k) {
    const double offset = k * geotag::kViewStepDeg * kPi / 180.0;
    const cv::Mat view = geotag::cut_panorama_view(pano, cam, offset);
    REQUIRE(view.rows == cam.height);
    REQUIRE(view.cols == cam.width);
    const double max_err = max_error_vs_analytic(view, cam, offset);
    INFO("view " << k << " max error " << max_err);
    // Bilinear interpolation of this function on a 0.18 deg grid errs by < 0.01 grey levels; a
    // half-pixel shift of the panorama would err by ~0.5.
    CHECK(max_err < 0.02);
  }
  // The check is sharp: a 0.05 deg error in the cut direction already fails it.
  const cv::Mat off = geotag::cut_panorama_view(pano, cam, 0.05 * kPi / 180.0);
  CHECK(max_error_vs_analytic(off, cam, 0.0) > 0.1);
}

TEST_CASE("PanoramaCutter (tables once, columns shifted per view) equals cutting each view anew",
          "[geotag][panorama]") {
  const map::Camera cam = kitti_camera();
  const cv::Mat pano = analytic_panorama(2048, 1024);
  const geotag::PanoramaCutter cutter(pano.cols, pano.rows, cam);
  CHECK(cutter.fits(2048, 1024, cam));
  CHECK_FALSE(cutter.fits(2048, 1000, cam));
  map::Camera other = cam;
  other.cx += 1;
  CHECK_FALSE(cutter.fits(2048, 1024, other));
  // The 8 views, and offsets across the seam, negative and beyond a turn.
  for (const double deg :
       {0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 17.3, -100.0, 400.0, 359.99}) {
    const double offset = deg * kPi / 180.0;
    const cv::Mat a = cutter.cut(pano, offset);
    const cv::Mat b = geotag::cut_panorama_view(pano, cam, offset);
    REQUIRE(a.size() == b.size());
    INFO("offset " << deg << " deg");
    // The tables agree up to float rounding of the column (~1e-4 px), but cv::remap quantizes
    // coordinates to 1/32 px, so a rounding difference can move a sample by one such step: on
    // this image (slope < 1 grey level per px) that is < 1/32 grey level.
    CHECK(cv::norm(a, b, cv::NORM_INF) < 1.0 / 32.0);
    // And the cutter's view is as accurate as the test above asks of cut_panorama_view().
    CHECK(max_error_vs_analytic(a, cam, offset) < 0.02);
  }
  CHECK_THROWS_AS(cutter.cut(cv::Mat(1024, 2000, CV_32F, cv::Scalar(0)), 0.0), InvalidArgument);
  CHECK_THROWS_AS(cutter.cut(pano, std::nan("")), InvalidArgument);
  CHECK_THROWS_AS(cutter.cut(cv::Mat(), 0.0), InvalidArgument);
}

TEST_CASE("A point target in the panorama lands on its projection in the view",
          "[geotag][panorama]") {
  const map::Camera cam = kitti_camera();
  const int W = 2048, H = 1024;
  cv::Mat pano = cv::Mat::zeros(H, W, CV_32F);
  // A Gaussian blob at bearing +30 deg (relative), elevation +5 deg.
  const double b0 = 30.0 * kPi / 180.0, e0 = 5.0 * kPi / 180.0, s = 0.6 * kPi / 180.0;
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const double b = 2.0 * kPi * ((u + 0.5) / W - 0.5), el = 0.5 * kPi - kPi * (v + 0.5) / H;
      const double d2 = std::pow((b - b0) * std::cos(e0), 2) + std::pow(el - e0, 2);
      pano.at<float>(v, u) = static_cast<float>(std::exp(-0.5 * d2 / (s * s)));
    }
  const double offset = 45.0 * kPi / 180.0;  // view 1: the target is 15 deg left of its axis
  const cv::Mat view = geotag::cut_panorama_view(pano, cam, offset);
  double sw = 0, su = 0, sv = 0;
  for (int y = 0; y < view.rows; ++y)
    for (int x = 0; x < view.cols; ++x) {
      const double w = view.at<float>(y, x);
      if (w < 0.05) continue;
      sw += w;
      su += w * x;
      sv += w * y;
    }
  REQUIRE(sw > 0);
  // Expected projection: direction in camera coordinates of the level view.
  const Eigen::Matrix3d R_wc = geo::level_camera_rotation(0.5 * kPi - offset);
  const Eigen::Vector3d d(std::cos(e0) * std::sin(b0), std::cos(e0) * std::cos(b0), std::sin(e0));
  const Eigen::Vector3d pc = R_wc.transpose() * d;
  const Eigen::Vector2d uv = cam.project(pc);
  INFO("centroid (" << su / sw << ", " << sv / sw << ") expected (" << uv.x() << ", " << uv.y()
                    << ")");
  // The blob is slightly distorted by the perspective, so its centroid moves < 0.3 px.
  CHECK(std::abs(su / sw - uv.x()) < 0.3);
  CHECK(std::abs(sv / sw - uv.y()) < 0.3);
}

TEST_CASE("Panorama cutting rejects bad inputs", "[geotag][panorama][errors]") {
  map::Camera cam = kitti_camera();
  CHECK_THROWS_AS(geotag::cut_panorama_view(cv::Mat(), cam, 0.0), InvalidArgument);
  const cv::Mat pano(64, 128, CV_8U, cv::Scalar(0));
  CHECK_THROWS_AS(geotag::cut_panorama_view(pano, cam, std::nan("")), InvalidArgument);
  cam.fx = -1;
  CHECK_THROWS_AS(geotag::cut_panorama_view(pano, cam, 0.0), InvalidArgument);
}
