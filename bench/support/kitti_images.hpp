#pragma once

// A real photo brought to KITTI's frame size for the OpenCV benches (bench_kvld, bench_geotag):
// grey, resized to 1241 px wide, the middle 376 rows.

#include <algorithm>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

namespace geodrift::bench {

/// Empty when the file cannot be read.
inline cv::Mat load_kitti_sized(const std::string& path) {
  const cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
  if (img.empty()) return img;
  cv::Mat small;
  const double s = 1241.0 / img.cols;
  cv::resize(img, small, cv::Size(), s, s, cv::INTER_AREA);
  const int y0 = std::max(0, (small.rows - 376) / 2);
  return small(cv::Rect(0, y0, small.cols, std::min(376, small.rows))).clone();
}

}  // namespace geodrift::bench
