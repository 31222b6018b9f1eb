// ORB extraction with a grid selection.

#include "geodrift/vo/features.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/features2d.hpp>

#include "geodrift/error.hpp"

namespace geodrift::vo {

OrbExtractor::OrbExtractor(const OrbOptions& o) : options_(o) {
  GEODRIFT_CHECK(o.num_features > 0, "num_features " << o.num_features << " must be > 0");
  GEODRIFT_CHECK(o.scale_factor > 1.0f, "scale_factor " << o.scale_factor << " must be > 1");
  GEODRIFT_CHECK(o.num_levels >= 1, "num_levels " << o.num_levels << " must be >= 1");
  GEODRIFT_CHECK(o.cell_size >= 8, "cell_size " << o.cell_size << " must be >= 8");
  GEODRIFT_CHECK(o.oversample >= 1.0, "oversample " << o.oversample << " must be >= 1");
  for (int l = 0; l < o.num_levels; ++l) scales_.push_back(std::pow(double(o.scale_factor), l));
  orb_ =
      cv::ORB::create(static_cast<int>(std::lround(o.num_features * o.oversample)), o.scale_factor,
                      o.num_levels, 19, 0, 2, cv::ORB::HARRIS_SCORE, 31, o.fast_threshold);
}

Features OrbExtractor::extract(const cv::Mat& gray) const {
  GEODRIFT_CHECK(gray.type() == CV_8UC1, "ORB extraction needs an 8-bit grayscale image");
  std::vector<cv::KeyPoint> all;
  cv::Mat desc;
  orb_->detectAndCompute(gray, cv::noArray(), all, desc);
  Features f;
  if (all.empty()) return f;
  // Grid selection: the quota per (cell, octave group) is what an even spread of the budget over
  // the cells would give; strongest responses first. Left-over budget is then filled by
  // response, so low-texture images still get their features.
  const int cs = options_.cell_size;
  const int gx = gray.cols / cs + 1, gy = gray.rows / cs + 1;
  const int quota = std::max(1, options_.num_features / (gx * gy));
  std::vector<int> order(all.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return all[a].response > all[b].response; });
  std::vector<int> count(static_cast<std::size_t>(gx * gy), 0);
  std::vector<char> taken(all.size(), 0);
  std::vector<int> keep;
  keep.reserve(options_.num_features);
  for (int i : order) {
    if (static_cast<int>(keep.size()) >= options_.num_features) break;
    const int c = static_cast<int>(all[i].pt.y) / cs * gx + static_cast<int>(all[i].pt.x) / cs;
    if (count[c] < quota) {
      ++count[c];
      taken[i] = 1;
      keep.push_back(i);
    }
  }
  for (int i : order) {
    if (static_cast<int>(keep.size()) >= options_.num_features) break;
    if (!taken[i]) keep.push_back(i);
  }
  std::sort(keep.begin(), keep.end());
  f.keypoints.reserve(keep.size());
  f.descriptors.create(static_cast<int>(keep.size()), 32, CV_8UC1);
  for (std::size_t k = 0; k < keep.size(); ++k) {
    f.keypoints.push_back(all[keep[k]]);
    desc.row(keep[k]).copyTo(f.descriptors.row(static_cast<int>(k)));
  }
  return f;
}

}  // namespace geodrift::vo
