// VO frontend throughput: tracking + keyframes + local BA over a rendered KITTI 02 stretch at
// 1241x376 (the target: >= 20 frames/s on 2 cores, goal 30), with the time per stage.
//
// Frames are rendered once before timing (geodrift::render, KITTI 02 frames 0..N-1), or read
// from a dataset folder written by `geodrift render` when GEODRIFT_BENCH_VO_DIR names one
// (DIR/image_0/*.png). Each benchmark iteration runs a fresh Odometry over the whole sequence.

#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "geodrift/io/trajectory.hpp"
#include "geodrift/render/render.hpp"
#include "geodrift/render/world.hpp"
#include "geodrift/vo/odometry.hpp"
#include "support/kitti.hpp"  // tests/support

using namespace geodrift;

namespace {

constexpr int kFrames = 150;

using test::kitti_camera;

const std::vector<cv::Mat>& frames() {
  static const std::vector<cv::Mat> f = [] {
    std::vector<cv::Mat> out;
    if (const char* dir = std::getenv("GEODRIFT_BENCH_VO_DIR")) {
      for (int i = 0; i < kFrames; ++i) {
        char name[64];
        std::snprintf(name, sizeof name, "/image_0/%06d.png", i);
        cv::Mat img = cv::imread(std::string(dir) + name, cv::IMREAD_GRAYSCALE);
        if (img.empty()) break;
        out.push_back(img);
      }
      if (static_cast<int>(out.size()) == kFrames) return out;
      out.clear();
    }
    const std::vector<Eigen::Isometry3d> T_K_c =
        test::kitti_T_K_c(std::string(GEODRIFT_DATA_DIR) + "/kitti_odometry_gt/poses/02.txt");
    render::WorldOptions wo;
    wo.last_frame = kFrames - 1;
    const render::World world = render::World::from_kitti(T_K_c, wo);
    render::RenderOptions ro;
    ro.threads = 2;
    for (int i = 0; i < kFrames; ++i)
      out.push_back(render::render_pinhole(world, world.frame_T_cw(i), kitti_camera(),
                                           render::Appearance::video(), ro));
    return out;
  }();
  return f;
}

double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// Arg 0: solver threads for local BA (1 or 2; OpenCV gets 2 either way). Arg 1: pipelined
/// local mapping (OdometryOptions::pipeline_mapping: mapping of a keyframe overlapped with the
/// next frame's ORB extraction on a second thread; same results as 0).
void BM_Vo_Sequence(benchmark::State& state) {
  const std::vector<cv::Mat>& imgs = frames();
  cv::setNumThreads(2);
  vo::OdometryOptions opt;
  opt.num_threads = static_cast<int>(state.range(0));
  opt.pipeline_mapping = state.range(1) != 0;
  vo::OdometryTimings t;
  int keyframes = 0, tracked = 0;
  double cpu = 0;
  for (auto _ : state) {
    const double c0 = process_cpu_seconds();
    vo::Odometry odo(kitti_camera(), opt);
    tracked = 0;
    for (std::size_t i = 0; i < imgs.size(); ++i) {
      vo::Frame f;
      f.index = static_cast<int>(i);
      f.gray = imgs[i];
      tracked += odo.process(f).has_pose();
    }
    odo.finish();
    keyframes = odo.num_keyframes();
    t = odo.timings();
    cpu = process_cpu_seconds() - c0;
    benchmark::DoNotOptimize(keyframes);
  }
  const double n = static_cast<double>(imgs.size());
  state.counters["ms_cpu_all_threads"] = 1e3 * cpu / n;
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(imgs.size()));
  state.counters["frames_per_s"] =
      benchmark::Counter(n * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["keyframes"] = keyframes;
  state.counters["tracked"] = tracked;
  // Per-frame milliseconds of each stage (last iteration).
  state.counters["ms_features"] = 1e3 * t.features / n;
  state.counters["ms_tracking"] = 1e3 * (t.tracking + t.init) / n;
  state.counters["ms_triangulation"] = 1e3 * t.triangulation / n;
  state.counters["ms_local_ba"] = 1e3 * t.local_ba / n;
  state.counters["ms_other"] = 1e3 * (t.keyframe + t.culling) / n;
}
BENCHMARK(BM_Vo_Sequence)
    ->Args({1, 0})
    ->Args({1, 1})
    ->Args({2, 1})
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

/// Peer/floor in the same run: ORB extraction alone on the same frames (what any ORB frontend
/// pays before tracking starts).
void BM_Vo_OrbOnly(benchmark::State& state) {
  const std::vector<cv::Mat>& imgs = frames();
  cv::setNumThreads(2);
  vo::OrbOptions oo;
  oo.oversample = 0.1 * static_cast<double>(state.range(0));
  const vo::OrbExtractor orb(oo);
  std::size_t total = 0;
  double cpu = 0;
  for (auto _ : state) {
    const double c0 = process_cpu_seconds();
    for (const cv::Mat& img : imgs) total += orb.extract(img).keypoints.size();
    cpu = process_cpu_seconds() - c0;
    benchmark::DoNotOptimize(total);
  }
  state.counters["ms_cpu_all_threads"] = 1e3 * cpu / static_cast<double>(imgs.size());
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(imgs.size()));
  state.counters["frames_per_s"] = benchmark::Counter(
      static_cast<double>(imgs.size()) * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Vo_OrbOnly)
    ->Arg(30)
    ->Arg(20)
    ->Arg(15)
    ->Arg(10)
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
