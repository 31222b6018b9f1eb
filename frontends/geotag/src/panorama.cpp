#include "geodrift/geotag/panorama.hpp"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "geodrift/error.hpp"

namespace geodrift::geotag {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

void panorama_view_maps(int pano_width, int pano_height, const map::Camera& view, double offset,
                        cv::Mat* map_x, cv::Mat* map_y) {
  view.validate();
  GEODRIFT_CHECK(std::isfinite(offset), "panorama view offset " << offset << " is not finite");
  GEODRIFT_CHECK(pano_width > 1 && pano_height > 1,
                 "panorama size " << pano_width << "x" << pano_height << " is too small");
  map_x->create(view.height, view.width, CV_32FC1);
  map_y->create(view.height, view.width, CV_32FC1);
  const double co = std::cos(offset), so = std::sin(offset);
  const double W = pano_width, H = pano_height;
  for (int y = 0; y < view.height; ++y) {
    float* mx = map_x->ptr<float>(y);
    float* my = map_y->ptr<float>(y);
    const double dy = (y - view.cy) / view.fy;
    for (int x = 0; x < view.width; ++x) {
      const double dx = (x - view.cx) / view.fx;
      // Camera right = (cos o, -sin o, 0), down = (0, 0, -1), forward = (sin o, cos o, 0) in the
      // panorama's (east', north', up) frame, whose north' is the panorama heading.
      const double e = dx * co + so;
      const double n = -dx * so + co;
      const double up = -dy;
      const double bearing = std::atan2(e, n);  // relative to the heading
      const double elevation = std::atan2(up, std::hypot(e, n));
      double u = W * (0.5 + bearing / (2.0 * kPi)) - 0.5;
      u = std::fmod(u, W);
      if (u < 0) u += W;
      const double v = H * (0.5 - elevation / kPi) - 0.5;
      mx[x] = static_cast<float>(u);
      my[x] = static_cast<float>(v);
    }
  }
}

cv::Mat cut_panorama_view(const cv::Mat& pano, const map::Camera& view, double offset) {
  GEODRIFT_CHECK(!pano.empty(), "cut_panorama_view: the panorama image is empty");
  cv::Mat mx, my, out;
  panorama_view_maps(pano.cols, pano.rows, view, offset, &mx, &my);
  // BORDER_WRAP joins the last and first columns at the seam. Vertically the view never reaches
  // the poles for a video field of view (|elevation| < 90 deg keeps v inside [−0.5, H − 0.5]).
  cv::remap(pano, out, mx, my, cv::INTER_LINEAR, cv::BORDER_WRAP);
  return out;
}

PanoramaCutter::PanoramaCutter(int pano_width, int pano_height, const map::Camera& view)
    : width_(pano_width), height_(pano_height), view_(view) {
  panorama_view_maps(pano_width, pano_height, view, 0.0, &map_x_, &map_y_);
}

bool PanoramaCutter::fits(int pano_width, int pano_height, const map::Camera& view) const {
  return pano_width == width_ && pano_height == height_ && view.width == view_.width &&
         view.height == view_.height && view.fx == view_.fx && view.fy == view_.fy &&
         view.cx == view_.cx && view.cy == view_.cy;
}

cv::Mat PanoramaCutter::cut(const cv::Mat& pano, double offset) const {
  GEODRIFT_CHECK(!pano.empty(), "PanoramaCutter: the panorama image is empty");
  GEODRIFT_CHECK(pano.cols == width_ && pano.rows == height_,
                 "PanoramaCutter: panorama " << pano.cols << "x" << pano.rows << ", made for "
                                             << width_ << "x" << height_);
  GEODRIFT_CHECK(std::isfinite(offset), "panorama view offset " << offset << " is not finite");
  const double W = width_;
  double shift = std::fmod(W * offset / (2.0 * kPi), W);
  if (shift < 0) shift += W;
  // Table columns lie in [0, W) and shift in [0, W): one subtraction wraps the sum.
  cv::Mat mx(map_x_.size(), CV_32FC1), out;
  for (int y = 0; y < mx.rows; ++y) {
    const float* src = map_x_.ptr<float>(y);
    float* dst = mx.ptr<float>(y);
    for (int x = 0; x < mx.cols; ++x) {
      const double u = src[x] + shift;
      dst[x] = static_cast<float>(u < W ? u : u - W);
    }
  }
  cv::remap(pano, out, mx, map_y_, cv::INTER_LINEAR, cv::BORDER_WRAP);
  return out;
}

cv::Vec3d panorama_pixel_direction(double u, double v, int pano_width, int pano_height,
                                   double heading) {
  const double bearing = heading + 2.0 * kPi * ((u + 0.5) / pano_width - 0.5);
  const double elevation = 0.5 * kPi - kPi * (v + 0.5) / pano_height;
  return {std::cos(elevation) * std::sin(bearing), std::cos(elevation) * std::cos(bearing),
          std::sin(elevation)};
}

}  // namespace geodrift::geotag
