// Google Benchmark of the per-view steps of the geo-tag database and localization (issue 26),
// each against its peer or the previous method in the same run:
//   - putative ORB matching (ratio 0.8 + mutual check) of two 2,000-feature sets: ours (one
//     POPCNT pass) against OpenCV's BFMatcher (knn k=2 forward + 1-NN backward, what it replaced);
//   - RootSIFT for retrieval at retrieval_scale 0.5 (default) against full resolution;
//   - cutting one view out of a 2048 x 1024 panorama: PanoramaCutter (tables once) against
//     cut_panorama_view (tables per view).
// OpenCV runs single-threaded here (CPU of one call). Input: two real street photos (OpenSfM's
// Berlin sample, ../shared/data/opensfm_berlin/images 01.jpg, 02.jpg) at KITTI's 1241 x 376; the
// panorama is photo 01 stretched to 2048 x 1024.
#include <benchmark/benchmark.h>

#include <memory>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "geodrift/geotag/features.hpp"
#include "geodrift/geotag/panorama.hpp"
#include "support/kitti.hpp"
#include "support/kitti_images.hpp"

namespace {

namespace geotag = geodrift::geotag;
namespace bench = geodrift::bench;

using bench::load_kitti_sized;

struct Scene {
  cv::Mat img1, img2, pano;
  geotag::Features f1, f2;
};

const Scene* scene() {
  static const std::unique_ptr<Scene> sc = []() -> std::unique_ptr<Scene> {
    const std::string dir = std::string(GEODRIFT_DATA_DIR) + "/opensfm_berlin/images/";
    cv::setNumThreads(1);  // CPU per call, as one pipeline thread spends it
    auto s = std::make_unique<Scene>();
    s->img1 = load_kitti_sized(dir + "01.jpg");
    s->img2 = load_kitti_sized(dir + "02.jpg");
    if (s->img1.empty() || s->img2.empty()) return nullptr;
    s->f1 = geotag::detect_orb(s->img1, 2000);
    s->f2 = geotag::detect_orb(s->img2, 2000);
    cv::resize(cv::imread(dir + "01.jpg", cv::IMREAD_GRAYSCALE), s->pano, cv::Size(2048, 1024));
    return s;
  }();
  return sc.get();
}

#define GEODRIFT_BENCH_SCENE(sc)                                                    \
  const Scene* sc = scene();                                                        \
  if (!sc) {                                                                        \
    state.SkipWithError("opensfm_berlin images not found under GEODRIFT_DATA_DIR"); \
    return;                                                                         \
  }

void BM_Match_Ours(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  std::size_t n = 0;
  for (auto _ : state) {
    const std::vector<cv::DMatch> m =
        geotag::match_ratio_mutual(sc->f1.descriptors, sc->f2.descriptors, 0.8);
    n = m.size();
    benchmark::DoNotOptimize(m.data());
  }
  state.counters["matches"] = static_cast<double>(n);
}
BENCHMARK(BM_Match_Ours)->Unit(benchmark::kMillisecond);

void BM_Match_BFMatcherPeer(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  std::size_t n = 0;
  for (auto _ : state) {
    cv::BFMatcher bf(cv::NORM_HAMMING, false);
    std::vector<std::vector<cv::DMatch>> fwd;
    bf.knnMatch(sc->f1.descriptors, sc->f2.descriptors, fwd, 2);
    std::vector<cv::DMatch> back;
    bf.match(sc->f2.descriptors, sc->f1.descriptors, back);
    std::vector<int> best(sc->f2.descriptors.rows, -1);
    for (const cv::DMatch& m : back) best[m.queryIdx] = m.trainIdx;
    n = 0;
    for (const auto& k : fwd)
      if (k.size() == 2 && k[0].distance < 0.8 * k[1].distance &&
          best[k[0].trainIdx] == k[0].queryIdx)
        ++n;
    benchmark::DoNotOptimize(n);
  }
  state.counters["matches"] = static_cast<double>(n);
}
BENCHMARK(BM_Match_BFMatcherPeer)->Unit(benchmark::kMillisecond);

/// Arg: retrieval scale in percent.
void BM_RootSift(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  const double scale = state.range(0) / 100.0;
  std::size_t n = 0;
  for (auto _ : state) {
    cv::Mat img = sc->img1;
    if (scale != 1.0) cv::resize(sc->img1, img, cv::Size(), scale, scale, cv::INTER_AREA);
    const geotag::Features f = geotag::detect_root_sift(img, 1000);
    n = f.keypoints.size();
    benchmark::DoNotOptimize(f.descriptors.data);
  }
  state.counters["features"] = static_cast<double>(n);
}
BENCHMARK(BM_RootSift)->Arg(50)->Arg(100)->Unit(benchmark::kMillisecond);

void BM_Orb_2000(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  for (auto _ : state) {
    const geotag::Features f = geotag::detect_orb(sc->img1, 2000);
    benchmark::DoNotOptimize(f.descriptors.data);
  }
}
BENCHMARK(BM_Orb_2000)->Unit(benchmark::kMillisecond);

void BM_CutView_Cutter(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  const geotag::PanoramaCutter cutter(sc->pano.cols, sc->pano.rows, geodrift::test::kitti_camera());
  int k = 0;
  for (auto _ : state) {
    const cv::Mat v = cutter.cut(sc->pano, (k++ % 8) * 3.14159265358979323846 / 4.0);
    benchmark::DoNotOptimize(v.data);
  }
}
BENCHMARK(BM_CutView_Cutter)->Unit(benchmark::kMillisecond);

void BM_CutView_PerView(benchmark::State& state) {
  GEODRIFT_BENCH_SCENE(sc);
  int k = 0;
  for (auto _ : state) {
    const cv::Mat v = geotag::cut_panorama_view(sc->pano, geodrift::test::kitti_camera(),
                                                (k++ % 8) * 3.14159265358979323846 / 4.0);
    benchmark::DoNotOptimize(v.data);
  }
}
BENCHMARK(BM_CutView_PerView)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
