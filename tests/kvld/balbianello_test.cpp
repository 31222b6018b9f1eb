// K-VLD on real photo pairs: Balbianello (5 photos + Bundler v0.3 reconstruction, from GTSAM's
// example data). True matches = two observations of the same reconstructed 3D point; wrong
// matches = real SIFT nearest-neighbour matches that violate the pair's epipolar geometry.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include "geodrift/kvld/kvld.hpp"

namespace kvld = geodrift::kvld;

namespace {

const std::string kDir = GEODRIFT_DATA_DIR "/gtsam_examples_data/";

struct Obs {
  int camera, key;
  double x, y;  // Bundler: origin at the image centre, x right, y UP
};

/// Per 3D point, its observations (Bundler v0.3: header, "ncam npt", 5 lines per camera, then
/// per point: position, colour, "n  cam key x y  cam key x y ...").
std::vector<std::vector<Obs>> read_bundler_tracks(const std::string& path, int* num_cameras) {
  std::ifstream in(path);
  REQUIRE(in.good());
  std::string header;
  std::getline(in, header);
  REQUIRE(header.rfind("# Bundle file v0.3", 0) == 0);
  int nc = 0, np = 0;
  in >> nc >> np;
  REQUIRE(nc > 0);
  double skip;
  for (int i = 0; i < nc * 15; ++i) in >> skip;  // f k1 k2, R (9), t (3)
  std::vector<std::vector<Obs>> tracks(static_cast<std::size_t>(np));
  for (auto& t : tracks) {
    double v;
    for (int i = 0; i < 6; ++i) in >> v;  // position, colour
    int n = 0;
    in >> n;
    for (int k = 0; k < n; ++k) {
      Obs o{};
      in >> o.camera >> o.key >> o.x >> o.y;
      t.push_back(o);
    }
  }
  REQUIRE(in.good());
  *num_cameras = nc;
  return tracks;
}

struct View {
  cv::Mat gray;
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
};

View load_view(int camera) {
  View v;
  v.gray = cv::imread(kDir + "Balbianello/BalbianelloMedium-" + std::to_string(camera + 1) + ".jpg",
                      cv::IMREAD_GRAYSCALE);
  REQUIRE_FALSE(v.gray.empty());
  cv::SIFT::create()->detectAndCompute(v.gray, cv::noArray(), v.kps, v.desc);
  return v;
}

/// Bundler (centre origin, y up) → pixel (top-left pixel centre origin, y down). The
/// reconstruction was made on these 640×427 images (focal ≈ 519 px; observations span
/// ±310 px); `s` rescales if the jpgs had another size.
cv::Point2d to_pixel(const Obs& o, const cv::Mat& img, double s) {
  return {s * o.x + 0.5 * img.cols - 0.5, 0.5 * img.rows - 0.5 - s * o.y};
}

/// Keypoints within `radius` px of p.
std::vector<int> near(const View& v, const cv::Point2d& p, double radius) {
  std::vector<int> out;
  for (std::size_t i = 0; i < v.kps.size(); ++i) {
    if (std::hypot(v.kps[i].pt.x - p.x, v.kps[i].pt.y - p.y) <= radius)
      out.push_back(static_cast<int>(i));
  }
  return out;
}

double epipolar_distance(const cv::Matx33d& F, const cv::Point2f& p1, const cv::Point2f& p2) {
  const cv::Vec3d x1(p1.x, p1.y, 1), x2(p2.x, p2.y, 1);
  const cv::Vec3d l2 = F * x1, l1 = F.t() * x2;
  const double e = x2.dot(l2);
  return std::max(std::abs(e) / std::hypot(l2[0], l2[1]), std::abs(e) / std::hypot(l1[0], l1[1]));
}

struct PairData {
  View v1, v2;
  std::vector<kvld::Match> truth;  // keypoint index pairs
  std::vector<kvld::Match> wrong;
  double median_snap_px = 0;
};

PairData build_pair(const std::vector<std::vector<Obs>>& tracks, int ca, int cb) {
  PairData pd;
  pd.v1 = load_view(ca);
  pd.v2 = load_view(cb);
  const double s = pd.v1.gray.cols / 640.0;
  // True matches: the SIFT keypoints at both observations of a track (the pair of candidates
  // with the closest descriptors when a location carries several orientations).
  std::vector<double> snaps;
  std::set<int> used1, used2;
  cv::BFMatcher l2(cv::NORM_L2);
  for (const auto& t : tracks) {
    const Obs* oa = nullptr;
    const Obs* ob = nullptr;
    for (const Obs& o : t) {
      if (o.camera == ca) oa = &o;
      if (o.camera == cb) ob = &o;
    }
    if (!oa || !ob) continue;
    const cv::Point2d pa = to_pixel(*oa, pd.v1.gray, s), pb = to_pixel(*ob, pd.v2.gray, s);
    const std::vector<int> na = near(pd.v1, pa, 1.5), nb = near(pd.v2, pb, 1.5);
    double best = 1e30;
    kvld::Match m{-1, -1};
    for (int i : na) {
      for (int j : nb) {
        const double d = cv::norm(pd.v1.desc.row(i), pd.v2.desc.row(j), cv::NORM_L2);
        if (d < best) {
          best = d;
          m = {i, j};
        }
      }
    }
    if (m.i1 < 0 || used1.count(m.i1) || used2.count(m.i2)) continue;
    used1.insert(m.i1);
    used2.insert(m.i2);
    snaps.push_back(std::hypot(pd.v1.kps[static_cast<std::size_t>(m.i1)].pt.x - pa.x,
                               pd.v1.kps[static_cast<std::size_t>(m.i1)].pt.y - pa.y));
    pd.truth.push_back(m);
  }
  REQUIRE(pd.truth.size() >= 100);
  std::nth_element(snaps.begin(), snaps.begin() + snaps.size() / 2, snaps.end());
  pd.median_snap_px = snaps[snaps.size() / 2];

  // The pair's true epipolar geometry, from the true matches.
  std::vector<cv::Point2f> p1, p2;
  for (const kvld::Match& m : pd.truth) {
    p1.push_back(pd.v1.kps[static_cast<std::size_t>(m.i1)].pt);
    p2.push_back(pd.v2.kps[static_cast<std::size_t>(m.i2)].pt);
  }
  const cv::Mat Fm = cv::findFundamentalMat(p1, p2, cv::FM_RANSAC, 1.5, 0.999);
  REQUIRE(Fm.rows == 3);
  const cv::Matx33d F(Fm);

  // Wrong matches: nearest and second-nearest SIFT neighbours (both directions, no ratio
  // test) that lie more than 10 px from their epipolar line; never at an image-1 keypoint of
  // a true match (a nearest-neighbour list has one partner per query keypoint).
  std::set<std::pair<int, int>> seen;
  const auto consider = [&](int i, int j) {
    if (used1.count(i) || !seen.insert({i, j}).second) return;
    if (epipolar_distance(F, pd.v1.kps[static_cast<std::size_t>(i)].pt,
                          pd.v2.kps[static_cast<std::size_t>(j)].pt) > 10.0) {
      pd.wrong.push_back({i, j});
    }
  };
  std::vector<std::vector<cv::DMatch>> knn12, knn21;
  l2.knnMatch(pd.v1.desc, pd.v2.desc, knn12, 2);
  l2.knnMatch(pd.v2.desc, pd.v1.desc, knn21, 2);
  for (int rank = 0; rank < 2; ++rank) {
    for (const auto& c : knn12)
      if (static_cast<int>(c.size()) > rank) consider(c[rank].queryIdx, c[rank].trainIdx);
    for (const auto& c : knn21)
      if (static_cast<int>(c.size()) > rank) consider(c[rank].trainIdx, c[rank].queryIdx);
  }
  return pd;
}

struct Score {
  std::size_t n_true = 0, n_wrong = 0, kept = 0, kept_true = 0;
  double precision = 0, recall = 0;
};

Score run_mix(const PairData& pd, double outlier_fraction, unsigned seed) {
  std::mt19937 rng(seed);
  std::vector<kvld::Match> truth = pd.truth, wrong = pd.wrong;
  std::shuffle(truth.begin(), truth.end(), rng);
  std::shuffle(wrong.begin(), wrong.end(), rng);
  // n_wrong / (n_true + n_wrong) = outlier_fraction; shrink the true set if wrong ones run out.
  std::size_t n_true = truth.size();
  auto n_wrong =
      static_cast<std::size_t>(std::lround(n_true * outlier_fraction / (1.0 - outlier_fraction)));
  if (n_wrong > wrong.size()) {
    n_wrong = wrong.size();
    n_true = static_cast<std::size_t>(
        std::lround(n_wrong * (1.0 - outlier_fraction) / outlier_fraction));
  }
  std::vector<std::pair<kvld::Match, bool>> mix;
  for (std::size_t i = 0; i < n_true; ++i) mix.push_back({truth[i], true});
  for (std::size_t i = 0; i < n_wrong; ++i) mix.push_back({wrong[i], false});
  std::shuffle(mix.begin(), mix.end(), rng);
  std::vector<kvld::Match> putative;
  for (const auto& m : mix) putative.push_back(m.first);

  const kvld::ImageScale s1(pd.v1.gray), s2(pd.v2.gray);
  const auto F1 = kvld::keypoints_from_cv(pd.v1.kps), F2 = kvld::keypoints_from_cv(pd.v2.kps);
  const kvld::Result r = kvld::filter(s1, s2, F1, F2, putative);
  Score sc;
  sc.n_true = n_true;
  sc.n_wrong = n_wrong;
  sc.kept = r.kept_indices.size();
  for (int idx : r.kept_indices) sc.kept_true += mix[static_cast<std::size_t>(idx)].second;
  sc.precision = sc.kept ? double(sc.kept_true) / sc.kept : 0.0;
  sc.recall = double(sc.kept_true) / n_true;
  return sc;
}

}  // namespace

TEST_CASE(
    "K-VLD keeps >= 90% precision and >= 50% recall on real Balbianello pairs with up to "
    "90% real nearest-neighbour outliers",
    "[kvld][data]") {
  int nc = 0;
  const auto tracks = read_bundler_tracks(kDir + "Balbianello.out", &nc);
  REQUIRE(nc == 5);
  for (const auto& cams : std::vector<std::pair<int, int>>{{0, 1}, {1, 2}}) {
    const PairData pd = build_pair(tracks, cams.first, cams.second);
    INFO("pair " << cams.first << "-" << cams.second << ": " << pd.truth.size() << " true, "
                 << pd.wrong.size() << " wrong available");
    // The coordinate conversion is right: Bundler observations sit on detected SIFT keypoints.
    CHECK(pd.median_snap_px < 0.5);
    for (double q : {0.5, 0.7, 0.9}) {
      const Score sc = run_mix(pd, q, 42);
      std::printf(
          "kvld balbianello %d-%d outliers %.0f%%: %zu true + %zu wrong -> kept %zu, "
          "precision %.3f recall %.3f\n",
          cams.first, cams.second, 100 * q, sc.n_true, sc.n_wrong, sc.kept, sc.precision,
          sc.recall);
      INFO("outliers " << q << ": " << sc.n_true << " true + " << sc.n_wrong << " wrong, kept "
                       << sc.kept << " precision " << sc.precision << " recall " << sc.recall);
      CHECK(sc.n_true >= 100);
      CHECK(sc.precision >= 0.9);
      CHECK(sc.recall >= 0.5);
    }
  }
}
