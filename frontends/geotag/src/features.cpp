#include "geodrift/geotag/features.hpp"

#include <algorithm>
#include <limits>

#include "geodrift/error.hpp"
#include "geodrift/geotag/vocabulary.hpp"

namespace geodrift::geotag {

namespace {
void check_gray(const cv::Mat& g, int n, const char* what) {
  GEODRIFT_CHECK(!g.empty(), what << ": the image is empty");
  GEODRIFT_CHECK(g.type() == CV_8UC1, what << ": the image must be 8-bit grayscale");
  GEODRIFT_CHECK(n >= 1, what << ": max_features " << n << " must be >= 1");
}
}  // namespace

Features detect_orb(const cv::Mat& gray, int max_features) {
  check_gray(gray, max_features, "detect_orb");
  Features f;
  cv::Ptr<cv::ORB> orb =
      cv::ORB::create(max_features, 1.2f, 8, 31, 0, 2, cv::ORB::HARRIS_SCORE, 31, 20);
  orb->detectAndCompute(gray, cv::noArray(), f.keypoints, f.descriptors);
  if (f.descriptors.empty()) f.descriptors = cv::Mat(0, 32, CV_8U);
  return f;
}

Features detect_root_sift(const cv::Mat& gray, int max_features) {
  check_gray(gray, max_features, "detect_root_sift");
  Features f;
  cv::Ptr<cv::SIFT> sift = cv::SIFT::create(max_features);
  sift->detectAndCompute(gray, cv::noArray(), f.keypoints, f.descriptors);
  if (f.descriptors.empty()) f.descriptors = cv::Mat(0, 128, CV_32F);
  root_sift(&f.descriptors);
  return f;
}

std::vector<cv::DMatch> match_ratio_mutual(const cv::Mat& query, const cv::Mat& train,
                                           double ratio) {
  GEODRIFT_CHECK(ratio > 0 && ratio <= 1, "match ratio " << ratio << " outside (0, 1]");
  std::vector<cv::DMatch> out;
  if (query.empty() || train.empty()) return out;
  GEODRIFT_CHECK(query.type() == CV_8U && train.type() == CV_8U && query.cols == train.cols,
                 "match_ratio_mutual: binary descriptors of equal width expected");
  cv::BFMatcher bf(cv::NORM_HAMMING, false);
  std::vector<std::vector<cv::DMatch>> fwd;
  bf.knnMatch(query, train, fwd, 2);
  // Best query for every train descriptor (the mutual check).
  std::vector<cv::DMatch> back;
  bf.match(train, query, back);
  std::vector<int> best_query(train.rows, -1);
  for (const cv::DMatch& m : back) best_query[m.queryIdx] = m.trainIdx;
  for (const auto& k : fwd) {
    if (k.empty()) continue;
    const cv::DMatch& m = k[0];
    if (k.size() >= 2 && !(m.distance < ratio * k[1].distance)) continue;
    if (best_query[m.trainIdx] != m.queryIdx) continue;
    out.push_back(m);
  }
  std::sort(out.begin(), out.end(),
            [](const cv::DMatch& a, const cv::DMatch& b) { return a.distance < b.distance; });
  return out;
}

}  // namespace geodrift::geotag
