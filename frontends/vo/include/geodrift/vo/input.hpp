#pragma once
/// @file
/// VO input: calibration files and frame sources (an image folder sorted by name, KITTI layout
/// included, or a video through cv::VideoCapture). Images only: the VO never reads depth or poses.
/// Intrinsics in pixels, OpenCV distortion order (k1, k2, p1, p2[, k3]); frames are undistorted
/// here (Undistorter) so that everything downstream sees a plain pinhole map::Camera.

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "geodrift/map/camera.hpp"

namespace geodrift::vo {

/// Pinhole intrinsics plus optional OpenCV distortion (k1, k2, p1, p2[, k3 ...]).
/// `camera.width/height` are 0 until known (KITTI calib.txt carries no image size); the frame
/// source fills them from the first image.
struct Calibration {
  map::Camera camera;
  std::vector<double> distortion;  ///< OpenCV order; empty or all zero = no distortion
  std::string source;              ///< file it was read from (for messages)

  bool has_distortion() const {
    for (double d : distortion)
      if (d != 0.0) return true;
    return false;
  }
};

/// Reads a calibration file. Accepted forms (first match wins):
///  - KITTI `calib.txt`: a line `P0: p00 p01 ... p23` (3x4 projection, row-major);
///    fx = p00, cx = p02, fy = p11, cy = p12 (no distortion).
///  - plain text with `K: fx 0 cx 0 fy cy 0 0 1` (9 numbers), optional `D: k1 k2 p1 p2 [k3]`
///    and `size: width height`.
///  - YAML with `camera_matrix` or `K` (3x3) as an OpenCV `!!opencv-matrix`, a ROS
///    camera_info rows/cols/data block or a 9-number list, optional `distortion_coefficients`
///    or `D`, `image_width`, `image_height`; or an ORB-SLAM2/3 settings file (`Camera.fx` /
///    `Camera1.fx`, fy, cx, cy, k1, k2, p1, p2, k3, `Camera.width`, `Camera.height`). geodrift
///    parses YAML itself (OpenCV 4.6's YAML parser can hang on malformed files).
///  - OpenCV FileStorage XML with the same keys as the OpenCV YAML.
/// @throws Error when the file is missing/unreadable, InvalidArgument when no calibration is
///         found in it or the intrinsics are not finite and positive.
Calibration load_calibration(const std::string& path);

/// One input frame, 8-bit grayscale.
struct Frame {
  int index = 0;           ///< 0-based position in the source
  double timestamp = 0.0;  ///< seconds (times.txt, video position, or index / fps)
  std::string name;        ///< file name (image folders) or "frame_<index>" (video)
  cv::Mat gray;            ///< CV_8UC1
};

/// A sequential source of frames.
class FrameSource {
 public:
  virtual ~FrameSource() = default;
  /// Next frame, false at the end. @throws Error when an image cannot be read.
  virtual bool next(Frame* frame) = 0;
  /// Number of frames if known (image folders), else -1.
  virtual int size() const = 0;
  /// Human-readable description for messages/reports.
  virtual std::string description() const = 0;
};

/// Image folder: DIR/image_0/ *.png (KITTI) if it exists, else DIR/ *.{png,jpg,jpeg,pgm,ppm,bmp,
/// tif,tiff}, sorted by name. Timestamps from DIR/times.txt (one per line, KITTI) when present
/// with one line per image, else index / `fps`.
/// @throws Error when the folder is missing or holds no images.
std::unique_ptr<FrameSource> open_image_folder(const std::string& dir, double fps = 10.0);

/// Video file through cv::VideoCapture; timestamps from the container (CAP_PROP_POS_MSEC), else
/// index / fps. @throws Error when the file is missing, cannot be opened or has no first frame.
std::unique_ptr<FrameSource> open_video(const std::string& path);

/// The calibration that belongs to an image folder when none is given: DIR/calib.txt. Returns ""
/// when there is none.
std::string default_calibration_path(const std::string& image_dir);

/// Undistorts frames to the pinhole camera of `calibration` (same K), or passes them through
/// when there is no distortion. Built once per image size.
class Undistorter {
 public:
  explicit Undistorter(const Calibration& calibration) : calib_(calibration) {}
  /// Returns the undistorted image (or `gray` itself without distortion).
  cv::Mat apply(const cv::Mat& gray);

 private:
  Calibration calib_;
  cv::Mat map1_, map2_;
  cv::Size size_;
};

}  // namespace geodrift::vo
