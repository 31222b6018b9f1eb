// Google Benchmark of the street-world renderer (geodrift::render): ms per 1241 x 376 video
// frame and per 2048 x 1024 panorama on a 300-frame stretch of KITTI 02 (frames 1000-1299,
// seed 1), each iteration rendering the next frame of the stretch (so the figure is a mean over
// the sequence, not one view). Peers in the same run: the depth render (one ray per pixel
// without shading or anti-aliasing: the ray-casting floor of a frame) and PNG encoding of the
// frame (what writing it costs anyway).
#if __has_include(<geodrift/render/render.hpp>)
#include <benchmark/benchmark.h>

#include <ctime>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "geodrift/render/dataset.hpp"
#include "geodrift/render/render.hpp"
#include "geodrift/sim/kitti_protocol.hpp"

namespace {

using namespace geodrift;

constexpr int kFirst = 1000, kLast = 1299;

/// Process CPU time (all threads) per iteration, in ms, as a counter: Google Benchmark's CPU
/// column counts the calling thread only, and the renderer's workers are other threads.
class ProcessCpu {
 public:
  ProcessCpu() : start_(std::clock()) {}
  void report(benchmark::State& state) const {
    const double ms = 1e3 * static_cast<double>(std::clock() - start_) / CLOCKS_PER_SEC;
    state.counters["process_cpu_ms"] = ms / static_cast<double>(state.iterations());
  }

 private:
  std::clock_t start_;
};

struct Scene {
  sim::KittiSequence seq;
  std::unique_ptr<render::World> world;
  std::vector<render::PanoramaSite> sites;
};

const Scene& scene() {
  static const std::unique_ptr<Scene> s = [] {
    const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
    auto sc = std::make_unique<Scene>();
    sc->seq = sim::load_kitti_sequence(dir + "/poses/02.txt", dir + "/calib_seq00-02.txt",
                                       dir + "/times/02.txt", "02");
    render::WorldOptions o;
    o.seed = 1;
    o.first_frame = kFirst;
    o.last_frame = kLast;
    sc->world = std::make_unique<render::World>(render::World::from_kitti(sc->seq.T_K_c, o));
    sc->sites = render::panorama_sites(*sc->world, kFirst, kLast, 5.0);
    return sc;
  }();
  return *s;
}

/// args: threads, antialias (0 none, 1 quincunx, 2 = 2x2 grid)
void BM_Frame(benchmark::State& state) {
  const Scene& sc = scene();
  render::RenderOptions ro;
  ro.threads = static_cast<int>(state.range(0));
  ro.antialias = state.range(1) == 0   ? render::Antialias::kNone
                 : state.range(1) == 1 ? render::Antialias::kQuincunx
                                       : render::Antialias::kGrid;
  ro.grid_n = 2;
  int f = kFirst;
  const ProcessCpu cpu;
  for (auto _ : state) {
    const cv::Mat img = render::render_pinhole(*sc.world, sc.world->frame_T_cw(f), sc.seq.camera,
                                               render::Appearance::video(), ro);
    benchmark::DoNotOptimize(img.data);
    f = f == kLast ? kFirst : f + 1;
  }
  cpu.report(state);
  state.SetLabel(state.range(1) == 0 ? "1 ray/px" : state.range(1) == 1 ? "quincunx" : "2x2");
}
BENCHMARK(BM_Frame)
    ->Args({2, 1})
    ->Args({1, 1})
    ->Args({2, 0})
    ->Args({2, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(60);

/// Floor: one ray per pixel centre, hit distance only.
void BM_DepthFloor(benchmark::State& state) {
  const Scene& sc = scene();
  int f = kFirst;
  const ProcessCpu cpu;
  for (auto _ : state) {
    const cv::Mat d =
        render::render_depth(*sc.world, sc.world->frame_T_cw(f), sc.seq.camera,
                             render::Appearance::video(), static_cast<int>(state.range(0)));
    benchmark::DoNotOptimize(d.data);
    f = f == kLast ? kFirst : f + 1;
  }
  cpu.report(state);
}
BENCHMARK(BM_DepthFloor)
    ->Arg(2)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(60);

/// Peer: PNG encoding of one rendered frame (the dataset writer's compression level 3).
void BM_PngEncodeFrame(benchmark::State& state) {
  const Scene& sc = scene();
  const cv::Mat img = render::render_pinhole(*sc.world, sc.world->frame_T_cw(kFirst + 50),
                                             sc.seq.camera, render::Appearance::video());
  std::vector<uchar> buf;
  for (auto _ : state) {
    cv::imencode(".png", img, buf, {cv::IMWRITE_PNG_COMPRESSION, 3});
    benchmark::DoNotOptimize(buf.data());
  }
}
BENCHMARK(BM_PngEncodeFrame)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(30);

/// Panoramas 2048 x 1024, street-view appearance, every 5 m along the stretch.
void BM_Panorama(benchmark::State& state) {
  const Scene& sc = scene();
  render::PanoramaOptions po;
  po.render.threads = static_cast<int>(state.range(0));
  std::size_t k = 0;
  const ProcessCpu cpu;
  for (auto _ : state) {
    const render::PanoramaSite& p = sc.sites[k];
    const cv::Mat img = render::render_panorama(*sc.world, p.centre, p.heading,
                                                render::Appearance::street_view(), po);
    benchmark::DoNotOptimize(img.data);
    k = (k + 1) % sc.sites.size();
  }
  cpu.report(state);
}
BENCHMARK(BM_Panorama)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(12);

/// World construction for the 300-frame stretch (objects, grids).
void BM_WorldBuild(benchmark::State& state) {
  const Scene& sc = scene();
  render::WorldOptions o;
  o.first_frame = kFirst;
  o.last_frame = kLast;
  for (auto _ : state) {
    const render::World w = render::World::from_kitti(sc.seq.T_K_c, o);
    benchmark::DoNotOptimize(&w);
  }
}
BENCHMARK(BM_WorldBuild)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
#else
#include <cstdio>
int main() {
  std::puts("bench_render: geodrift::render was not built (OpenCV missing); nothing to measure");
  return 0;
}
#endif
