// K-VLD scale space (kvld.md §3.2): gradient pyramid with √2 steps, levels made by exact box
// averages through an integral image.
#include <algorithm>
#include <cmath>

#include "geodrift/error.hpp"
#include "geodrift/kvld/kvld.hpp"

namespace geodrift::kvld {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;

/// Orientation in [0, 2π) of (gx, gy) (y down); false for the zero vector.
bool orientation(double gx, double gy, double* angle) {
  if (gx == 0.0 && gy == 0.0) return false;
  double a = std::atan2(gy, gx);
  if (a < 0.0) a += kTwoPi;
  if (a >= kTwoPi) a -= kTwoPi;  // atan2 may return -0 -> 2π after the add on some inputs
  *angle = a;
  return true;
}

void gradients(const std::vector<float>& img, int w, int h, ScaleLevel* out) {
  out->width = w;
  out->height = h;
  out->angle.assign(static_cast<std::size_t>(w) * h, 0.0f);
  out->magnitude.assign(static_cast<std::size_t>(w) * h, 0.0f);
  for (int y = 1; y < h - 1; ++y) {
    for (int x = 1; x < w - 1; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      const double gx = static_cast<double>(img[i + 1]) - img[i - 1];
      const double gy = static_cast<double>(img[i + w]) - img[i - w];
      double a = 0.0;
      out->angle[i] = orientation(gx, gy, &a) ? static_cast<float>(a) : -1.0f;
      out->magnitude[i] = static_cast<float>(std::hypot(gx, gy));
    }
  }
}

/// Summed-area table S with S(x, y) = Σ_{u<x, v<y} I(u, v) at integer corners; between corners
/// the bilinear interpolation of S is the exact area integral of the piecewise-constant image.
class Integral {
 public:
  Integral(const std::vector<float>& img, int w, int h) : w_(w), h_(h) {
    s_.assign(static_cast<std::size_t>(w + 1) * (h + 1), 0.0);
    for (int y = 0; y < h; ++y) {
      double row = 0.0;
      for (int x = 0; x < w; ++x) {
        row += img[static_cast<std::size_t>(y) * w + x];
        s_[idx(x + 1, y + 1)] = s_[idx(x + 1, y)] + row;
      }
    }
  }
  /// Area integral over [0, x) × [0, y), x ∈ [0, w], y ∈ [0, h].
  double at(double x, double y) const {
    x = std::clamp(x, 0.0, static_cast<double>(w_));
    y = std::clamp(y, 0.0, static_cast<double>(h_));
    const int ix = std::min(static_cast<int>(x), w_ - 1);
    const int iy = std::min(static_cast<int>(y), h_ - 1);
    const double fx = x - ix, fy = y - iy;
    return s_[idx(ix, iy)] * (1 - fx) * (1 - fy) + s_[idx(ix + 1, iy)] * fx * (1 - fy) +
           s_[idx(ix, iy + 1)] * (1 - fx) * fy + s_[idx(ix + 1, iy + 1)] * fx * fy;
  }
  double box_mean(double x0, double y0, double x1, double y1) const {
    return (at(x1, y1) - at(x0, y1) - at(x1, y0) + at(x0, y0)) / ((x1 - x0) * (y1 - y0));
  }

 private:
  std::size_t idx(int x, int y) const { return static_cast<std::size_t>(y) * (w_ + 1) + x; }
  int w_, h_;
  std::vector<double> s_;
};

template <typename T>
void copy_rows(const cv::Mat& m, std::vector<float>* out) {
  for (int y = 0; y < m.rows; ++y) {
    const T* row = m.ptr<T>(y);
    for (int x = 0; x < m.cols; ++x) {
      const double v = static_cast<double>(row[x]);
      GEODRIFT_CHECK(std::isfinite(v), "kvld::ImageScale: pixel ("
                                           << x << ", " << y << ") is not finite (" << v << ")");
      (*out)[static_cast<std::size_t>(y) * m.cols + x] = static_cast<float>(v);
    }
  }
}

}  // namespace

ImageScale::ImageScale(const cv::Mat& gray, double base_radius) : base_radius_(base_radius) {
  GEODRIFT_CHECK(!gray.empty(), "kvld::ImageScale: the image is empty");
  GEODRIFT_CHECK(gray.channels() == 1,
                 "kvld::ImageScale: expected a single-channel (grayscale) "
                 "image, got "
                     << gray.channels() << " channels");
  GEODRIFT_CHECK(gray.dims == 2, "kvld::ImageScale: expected a 2-D image");
  GEODRIFT_CHECK(gray.cols >= 3 && gray.rows >= 3, "kvld::ImageScale: image "
                                                       << gray.cols << "x" << gray.rows
                                                       << " is smaller than 3x3");
  GEODRIFT_CHECK(std::isfinite(base_radius) && base_radius > 0,
                 "kvld::ImageScale: base radius " << base_radius << " must be > 0");
  width_ = gray.cols;
  height_ = gray.rows;
  std::vector<float> img(static_cast<std::size_t>(width_) * height_);
  switch (gray.depth()) {
    case CV_8U:
      copy_rows<unsigned char>(gray, &img);
      break;
    case CV_16U:
      copy_rows<unsigned short>(gray, &img);
      break;
    case CV_32F:
      copy_rows<float>(gray, &img);
      break;
    case CV_64F:
      copy_rows<double>(gray, &img);
      break;
    default:
      GEODRIFT_CHECK(false, "kvld::ImageScale: unsupported depth "
                                << gray.depth() << " (use CV_8U, CV_16U, CV_32F or CV_64F)");
  }
  build(img);
}

ImageScale::ImageScale(const float* data, int width, int height, std::ptrdiff_t stride,
                       double base_radius)
    : width_(width), height_(height), base_radius_(base_radius) {
  GEODRIFT_CHECK(data != nullptr, "kvld::ImageScale: null image buffer");
  GEODRIFT_CHECK(width >= 3 && height >= 3,
                 "kvld::ImageScale: image " << width << "x" << height << " is smaller than 3x3");
  GEODRIFT_CHECK(stride >= width,
                 "kvld::ImageScale: stride " << stride << " floats is below the width " << width);
  GEODRIFT_CHECK(std::isfinite(base_radius) && base_radius > 0,
                 "kvld::ImageScale: base radius " << base_radius << " must be > 0");
  std::vector<float> img(static_cast<std::size_t>(width) * height);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const float v = data[y * stride + x];
      GEODRIFT_CHECK(std::isfinite(v), "kvld::ImageScale: pixel ("
                                           << x << ", " << y << ") is not finite (" << v << ")");
      img[static_cast<std::size_t>(y) * width + x] = v;
    }
  }
  build(img);
}

void ImageScale::build(const std::vector<float>& image) {
  const double step = std::sqrt(2.0);
  const double size = std::max(width_, height_);
  // ⌊log₂(size / r₀)⌋ + 1 levels (reference: log base 2 although the step is √2), at least 1.
  const int n = std::max(1, static_cast<int>(std::floor(std::log2(size / base_radius_))) + 1);
  levels_.resize(static_cast<std::size_t>(n));
  gradients(image, width_, height_, &levels_[0]);
  levels_[0].ratio = 1.0;
  if (n == 1) return;
  const Integral integral(image, width_, height_);
  std::vector<float> small;
  for (int k = 1; k < n; ++k) {
    const double ratio = std::pow(step, k);
    const int w = static_cast<int>(width_ / ratio);
    const int h = static_cast<int>(height_ / ratio);
    small.assign(static_cast<std::size_t>(std::max(w, 0)) * std::max(h, 0), 0.0f);
    for (int j = 0; j < h; ++j) {
      for (int i = 0; i < w; ++i) {
        small[static_cast<std::size_t>(j) * w + i] = static_cast<float>(
            integral.box_mean(i * ratio, j * ratio, (i + 1) * ratio, (j + 1) * ratio));
      }
    }
    gradients(small, w, h, &levels_[static_cast<std::size_t>(k)]);
    levels_[static_cast<std::size_t>(k)].ratio = ratio;
  }
}

int ImageScale::level_for_radius(double r) const {
  if (!(r > base_radius_)) return 0;
  const double step = std::sqrt(2.0);
  int k = 0;
  double low = base_radius_;
  while (r > low * step && k < num_levels() - 1) {
    ++k;
    low *= step;
  }
  return k;
}

}  // namespace geodrift::kvld
