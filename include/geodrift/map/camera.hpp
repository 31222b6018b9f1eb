#pragma once

/// @file
/// map::Camera: the pinhole intrinsics (fx, fy, cx, cy in pixels, image size) shared by the
/// core and the frontends. Images are undistorted by the front end, so there are no distortion
/// terms. Camera frame x right, y down, z forward (OpenCV, DESIGN.md); pixel centres at integer
/// coordinates.

#include <Eigen/Core>
#include <cmath>

#include "geodrift/error.hpp"

namespace geodrift::map {

/// Pinhole camera in pixels. The front end undistorts before the core, so there are no
/// distortion terms. Pixel (u, v) = (fx·x/z + cx, fy·y/z + cy) for a point (x, y, z) in the
/// camera frame (x right, y down, z forward; DESIGN.md).
struct Camera {
  int id = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;

  /// Projects a camera-frame point; the caller checks z > 0.
  Eigen::Vector2d project(const Eigen::Vector3d& p_c) const {
    return {fx * p_c.x() / p_c.z() + cx, fy * p_c.y() / p_c.z() + cy};
  }
  /// True when pixel (u, v) lies inside [0, width) x [0, height).
  bool in_image(const Eigen::Vector2d& uv) const {
    return uv.x() >= 0 && uv.y() >= 0 && uv.x() < width && uv.y() < height;
  }
  /// @throws InvalidArgument unless fx, fy > 0, cx, cy finite and width, height > 0.
  void validate() const {
    GEODRIFT_CHECK(std::isfinite(fx) && fx > 0, "camera " << id << ": fx " << fx << " must be > 0");
    GEODRIFT_CHECK(std::isfinite(fy) && fy > 0, "camera " << id << ": fy " << fy << " must be > 0");
    GEODRIFT_CHECK(std::isfinite(cx) && std::isfinite(cy),
                   "camera " << id << ": principal point (" << cx << ", " << cy << ") not finite");
    GEODRIFT_CHECK(width > 0 && height > 0,
                   "camera " << id << ": image size " << width << "x" << height << " not positive");
  }
};

}  // namespace geodrift::map
