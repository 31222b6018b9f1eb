// K-VLD on a synthetic pair: image 2 is a similarity warp of a textured image 1, inliers are
// ORB keypoints mapped through the warp, outliers random pairings.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "geodrift/kvld/kvld.hpp"

namespace kvld = geodrift::kvld;

namespace {
constexpr double kPi = 3.14159265358979323846;

cv::Mat texture(int w, int h, unsigned seed) {
  cv::Mat noise(h, w, CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::UNIFORM, 0.0, 1.0);
  cv::Mat smooth;
  cv::GaussianBlur(noise, smooth, cv::Size(0, 0), 2.5);
  cv::normalize(smooth, smooth, 0, 255, cv::NORM_MINMAX);
  cv::Mat out;
  smooth.convertTo(out, CV_8U);
  for (int k = 0; k < 40; ++k) {  // some straight edges and corners
    const cv::Point p(rng.uniform(0, w), rng.uniform(0, h));
    cv::rectangle(out, p, p + cv::Point(rng.uniform(10, 60), rng.uniform(10, 60)),
                  cv::Scalar(rng.uniform(0, 255)), cv::FILLED);
  }
  return out;
}

struct SyntheticPair {
  cv::Mat img1, img2;
  std::vector<kvld::Keypoint> F1, F2;
  std::vector<kvld::Match> putative;
  std::set<int> inliers;  // indices into putative
};

/// Image 2 = s·R(phi)·p + t of image 1; `n_in` true matches, `n_out` random ones, shuffled.
SyntheticPair make_pair(int n_in, int n_out, unsigned seed) {
  SyntheticPair sp;
  const int w = 480, h = 360;
  sp.img1 = texture(w, h, seed);
  const double s = 0.9, phi = 10 * kPi / 180;
  const double c = s * std::cos(phi), sn = s * std::sin(phi);
  const cv::Matx23d A(c, -sn, 40, sn, c, -10);
  cv::warpAffine(sp.img1, sp.img2, A, sp.img1.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  std::vector<cv::KeyPoint> kps;
  cv::ORB::create(3000)->detect(sp.img1, kps);
  std::mt19937 rng(seed);
  std::shuffle(kps.begin(), kps.end(), rng);
  std::vector<std::pair<kvld::Match, bool>> all;
  for (const cv::KeyPoint& k : kps) {
    if (static_cast<int>(all.size()) >= n_in) break;
    const double x2 = A(0, 0) * k.pt.x + A(0, 1) * k.pt.y + A(0, 2);
    const double y2 = A(1, 0) * k.pt.x + A(1, 1) * k.pt.y + A(1, 2);
    if (x2 < 5 || y2 < 5 || x2 > w - 6 || y2 > h - 6) continue;
    const kvld::Keypoint a = kvld::keypoints_from_cv({k})[0];
    sp.F1.push_back(a);
    sp.F2.push_back({x2, y2, a.scale * s, a.angle + phi});
    all.push_back({{static_cast<int>(sp.F1.size()) - 1, static_cast<int>(sp.F2.size()) - 1}, true});
  }
  REQUIRE(static_cast<int>(all.size()) == n_in);
  std::uniform_real_distribution<double> ux(0, w - 1), uy(0, h - 1), ua(0, 2 * kPi), us(8, 60);
  std::uniform_int_distribution<int> pick(0, n_in - 1);
  for (int k = 0; k < n_out; ++k) {
    // A wrong partner for an existing image-1 point, or a fresh random point pair.
    sp.F2.push_back({ux(rng), uy(rng), us(rng), ua(rng)});
    int i1 = pick(rng);
    if (k % 2 == 0) {
      sp.F1.push_back({ux(rng), uy(rng), us(rng), ua(rng)});
      i1 = static_cast<int>(sp.F1.size()) - 1;
    }
    all.push_back({{i1, static_cast<int>(sp.F2.size()) - 1}, false});
  }
  std::shuffle(all.begin(), all.end(), rng);
  for (std::size_t i = 0; i < all.size(); ++i) {
    sp.putative.push_back(all[i].first);
    if (all[i].second) sp.inliers.insert(static_cast<int>(i));
  }
  return sp;
}
}  // namespace

TEST_CASE("K-VLD separates warped-image inliers from random matches", "[kvld][filter]") {
  const SyntheticPair sp = make_pair(250, 750, 7);
  const kvld::ImageScale s1(sp.img1), s2(sp.img2);
  kvld::Options opt;
  opt.collect_edges = true;
  const kvld::Result r = kvld::filter(s1, s2, sp.F1, sp.F2, sp.putative, opt);
  int tp = 0;
  for (int idx : r.kept_indices) tp += sp.inliers.count(idx) ? 1 : 0;
  const double precision = r.kept_indices.empty() ? 0.0 : double(tp) / r.kept_indices.size();
  const double recall = double(tp) / sp.inliers.size();
  INFO("kept " << r.kept_indices.size() << " precision " << precision << " recall " << recall
               << " runs " << r.runs);
  CHECK(r.runs == 1);  // 25 % inliers survive: no retry
  CHECK(precision >= 0.98);
  CHECK(recall >= 0.8);
  CHECK(r.survival_ratio == Approx(double(r.kept_indices.size()) / sp.putative.size()));
  REQUIRE(r.matches.size() == r.kept_indices.size());
  REQUIRE(r.scores.size() == r.kept_indices.size());
  for (std::size_t k = 0; k < r.matches.size(); ++k) {
    CHECK(r.matches[k] == sp.putative[static_cast<std::size_t>(r.kept_indices[k])]);
    CHECK(r.num_consistent[k] >= opt.K);
  }
  // One-to-one output.
  std::set<int> used1, used2;
  for (const kvld::Match& m : r.matches) {
    CHECK(used1.insert(m.i1).second);
    CHECK(used2.insert(m.i2).second);
  }
  // Edges join kept matches and are VLD-consistent.
  REQUIRE_FALSE(r.edges.empty());
  const std::set<int> kept(r.kept_indices.begin(), r.kept_indices.end());
  for (const kvld::Edge& e : r.edges) {
    CHECK(e.m1 < e.m2);
    CHECK(kept.count(e.m1) == 1);
    CHECK(kept.count(e.m2) == 1);
    CHECK(e.vld_diff >= 0.0);
    CHECK(e.vld_diff < opt.juge);
  }
}

TEST_CASE("Without any consistent structure K-VLD retries with half the inlier rate and K = 2",
          "[kvld][filter]") {
  SyntheticPair sp = make_pair(10, 600, 11);
  // Drop the ten true matches: nothing but random pairings remains.
  std::vector<kvld::Match> only_out;
  for (std::size_t i = 0; i < sp.putative.size(); ++i)
    if (!sp.inliers.count(static_cast<int>(i))) only_out.push_back(sp.putative[i]);
  const kvld::ImageScale s1(sp.img1), s2(sp.img2);
  const kvld::Result r = kvld::filter(s1, s2, sp.F1, sp.F2, only_out);
  CHECK(r.runs == 5);
  CHECK(r.final_K == 2);
  CHECK(r.final_inlier_rate == Approx(0.04 / 16));
  CHECK(r.survival_ratio < 0.02);

  kvld::Options once;
  once.max_runs = 1;
  const kvld::Result r1 = kvld::filter(s1, s2, sp.F1, sp.F2, only_out, once);
  CHECK(r1.runs == 1);
  CHECK(r1.final_K == 3);
  // Later runs have a larger range, so they test at least the pairs of the first run.
  CHECK(r.tested_pairs > r1.tested_pairs);
}

TEST_CASE("Photometric-only K-VLD (geometry off) still rejects random matches", "[kvld][filter]") {
  const SyntheticPair sp = make_pair(200, 400, 5);
  const kvld::ImageScale s1(sp.img1), s2(sp.img2);
  kvld::Options opt;
  opt.geometry = false;
  std::vector<kvld::Keypoint> F1 = sp.F1, F2 = sp.F2;
  for (auto& k : F1) k.angle = std::numeric_limits<double>::quiet_NaN();  // not needed
  const kvld::Result r = kvld::filter(s1, s2, F1, F2, sp.putative, opt);
  int tp = 0;
  for (int idx : r.kept_indices) tp += sp.inliers.count(idx) ? 1 : 0;
  INFO("kept " << r.kept_indices.size() << " true " << tp);
  CHECK(tp >= 0.7 * sp.inliers.size());
  CHECK(double(tp) / r.kept_indices.size() >= 0.9);
}

TEST_CASE("Putative matching applies the ratio test, the mutual check and the cap",
          "[kvld][putative]") {
  // Binary descriptors built so that the distances are known.
  cv::Mat d1 = cv::Mat::zeros(4, 32, CV_8U), d2 = cv::Mat::zeros(5, 32, CV_8U);
  for (int c = 0; c < 32; ++c) {
    d1.at<unsigned char>(0, c) = 0x00;  // ↔ d2 row 0 (distance 0), row 1 at 8 bits
    d1.at<unsigned char>(1, c) = 0xFF;  // ↔ d2 row 2 (0), row 3 at 16: ratio 0 passes
    d1.at<unsigned char>(2, c) = 0xF0;  // equidistant to rows 0 and 2 (128): fails the ratio
    d1.at<unsigned char>(3, c) = 0x01;  // nearest d2 row 0 (32) but row 0's nearest is d1 row 0
    d2.at<unsigned char>(0, c) = 0x00;
    d2.at<unsigned char>(1, c) = c < 8 ? 0x01 : 0x00;
    d2.at<unsigned char>(2, c) = 0xFF;
    d2.at<unsigned char>(3, c) = c < 16 ? 0xFE : 0xFF;
    d2.at<unsigned char>(4, c) = 0x0F;
  }
  kvld::PutativeOptions opt;
  const auto m = kvld::match_putative(d1, d2, opt);
  REQUIRE(m.size() == 2);
  CHECK(m[0] == kvld::Match{0, 0});
  CHECK(m[1] == kvld::Match{1, 2});
  opt.mutual = false;
  const auto m2 = kvld::match_putative(d1, d2, opt);
  CHECK(m2.size() == 3);  // row 3 → d2 row 1 (24 bits) vs row 0 (32): 24 < 0.8·32 passes
  opt.max_matches = 1;
  CHECK(kvld::match_putative(d1, d2, opt).size() == 1);
  CHECK(kvld::match_putative(cv::Mat(), d2, opt).empty());
}
