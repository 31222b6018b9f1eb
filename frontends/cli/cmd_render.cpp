// geodrift render: a rendered street-world dataset (video frames, ground truth, geo-tagged
// panoramas) along a KITTI ground-truth path (geodrift::render).
#if __has_include(<geodrift/render/dataset.hpp>)
#include <chrono>
#include <cmath>
#include <cstdio>
#include <geodrift/error.hpp>
#include <geodrift/render/dataset.hpp>
#include <string>

#include "cli_util.hpp"
#include "commands.hpp"

namespace geodrift::cli {
namespace {

const char* kRenderHelp =
    R"(usage: geodrift render --sequence-poses FILE --calib FILE --first N --last M --out DIR
                       [options]

Renders a street world (textured buildings, road with markings, sidewalks, poles, trees,
parked cars) along a KITTI ground-truth path: the video as seen by KITTI's cam0 and, every
--panorama-spacing metres, a geo-tagged equirectangular panorama in the "street view"
appearance (other sun, +40 % sun brightness, warmer colour, 20 % of facades replaced, parked
cars moved). Deterministic: the same inputs and --seed give bit-identical files.

Output folder (--out):
  calib.txt          KITTI format: P0 (intrinsics of --calib's P0) and P1 (its stereo baseline)
  times.txt          one time per frame (--times' values, else 0.1 s x sequence frame index)
  poses.txt          ground truth cam0 -> KITTI world of the sequence (the input rows of frames
                     N..M), KITTI format after one '#' line
  image_0/000000.png frames N..M as 000000.png ..., grey 8-bit, the calib's size (1241 x 376)
  panoramas/pano_000000.png  RGB equirectangular panoramas (2048 x 1024)
  geotags.csv        id,file,latitude,longitude,height,heading_deg,x,y,z,frame (after one '#'
                     line); latitude/longitude through the ASSUMED KITTI geo origin (49.0110N
                     8.4170E, 160 m, UTM 32N); x,y,z in W (E/N/Up of cam0 at sequence frame 0);
                     frame = nearest dataset frame; heading_deg = true bearing of the centre
                     column
  dataset.json       seed, sequence, frame range, appearance settings, origin, versions

Panorama pixels: level; column u -> true bearing heading_deg + 360*((u+0.5)/W - 0.5) deg,
row v -> elevation 90 - 180*(v+0.5)/H deg; centre 2.5 m above the ground on the route.

options:
  --sequence-poses FILE  KITTI poses (12 numbers per line, or 13 with a leading index/time)
  --calib FILE           KITTI calib.txt (P0 and P1 lines)
  --times FILE           KITTI times.txt (optional)
  --first N --last M     frame range of the sequence (inclusive)
  --seed S               world seed (default 1)
  --panorama-spacing D   metres of route between panoramas (default 5)
  --no-panoramas         frames only
  --panorama-size WxH    panorama size (default 2048x1024)
  --threads T            render threads (default: all cores)
  --sequence NAME        name for dataset.json (default: the pose file's name)
  --out DIR              output directory (created; must not exist or be empty unless --force)
  --force                write into an existing non-empty --out (replaces geodrift's own files)
)";

}  // namespace

int run_render(int argc, char** argv) {
  const Args args(argc, argv,
                  {"sequence-poses", "calib", "times", "first", "last", "seed", "panorama-spacing",
                   "panorama-size", "threads", "sequence", "out"},
                  {"help", "force", "no-panoramas"});
  if (args.flag("help")) {
    std::fputs(kRenderHelp, stdout);
    return 0;
  }
  render::DatasetOptions o;
  o.poses_path = args.required("sequence-poses");
  o.calib_path = args.required("calib");
  o.times_path = args.get("times");
  o.sequence = args.get("sequence");
  const std::string out_dir = args.required("out");
  if (!args.has("first")) throw UsageError("missing required option --first (see --help)");
  if (!args.has("last")) throw UsageError("missing required option --last (see --help)");
  const long long first = args.get_int("first", 0), last = args.get_int("last", 0);
  if (first < 0) throw UsageError("--first " + std::to_string(first) + " must be >= 0");
  if (last < first)
    throw UsageError("--last " + std::to_string(last) + " is before --first " +
                     std::to_string(first));
  if (last > 1000000000LL) throw UsageError("--last " + std::to_string(last) + " is too large");
  o.first = static_cast<int>(first);
  o.last = static_cast<int>(last);
  const long long seed = args.get_int("seed", 1);
  if (seed < 0) throw UsageError("--seed must be >= 0");
  o.seed = static_cast<std::uint64_t>(seed);
  const long long threads = args.get_int("threads", 0);
  if (threads < 0 || threads > 256) throw UsageError("--threads must be in [0, 256]");
  o.threads = static_cast<int>(threads);
  if (args.flag("no-panoramas") && args.has("panorama-spacing"))
    throw UsageError("--no-panoramas and --panorama-spacing exclude each other");
  if (args.flag("no-panoramas")) {
    o.panorama_spacing_m = 0;
  } else if (args.has("panorama-spacing")) {
    const std::vector<double> v =
        parse_number_list("panorama-spacing", args.get("panorama-spacing"));
    if (v.size() != 1 || !(v[0] > 0))
      throw UsageError("--panorama-spacing must be one positive number of metres");
    o.panorama_spacing_m = v[0];
  }
  if (args.has("panorama-size")) {
    const std::vector<double> v =
        parse_number_list("panorama-size", args.get("panorama-size"), 'x');
    if (v.size() != 2 || v[0] < 8 || v[1] < 4 || v[0] > 16384 || v[1] > 8192 ||
        v[0] != std::floor(v[0]) || v[1] != std::floor(v[1]))
      throw UsageError("--panorama-size must be WxH with integers 8 <= W <= 16384, 4 <= H <= 8192");
    o.panorama_width = static_cast<int>(v[0]);
    o.panorama_height = static_cast<int>(v[1]);
  }

  AtomicOutputDir out(out_dir, args.flag("force"));
  const bool tty = stderr_is_tty();
  const auto t0 = std::chrono::steady_clock::now();
  const render::DatasetSummary s =
      render::write_dataset(o, out.staging_dir(), [&](const char* stage, int done, int total) {
        if (!tty) return;
        const double el =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        std::fprintf(stderr, "\rgeodrift render: %s %d / %d  (%.1f s)   ", stage, done, total, el);
        if (done == total) std::fputc('\n', stderr);
      });
  out.commit();
  std::printf(
      "geodrift render: %d frames (%.1f ms/frame), %d panoramas (%.1f ms/panorama) -> %s\n"
      "  world: %s\n",
      s.frames, s.frames ? 1e3 * s.frame_seconds / s.frames : 0.0, s.panoramas,
      s.panoramas ? 1e3 * s.panorama_seconds / s.panoramas : 0.0, out_dir.c_str(),
      s.world_summary.c_str());
  return 0;
}

}  // namespace geodrift::cli
#endif
