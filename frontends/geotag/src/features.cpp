#include "geodrift/geotag/features.hpp"

#include <algorithm>
#include <cstdint>
#include <cstring>
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

namespace {

/// One pass over all query x train pairs (the Hamming distance of each pair is computed once):
/// per query the best and second-best distance and the best train index, per train the best
/// query index. Ties keep the lower index (strict <, ascending loops), as a brute-force scan
/// does. Descriptors are packed into 64-bit words, zero-padded (padding adds no distance).
template <int kWords>
void hamming_pass(const std::uint64_t* q, int nq, const std::uint64_t* t, int nt, int words,
                  int* q_best, int* q_second, int* q_idx, int* t_best, int* t_idx) {
  const int w = kWords > 0 ? kWords : words;
  for (int i = 0; i < nq; ++i) {
    const std::uint64_t* a = q + static_cast<std::size_t>(i) * w;
    int b1 = std::numeric_limits<int>::max(), b2 = b1, bi = -1;
    for (int j = 0; j < nt; ++j) {
      const std::uint64_t* b = t + static_cast<std::size_t>(j) * w;
      int d = 0;
      for (int k = 0; k < w; ++k) d += __builtin_popcountll(a[k] ^ b[k]);
      if (d < b1) {
        b2 = b1;
        b1 = d;
        bi = j;
      } else if (d < b2) {
        b2 = d;
      }
      if (d < t_best[j]) {
        t_best[j] = d;
        t_idx[j] = i;
      }
    }
    q_best[i] = b1;
    q_second[i] = b2;
    q_idx[i] = bi;
  }
}

#if defined(__GNUC__) && defined(__x86_64__)
// The same loop compiled for the POPCNT instruction (x86-64 baseline lacks it; every x86-64 CPU
// since 2008 has it), chosen at run time.
__attribute__((target("popcnt"))) void hamming_pass_popcnt4(const std::uint64_t* q, int nq,
                                                            const std::uint64_t* t, int nt,
                                                            int* q_best, int* q_second, int* q_idx,
                                                            int* t_best, int* t_idx) {
  hamming_pass<4>(q, nq, t, nt, 4, q_best, q_second, q_idx, t_best, t_idx);
}
__attribute__((target("popcnt"))) void hamming_pass_popcnt(const std::uint64_t* q, int nq,
                                                           const std::uint64_t* t, int nt,
                                                           int words, int* q_best, int* q_second,
                                                           int* q_idx, int* t_best, int* t_idx) {
  hamming_pass<0>(q, nq, t, nt, words, q_best, q_second, q_idx, t_best, t_idx);
}
#endif

std::vector<std::uint64_t> pack_words(const cv::Mat& d, int words) {
  std::vector<std::uint64_t> out(static_cast<std::size_t>(d.rows) * words, 0);
  for (int r = 0; r < d.rows; ++r)
    std::memcpy(out.data() + static_cast<std::size_t>(r) * words, d.ptr<std::uint8_t>(r),
                static_cast<std::size_t>(d.cols));
  return out;
}

}  // namespace

std::vector<cv::DMatch> match_ratio_mutual(const cv::Mat& query, const cv::Mat& train,
                                           double ratio) {
  GEODRIFT_CHECK(ratio > 0 && ratio <= 1, "match ratio " << ratio << " outside (0, 1]");
  std::vector<cv::DMatch> out;
  if (query.empty() || train.empty()) return out;
  GEODRIFT_CHECK(query.type() == CV_8U && train.type() == CV_8U && query.cols == train.cols,
                 "match_ratio_mutual: binary descriptors of equal width expected");
  const int words = (query.cols + 7) / 8;
  const std::vector<std::uint64_t> q = pack_words(query, words), t = pack_words(train, words);
  const int nq = query.rows, nt = train.rows;
  std::vector<int> q_best(nq), q_second(nq), q_idx(nq);
  std::vector<int> t_best(nt, std::numeric_limits<int>::max()), t_idx(nt, -1);
#if defined(__GNUC__) && defined(__x86_64__)
  if (__builtin_cpu_supports("popcnt")) {
    if (words == 4)
      hamming_pass_popcnt4(q.data(), nq, t.data(), nt, q_best.data(), q_second.data(), q_idx.data(),
                           t_best.data(), t_idx.data());
    else
      hamming_pass_popcnt(q.data(), nq, t.data(), nt, words, q_best.data(), q_second.data(),
                          q_idx.data(), t_best.data(), t_idx.data());
  } else
#endif
  {
    hamming_pass<0>(q.data(), nq, t.data(), nt, words, q_best.data(), q_second.data(), q_idx.data(),
                    t_best.data(), t_idx.data());
  }
  for (int i = 0; i < nq; ++i) {
    const int j = q_idx[i];
    // A single train descriptor has no second neighbour: the ratio test does not apply.
    if (nt >= 2 && !(q_best[i] < ratio * q_second[i])) continue;
    if (t_idx[j] != i) continue;
    out.emplace_back(i, j, static_cast<float>(q_best[i]));
  }
  std::stable_sort(out.begin(), out.end(), [](const cv::DMatch& a, const cv::DMatch& b) {
    return a.distance < b.distance;
  });
  return out;
}

}  // namespace geodrift::geotag
