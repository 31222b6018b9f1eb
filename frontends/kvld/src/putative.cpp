// Putative matching before K-VLD: brute-force nearest neighbours, ratio test, mutual check, cap.
#include <algorithm>
#include <cmath>
#include <opencv2/features2d.hpp>
#include <sstream>

#include "geodrift/error.hpp"
#include "geodrift/kvld/kvld.hpp"

namespace geodrift::kvld {

bool PutativeOptions::validate(std::string* why) const {
  std::ostringstream os;
  if (!(std::isfinite(ratio) && ratio > 0 && ratio <= 1)) {
    os << "ratio " << ratio << " outside (0, 1]";
  } else if (max_matches < 0) {
    os << "max_matches " << max_matches << " must be >= 0 (0 = no cap)";
  }
  const std::string msg = os.str();
  if (why) *why = msg;
  return msg.empty();
}

std::vector<Match> match_putative(const cv::Mat& desc1, const cv::Mat& desc2,
                                  const PutativeOptions& options) {
  std::string why;
  GEODRIFT_CHECK(options.validate(&why), "kvld::match_putative: invalid options: " << why);
  if (desc1.empty() || desc2.empty()) return {};
  GEODRIFT_CHECK(desc1.type() == desc2.type(), "kvld::match_putative: descriptor types differ ("
                                                   << desc1.type() << " vs " << desc2.type()
                                                   << ")");
  GEODRIFT_CHECK(desc1.cols == desc2.cols, "kvld::match_putative: descriptor widths differ ("
                                               << desc1.cols << " vs " << desc2.cols << ")");
  GEODRIFT_CHECK(desc1.type() == CV_8UC1 || desc1.type() == CV_32FC1,
                 "kvld::match_putative: descriptors must be CV_8UC1 (binary, Hamming) or "
                 "CV_32FC1 (L2), got type "
                     << desc1.type());
  if (desc2.rows < 2) return {};
  const int norm = desc1.type() == CV_8UC1 ? cv::NORM_HAMMING : cv::NORM_L2;
  cv::BFMatcher matcher(norm, /*crossCheck=*/false);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(desc1, desc2, knn, 2);
  std::vector<int> back;  // nearest neighbour in image 1 of each row of desc2
  if (options.mutual) {
    std::vector<cv::DMatch> rev;
    matcher.match(desc2, desc1, rev);
    back.assign(static_cast<std::size_t>(desc2.rows), -1);
    for (const cv::DMatch& m : rev) back[static_cast<std::size_t>(m.queryIdx)] = m.trainIdx;
  }
  std::vector<cv::DMatch> kept;
  for (const auto& cand : knn) {
    if (cand.size() < 2) continue;
    if (!(cand[0].distance < options.ratio * cand[1].distance)) continue;
    if (options.mutual && back[static_cast<std::size_t>(cand[0].trainIdx)] != cand[0].queryIdx) {
      continue;
    }
    kept.push_back(cand[0]);
  }
  std::stable_sort(kept.begin(), kept.end(), [](const cv::DMatch& a, const cv::DMatch& b) {
    return a.distance < b.distance;
  });
  if (options.max_matches > 0 && kept.size() > static_cast<std::size_t>(options.max_matches)) {
    kept.resize(static_cast<std::size_t>(options.max_matches));
  }
  std::vector<Match> out;
  out.reserve(kept.size());
  for (const cv::DMatch& m : kept) out.push_back({m.queryIdx, m.trainIdx});
  return out;
}

}  // namespace geodrift::kvld
