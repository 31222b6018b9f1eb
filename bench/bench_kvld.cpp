// Google Benchmark of K-VLD (issue 6 target: kVLD on 1,000 putative matches < 50 ms, with the
// scale spaces precomputed). Input: two consecutive real street photos (OpenSfM's Berlin
// sample, ../shared/data/opensfm_berlin/images/01.jpg and 02.jpg) resized to 1241 px wide and
// cropped to the middle 376 rows (KITTI's frame size). Putative matches: ORB (4000 features)
// nearest neighbours with the mutual check, best N by Hamming distance (no ratio test, so
// that N = 1000 is reached and the outlier share is realistic). Built once, outside the loop.
//
// Peers measured in the same run: building one ImageScale (done once per image in the
// pipeline) and ORB detect+compute on one frame (the step K-VLD follows).
#include <benchmark/benchmark.h>

#include <memory>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "geodrift/kvld/kvld.hpp"
#include "support/kitti_images.hpp"

namespace {

namespace kvld = geodrift::kvld;
namespace bench = geodrift::bench;

using bench::load_kitti_sized;

struct Scene {
  cv::Mat img1, img2;
  std::vector<cv::KeyPoint> kp1, kp2;
  std::vector<kvld::Keypoint> F1, F2;
  std::vector<kvld::Match> all;  // sorted best first
  std::unique_ptr<kvld::ImageScale> s1, s2;
};

const Scene* scene() {
  static const std::unique_ptr<Scene> sc = []() -> std::unique_ptr<Scene> {
    const std::string dir = std::string(GEODRIFT_DATA_DIR) + "/opensfm_berlin/images/";
    auto s = std::make_unique<Scene>();
    s->img1 = load_kitti_sized(dir + "01.jpg");
    s->img2 = load_kitti_sized(dir + "02.jpg");
    if (s->img1.empty() || s->img2.empty()) return nullptr;
    const cv::Ptr<cv::ORB> orb = cv::ORB::create(4000);
    cv::Mat d1, d2;
    orb->detectAndCompute(s->img1, cv::noArray(), s->kp1, d1);
    orb->detectAndCompute(s->img2, cv::noArray(), s->kp2, d2);
    s->F1 = kvld::keypoints_from_cv(s->kp1);
    s->F2 = kvld::keypoints_from_cv(s->kp2);
    kvld::PutativeOptions po;
    po.ratio = 1.0;  // nearest neighbour only (strictly closer than the second)
    po.max_matches = 0;
    po.mutual = false;  // one partner per image-1 keypoint, as a plain NN list
    s->all = kvld::match_putative(d1, d2, po);
    s->s1 = std::make_unique<kvld::ImageScale>(s->img1);
    s->s2 = std::make_unique<kvld::ImageScale>(s->img2);
    return s;
  }();
  return sc.get();
}

void BM_Kvld_Filter(benchmark::State& state) {
  const Scene* sc = scene();
  if (!sc) {
    state.SkipWithError("opensfm_berlin images not found under GEODRIFT_DATA_DIR");
    return;
  }
  const auto n = static_cast<std::size_t>(state.range(0));
  if (sc->all.size() < n) {
    state.SkipWithError("not enough putative matches for this size");
    return;
  }
  const std::vector<kvld::Match> putative(sc->all.begin(), sc->all.begin() + n);
  kvld::Result r;
  for (auto _ : state) {
    r = kvld::filter(*sc->s1, *sc->s2, sc->F1, sc->F2, putative);
    benchmark::DoNotOptimize(r.matches.data());
  }
  state.counters["kept"] = static_cast<double>(r.matches.size());
  state.counters["runs"] = r.runs;
  state.counters["vld_pairs"] = static_cast<double>(r.vld_pairs);
  state.counters["tested_pairs"] = static_cast<double>(r.tested_pairs);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(n));
}
BENCHMARK(BM_Kvld_Filter)->Arg(250)->Arg(500)->Arg(1000)->Unit(benchmark::kMillisecond);

void BM_Kvld_ImageScale(benchmark::State& state) {
  const Scene* sc = scene();
  if (!sc) {
    state.SkipWithError("opensfm_berlin images not found under GEODRIFT_DATA_DIR");
    return;
  }
  for (auto _ : state) {
    const kvld::ImageScale s(sc->img1);
    benchmark::DoNotOptimize(s.level(0).magnitude.data());
  }
  state.counters["levels"] = sc->s1->num_levels();
}
BENCHMARK(BM_Kvld_ImageScale)->Unit(benchmark::kMillisecond);

void BM_Orb_DetectCompute(benchmark::State& state) {
  const Scene* sc = scene();
  if (!sc) {
    state.SkipWithError("opensfm_berlin images not found under GEODRIFT_DATA_DIR");
    return;
  }
  const cv::Ptr<cv::ORB> orb = cv::ORB::create(4000);
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  for (auto _ : state) {
    orb->detectAndCompute(sc->img1, cv::noArray(), kps, desc);
    benchmark::DoNotOptimize(desc.data);
  }
  state.counters["keypoints"] = static_cast<double>(kps.size());
}
BENCHMARK(BM_Orb_DetectCompute)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
