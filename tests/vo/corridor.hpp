#pragma once
// A tiny ray-cast test world for the VO tracker: a textured ground plane and two textured walls
// (blocky multi-scale value noise, so FAST/ORB find corners), seen by a pinhole camera driving
// down the corridor. Frame W = the camera frame at z = 0 (x right, y down, z forward).

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>

#include "geodrift/map/camera.hpp"

namespace geodrift::test {

struct Corridor {
  double ground_y = 1.65;  ///< metres below the camera
  double wall_x = 6.0;     ///< walls at x = -wall_x and +wall_x
  unsigned seed = 1;

  static double hash01(std::int64_t a, std::int64_t b, std::int64_t c, unsigned seed) {
    std::uint64_t h = static_cast<std::uint64_t>(a) * 0x9E3779B97F4A7C15ull ^
                      static_cast<std::uint64_t>(b) * 0xC2B2AE3D27D4EB4Full ^
                      static_cast<std::uint64_t>(c) * 0x165667B19E3779F9ull ^ seed;
    h ^= h >> 31;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 29;
    return static_cast<double>(h & 0xFFFFFF) / 16777215.0;
  }
  double texture(double a, double b, int plane) const {
    double v = 0, w = 0;
    const double cells[3] = {0.25, 0.7, 2.3};
    for (int s = 0; s < 3; ++s) {
      const double c = cells[s];
      v += (s + 1.0) * hash01(static_cast<std::int64_t>(std::floor(a / c)),
                              static_cast<std::int64_t>(std::floor(b / c)), plane * 7 + s, seed);
      w += s + 1.0;
    }
    return v / w;
  }
  /// Intensity seen along ray origin o, direction d (world).
  double shade(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
    double best = 1e9;
    double val = 0.8;  // sky
    if (d.y() > 1e-9) {
      const double t = (ground_y - o.y()) / d.y();
      if (t > 0 && t < best) {
        const Eigen::Vector3d p = o + t * d;
        best = t;
        val = texture(p.x(), p.z(), 0);
      }
    }
    for (int side = 0; side < 2; ++side) {
      const double x = side ? wall_x : -wall_x;
      if (std::abs(d.x()) < 1e-9) continue;
      const double t = (x - o.x()) / d.x();
      if (t > 0 && t < best) {
        const Eigen::Vector3d p = o + t * d;
        if (p.y() < -6.0) continue;  // walls 7.65 m high
        best = t;
        val = texture(p.z(), p.y(), 1 + side);
      }
    }
    if (best > 150) val = 0.8 - 0.5 * (0.8 - val) * std::exp(-(best - 150) / 50);  // haze
    return val;
  }
  /// Renders T_wc with 2x2 supersampling.
  cv::Mat render(const map::Camera& cam, const Eigen::Isometry3d& T_wc) const {
    cv::Mat img(cam.height, cam.width, CV_8UC1);
    const Eigen::Matrix3d R = T_wc.rotation();
    const Eigen::Vector3d o = T_wc.translation();
    for (int v = 0; v < cam.height; ++v)
      for (int u = 0; u < cam.width; ++u) {
        double acc = 0;
        for (int s = 0; s < 4; ++s) {
          const double uu = u + 0.25 + 0.5 * (s & 1), vv = v + 0.25 + 0.5 * (s >> 1);
          const Eigen::Vector3d d =
              R * Eigen::Vector3d((uu - cam.cx) / cam.fx, (vv - cam.cy) / cam.fy, 1.0);
          acc += shade(o, d);
        }
        img.at<std::uint8_t>(v, u) = static_cast<std::uint8_t>(std::lround(20 + 215 * acc / 4));
      }
    return img;
  }
  /// A gently weaving forward drive: `step` metres per frame, yaw oscillating by a few degrees.
  static Eigen::Isometry3d pose(int i, double step = 0.8) {
    const double z = step * i;
    const double x = 1.2 * std::sin(z / 25.0);
    const double yaw = std::atan(1.2 / 25.0 * std::cos(z / 25.0));
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(x, 0, z);
    return T;
  }
};

inline map::Camera corridor_camera() {
  map::Camera c;
  c.fx = c.fy = 360;
  c.cx = 320;
  c.cy = 120;
  c.width = 640;
  c.height = 240;
  return c;
}

}  // namespace geodrift::test
