// geodrift command line: dispatches to the subcommands. Library code throws geodrift::Error;
// this is the one place that turns an exception into a message and a non-zero exit.
#include <cstdio>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <exception>
#include <geodrift/error.hpp>
#include <geodrift/version.hpp>
#include <string>

#include "cli_util.hpp"
#include "commands.hpp"

// cmd_experiment.cpp is written separately; the dispatch table names it once it exists.
#if __has_include("cmd_experiment.cpp")
#define GEODRIFT_CLI_HAS_EXPERIMENT 1
#else
#define GEODRIFT_CLI_HAS_EXPERIMENT 0
#endif
// geodrift render exists when geodrift::render is built (it needs OpenCV).
#if __has_include(<geodrift/render/dataset.hpp>)
#define GEODRIFT_CLI_HAS_RENDER 1
#else
#define GEODRIFT_CLI_HAS_RENDER 0
#endif

// geodrift run exists when geodrift::vo is built (it needs OpenCV).
#if __has_include(<geodrift/vo/odometry.hpp>)
#define GEODRIFT_CLI_HAS_VO 1
#else
#define GEODRIFT_CLI_HAS_VO 0
#endif

namespace {

struct Subcommand {
  const char* name;
  int (*run)(int, char**);
  const char* summary;
};

// The one dispatch table.
const Subcommand kSubcommands[] = {
    {"correct", geodrift::cli::run_correct,
     "geo-localize a SLAM trajectory (+ optional COLMAP map) with an anchors CSV"},
    {"eval", geodrift::cli::run_eval, "compare a corrected trajectory with ground truth"},
    {"simulate", geodrift::cli::run_simulate,
     "simulate monocular SLAM output (drifted trajectory, map, anchors) on KITTI"},
#if GEODRIFT_CLI_HAS_VO
    {"run", geodrift::cli::run_run, "monocular VO on images or a video, then the Corrector"},
#endif
#if GEODRIFT_CLI_HAS_RENDER
    {"render", geodrift::cli::run_render,
     "render a street-world dataset (frames + panoramas) on a KITTI path"},
#endif
#if GEODRIFT_CLI_HAS_EXPERIMENT
    {"experiment", geodrift::cli::run_experiment, "regenerate the paper's KITTI experiment"},
#endif
#if defined(GEODRIFT_CLI_HAS_GEOTAG)
    {"geotags", geodrift::cli::run_geotags, "build or query a geo-tagged image database"},
#endif
};

void print_usage(std::FILE* f) {
  std::fprintf(f,
               "geodrift %s: geo-localize a monocular reconstruction with sparse geo-tagged "
               "images\n\nusage: geodrift <subcommand> [options]\n       geodrift --version\n\n"
               "subcommands (geodrift <subcommand> --help for each):\n",
               geodrift::kVersion);
  for (const Subcommand& s : kSubcommands) std::fprintf(f, "  %-11s %s\n", s.name, s.summary);
}

/// glibc serves blocks above its mmap threshold (adaptive, at most 32 MB) with fresh mappings and
/// returns heap tops above the trim threshold to the kernel when freed, so every image-sized
/// buffer (SIFT and ORB pyramids, K-VLD scale spaces, decoded panoramas) faulted its pages in
/// anew: a third of `geotags build`'s CPU was system time, and half its user time went to
/// zeroing pages. Keeping blocks below 256 MB in the heap, and up to 512 MB of free heap, cut
/// the build of 12 panoramas from 9.8 s to 5.1 s CPU (peak memory +5 %). Larger blocks (a
/// 10-million-pose trajectory) are still mapped and unmapped.
void tune_allocator() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
#endif
}
}  // namespace

int main(int argc, char** argv) {
  tune_allocator();
  geodrift::cli::install_signal_cleanup();  // SIGINT/SIGTERM remove staged outputs
  if (argc < 2) {
    print_usage(stderr);
    return 2;
  }
  const std::string cmd = argv[1];
  try {
    if (cmd == "--version" || cmd == "version") {
      std::printf("geodrift %s\n", geodrift::kVersion);
      return 0;
    }
    if (cmd == "--help" || cmd == "-h" || cmd == "help") {
      print_usage(stdout);
      return 0;
    }
    for (const Subcommand& s : kSubcommands)
      if (cmd == s.name) return s.run(argc - 1, argv + 1);
    std::fprintf(stderr, "geodrift: unknown subcommand '%s'\n", cmd.c_str());
    print_usage(stderr);
    return 2;
  } catch (const geodrift::cli::UsageError& e) {
    std::fprintf(stderr, "geodrift %s: usage error: %s\n", cmd.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "geodrift %s: error: %s\n", cmd.c_str(),
                 geodrift::cli::describe_output_error(e).c_str());
    return 1;
  }
}
