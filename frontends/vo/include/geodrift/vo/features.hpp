#pragma once
/// @file
/// ORB features spread over the image: OpenCV's ORB pyramid detector, then a grid selection
/// (strongest responses per cell first, as ORB-SLAM's distribution step intends), so texture-
/// rich corners do not take the whole budget.
/// Keypoints are OpenCV's (cv::KeyPoint: level-0 pixels of the undistorted image, x right,
/// y down; octave = pyramid level); descriptors are 256-bit ORB rows (CV_8U, 32 columns).

#include <cstdint>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <vector>

namespace geodrift::vo {

struct OrbOptions {
  int num_features = 2000;    ///< kept after the grid selection
  float scale_factor = 1.2f;  ///< pyramid scale between levels
  int num_levels = 8;         ///< pyramid levels
  int fast_threshold = 12;    ///< FAST threshold (grey levels)
  int cell_size = 40;         ///< grid cell, level-0 pixels
  double oversample = 1.5;    ///< detector budget = oversample * num_features (>= 1)
};

/// Keypoints (cv::KeyPoint: pixel, size, angle, octave) and their 256-bit descriptors
/// (rows of a CV_8UC1 N x 32 matrix).
struct Features {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
};

class OrbExtractor {
 public:
  explicit OrbExtractor(const OrbOptions& options = {});
  /// Features of an 8-bit grayscale image; empty for a black or textureless image.
  Features extract(const cv::Mat& gray) const;
  const OrbOptions& options() const { return options_; }
  /// Scale of pyramid level `octave` relative to level 0.
  double level_scale(int octave) const { return scales_.at(static_cast<std::size_t>(octave)); }

 private:
  OrbOptions options_;
  std::vector<double> scales_;
  cv::Ptr<cv::Feature2D> orb_;
};

/// Bits set in a 64-bit word: the popcnt instruction where the build targets it, else an inline
/// SWAR count (a generic x86-64 build would otherwise call libgcc's table-based __popcountdi2).
inline int popcount64(std::uint64_t x) {
#if defined(__POPCNT__)
  return __builtin_popcountll(x);
#else
  x = x - ((x >> 1) & 0x5555555555555555ULL);
  x = (x & 0x3333333333333333ULL) + ((x >> 2) & 0x3333333333333333ULL);
  x = (x + (x >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
  return static_cast<int>((x * 0x0101010101010101ULL) >> 56);
#endif
}

/// Hamming distance between two 32-byte ORB descriptors.
inline int hamming(const std::uint8_t* a, const std::uint8_t* b) {
  int d = 0;
  for (int i = 0; i < 32; i += 8) {
    std::uint64_t x, y;
    __builtin_memcpy(&x, a + i, 8);
    __builtin_memcpy(&y, b + i, 8);
    d += popcount64(x ^ y);
  }
  return d;
}

}  // namespace geodrift::vo
