#pragma once

/// @file
/// Local features of the geotag pipeline: ORB (matching, the paper's Sec. 3.3 "Keypoint
/// Matching") and SIFT (retrieval), and the putative ORB matcher (Lowe ratio test + mutual
/// nearest-neighbour check, Hamming distance).
/// Keypoints are OpenCV's (cv::KeyPoint: pixels of the full-resolution image, x right, y down,
/// angle in degrees); OpenCV types stay inside the frontend.

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <vector>

namespace geodrift::geotag {

/// Keypoints and their descriptors (one row per keypoint).
struct Features {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;  ///< ORB: CV_8U x 32; SIFT: CV_32F x 128
};

/// ORB on a grayscale image (OpenCV ORB, FAST threshold 20, 8 levels, scale 1.2).
/// @throws InvalidArgument for an empty or non-8-bit image or max_features < 1.
Features detect_orb(const cv::Mat& gray, int max_features);

/// RootSIFT (root_sift() of OpenCV's SIFT) on a grayscale image, at most max_features.
/// @throws InvalidArgument as detect_orb().
Features detect_root_sift(const cv::Mat& gray, int max_features);

/// Putative ORB matches query -> train: nearest neighbour in Hamming distance kept when it is
/// clearly better than the second (d1 < ratio * d2) and the train descriptor's nearest
/// neighbour among the query descriptors is the same query descriptor (mutual check). DMatch
/// queryIdx / trainIdx index the two descriptor sets; sorted by distance.
/// @throws InvalidArgument if the descriptors are not CV_8U with equal widths or ratio is
///         outside (0, 1].
std::vector<cv::DMatch> match_ratio_mutual(const cv::Mat& query, const cv::Mat& train,
                                           double ratio = 0.8);

}  // namespace geodrift::geotag
