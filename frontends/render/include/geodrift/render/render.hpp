#pragma once

/// @file
/// Rendering the street world: pinhole frames (the video) and level equirectangular panoramas
/// (the geo-tagged "street view" images).
///
/// Pinhole convention: map::Camera (fx, fy, cx, cy, width, height), OpenCV pixel centres: the
/// centre of pixel (col, row) is at image coordinates (u, v) = (col, row), so a camera-frame point
/// (x, y, z) is seen at pixel (fx·x/z + cx, fy·y/z + cy) (map::Camera::project). Poses are T_cw
/// in W (world.hpp); a KITTI pose T_K_c converts with geo::kitti_pose_to_T_cw, or use
/// World::frame_T_cw(i).
///
/// Panorama convention (fixed interface, also in dataset.hpp): the panorama is level
/// (gravity-aligned). Column u (0..W-1) looks along the true bearing
///     beta(u) = heading + 360 deg · ((u + 0.5)/W − 0.5)      (clockwise from TRUE north),
/// row v (0..H-1) along the elevation
///     el(v) = 90 deg − 180 deg · (v + 0.5)/H.
/// The centre column (u + 0.5 = W/2) looks along `heading`. True bearings become W directions
/// with the meridian convergence at the panorama centre (geo::LocalFrame of the world):
/// grid yaw = 90 deg − beta + gamma, direction = (cos el cos yaw, cos el sin yaw, sin el).
///
/// Anti-aliasing: every pixel averages several rays over its footprint (quincunx by default: the
/// pixel centre with weight 1/2 and its four corners with 1/8, corners shared with the
/// neighbours, about 2 rays per pixel; or an n×n grid), and textures are band-limited by the
/// ray's footprint, so features are sub-pixel stable from frame to frame.
///
/// Images are cv::Mat: CV_8UC1 (grey, luma 0.299 R + 0.587 G + 0.114 B) or CV_8UC3 (BGR, as
/// cv::imwrite expects, so PNG files are RGB). Rendering uses `threads` std::threads (0 = all
/// hardware threads); the result does not depend on the thread count.

#include <opencv2/core.hpp>

#include "geodrift/map/camera.hpp"
#include "geodrift/render/world.hpp"

namespace geodrift::render {

/// Anti-aliasing pattern.
enum class Antialias {
  kNone,      ///< one ray per pixel (centre)
  kQuincunx,  ///< centre (1/2) + 4 shared corners (1/8 each): ~2 rays per pixel (default)
  kGrid,      ///< grid_n × grid_n stratified rays per pixel
};

/// Options of one render call.
struct RenderOptions {
  bool color = false;  ///< CV_8UC3 BGR when true, else CV_8UC1 grey
  Antialias antialias = Antialias::kQuincunx;
  int grid_n = 2;   ///< rays per pixel side for Antialias::kGrid (1..8)
  int threads = 0;  ///< worker threads (0 = hardware concurrency)
};

/// Renders a pinhole frame.
/// @param T_cw   W -> camera pose.
/// @param camera intrinsics and size (validated).
/// @throws InvalidArgument for an invalid camera or options, or a non-finite pose.
cv::Mat render_pinhole(const World& world, const lie::SE3d& T_cw, const map::Camera& camera,
                       const Appearance& appearance, const RenderOptions& options = {});

/// Renders the depth (camera-frame z, metres; +inf for sky) of the pixel-centre rays of a
/// pinhole frame, CV_32FC1. Ground truth for tests; the VO never sees it.
cv::Mat render_depth(const World& world, const lie::SE3d& T_cw, const map::Camera& camera,
                     const Appearance& appearance, int threads = 0);

/// Panorama size and options.
struct PanoramaOptions {
  int width = 2048;                                        ///< columns (360 deg)
  int height = 1024;                                       ///< rows (180 deg)
  RenderOptions render{true, Antialias::kQuincunx, 2, 0};  ///< colour by default
};

/// Renders a level equirectangular panorama centred at `centre` (W) whose centre column looks
/// along the true bearing `heading` (radians, clockwise from true north). See the file comment.
/// @throws InvalidArgument for a non-finite centre/heading or a size below 8x4.
cv::Mat render_panorama(const World& world, const Eigen::Vector3d& centre, double heading,
                        const Appearance& appearance, const PanoramaOptions& options = {});

/// Unit W direction of panorama image coordinates (u, v) (continuous; the centre of pixel
/// (col, row) is (col + 0.5, row + 0.5)) for a panorama of size width × height with the given
/// heading (rad) and meridian convergence gamma (rad) at its centre.
Eigen::Vector3d panorama_direction(double u, double v, int width, int height, double heading,
                                   double gamma);

/// Inverse of panorama_direction(): continuous image coordinates (u in [0, width), v in
/// [0, height]) of a W direction.
Eigen::Vector2d panorama_pixel(const Eigen::Vector3d& dir, int width, int height, double heading,
                               double gamma);

}  // namespace geodrift::render
