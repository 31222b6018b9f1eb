#pragma once

/// @file
/// Cutting an equirectangular panorama into rectilinear views (the paper's Sec. 3.3,
/// "Geo-tagged Image Collection": each Street View panorama becomes eight rectilinear images
/// with the video's field of view, at eight horizontal directions).
///
/// Panorama convention (the renderer's, and Street View's once its heading is known): the
/// panorama is LEVEL; column u (pixel centres at u + 0.5) maps to the bearing
///
///     beta(u) = heading + 2*pi * ((u + 0.5) / W - 0.5)        (clockwise from true north)
///
/// so the centre column looks along the panorama's `heading`; row v maps to the elevation
///
///     el(v) = pi/2 - pi * (v + 0.5) / H                        (up positive).
///
/// A view is a level pinhole camera (x right, y down, z forward; DESIGN.md) whose optical axis
/// has the bearing heading + offset. Pixel (x, y) of the view looks along
///     d_cam = ((x - cx)/fx, (y - cy)/fy, 1),
/// which, in the panorama's (east', north', up) frame rotated by `offset`, is
///     d = d_cam.x * (cos o, -sin o, 0) + d_cam.y * (0, 0, -1) + d_cam.z * (sin o, cos o, 0).

#include <opencv2/core.hpp>

#include "geodrift/map/camera.hpp"

namespace geodrift::geotag {

/// Views per panorama and their spacing (the paper: eight horizontal directions).
inline constexpr int kViewsPerPanorama = 8;
inline constexpr double kViewStepDeg = 360.0 / kViewsPerPanorama;

/// The remap tables of one view: for every view pixel, the (sub-pixel) panorama column and row
/// it samples (CV_32FC1 each, view height x width). Columns are in [0, W); the horizontal seam
/// is handled by cv::BORDER_WRAP in cut_panorama_view().
/// @param pano_width, pano_height  panorama size W x H (W = 2 H for a full equirectangular
///                                 image; other sizes are accepted as long as both are > 1).
/// @param view      the view's pinhole intrinsics and size.
/// @param offset    bearing of the view's optical axis minus the panorama's heading, radians,
///                  clockwise (view k of 8 has offset k * 45 deg).
/// @throws InvalidArgument for an invalid camera, a non-finite offset or a panorama smaller than
///         2 x 2.
void panorama_view_maps(int pano_width, int pano_height, const map::Camera& view, double offset,
                        cv::Mat* map_x, cv::Mat* map_y);

/// Cuts one rectilinear view out of an equirectangular panorama (any depth and channel count
/// that cv::remap takes), bilinear interpolation, horizontal wrap-around at the seam.
/// @throws InvalidArgument for an empty panorama and as panorama_view_maps().
cv::Mat cut_panorama_view(const cv::Mat& pano, const map::Camera& view, double offset);

/// Cuts views of one panorama size with one view camera, the remap tables computed once: the
/// view at offset o samples the rows of the view at offset 0 and its columns shifted by
/// W * o / (2 pi) (the bearing of every view pixel grows by o, its elevation is unchanged), so
/// a view costs the remap only. Equal to cut_panorama_view() up to float rounding of the tables.
class PanoramaCutter {
 public:
  /// @throws InvalidArgument as panorama_view_maps().
  PanoramaCutter(int pano_width, int pano_height, const map::Camera& view);
  /// True when this cutter was made for that panorama size and view camera.
  bool fits(int pano_width, int pano_height, const map::Camera& view) const;
  /// The view at `offset` (radians, as cut_panorama_view()).
  /// @throws InvalidArgument for a panorama of another size or a non-finite offset.
  cv::Mat cut(const cv::Mat& pano, double offset) const;

 private:
  int width_, height_;
  map::Camera view_;
  cv::Mat map_x_, map_y_;  ///< offset 0
};

/// The unit direction, in the panorama's (east, north, up) frame, of the panorama pixel centre
/// (u, v) (continuous coordinates; pixel centres at integers). Tests and the renderer's checks.
cv::Vec3d panorama_pixel_direction(double u, double v, int pano_width, int pano_height,
                                   double heading);

}  // namespace geodrift::geotag
