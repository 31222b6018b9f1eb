// Calibration YAML read by geodrift itself (internal to geodrift::vo).
//
// OpenCV 4.6's FileStorage YAML parser can loop forever on a malformed file
// (docs/fuzzing.md, "OpenCV FileStorage hang"), so YAML calibration files never reach it. This
// reader accepts the subset calibration files use, in one linear pass with no recursion:
//  - OpenCV's own output: `camera_matrix: !!opencv-matrix` (or `K:`) with indented `rows`,
//    `cols`, `dt`, `data: [ ... ]` (the list may span lines), `distortion_coefficients` (or
//    `D`), `image_width`, `image_height`;
//  - ROS camera_info YAML: the same keys without the `!!opencv-matrix` tag;
//  - a plain list: `K: [fx, 0, cx, 0, fy, cy, 0, 0, 1]`, `D: [k1, k2, p1, p2]`;
//  - ORB-SLAM2/3 settings: `Camera.fx` / `Camera1.fx` (fy, cx, cy, k1, k2, p1, p2, k3) and
//    `Camera.width` / `Camera.height`; a `Camera.type` other than PinHole is refused.
// Other keys and their nested blocks are skipped unread.
#pragma once

#include <string>

#include "geodrift/vo/input.hpp"

namespace geodrift::vo::detail {

/// Largest image width or height a calibration file may state (pixels).
inline constexpr int kMaxCalibrationImageSide = 1 << 20;

/// Parses `text` (the contents of `path`, which only names the file in messages).
/// @return false when the text holds no camera matrix in any accepted form.
/// @throws InvalidArgument naming the file and line when a calibration key is malformed.
bool parse_calibration_yaml(const std::string& text, const std::string& path, Calibration* c);

}  // namespace geodrift::vo::detail
