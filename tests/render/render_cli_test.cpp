// `geodrift render` end to end: a small dataset is written; bad inputs give a message, a
// non-zero exit and no output; a non-empty --out is refused without --force.
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/test_files.hpp"

#ifdef GEODRIFT_CLI_EXE

namespace fs = std::filesystem;

namespace {

using Run = geodrift::test::CliRun;
Run run(const std::string& args) { return geodrift::test::run_cli(GEODRIFT_CLI_EXE, args); }

const std::string kData = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";

}  // namespace

TEST_CASE("geodrift render writes a dataset and rejects bad input cleanly", "[render][cli]") {
  geodrift::test::TempDir t;
  const std::string poses = kData + "/poses/02.txt", calib = kData + "/calib_seq00-02.txt";
  const std::string base = "render --sequence-poses " + poses + " --calib " + calib;
  const auto expect_failure = [&](const Run& r, const std::vector<std::string>& words) {
    INFO(r.output);
    CHECK(r.code != 0);
    for (const auto& w : words) CHECK(r.output.find(w) != std::string::npos);
    CHECK(geodrift::test::no_outputs(t.path(), "out"));
  };

  SECTION("a good run writes the documented layout; a second run needs --force") {
    const std::string args = base + " --times " + kData +
                             "/times/02.txt --first 10 --last 12 --panorama-spacing 2 "
                             "--panorama-size 64x32 --out " +
                             t.file("out");
    const Run r = run(args);
    INFO(r.output);
    REQUIRE(r.code == 0);
    for (const char* f : {"calib.txt", "times.txt", "poses.txt", "geotags.csv", "dataset.json",
                          "image_0/000000.png", "image_0/000002.png", "panoramas/pano_000000.png"})
      CHECK(fs::exists(t.file("out") + "/" + f));
    CHECK(!fs::exists(t.file("out") + "/image_0/000003.png"));
    const Run again = run(args);
    INFO(again.output);
    CHECK(again.code != 0);
    CHECK(again.output.find("not empty") != std::string::npos);
    CHECK(run(args + " --force").code == 0);
  }
  SECTION("a missing pose file") {
    expect_failure(run("render --sequence-poses " + t.file("nope.txt") + " --calib " + calib +
                       " --first 0 --last 2 --out " + t.file("out")),
                   {"nope.txt", "not found"});
  }
  SECTION("a frame range outside the poses, or reversed") {
    expect_failure(run(base + " --first 0 --last 99999 --out " + t.file("out")),
                   {"--last 99999", "4661 poses"});
    expect_failure(run(base + " --first 5 --last 2 --out " + t.file("out")), {"--last 2"});
    expect_failure(run(base + " --first -3 --last 2 --out " + t.file("out")), {"--first"});
  }
  SECTION("a malformed calibration") {
    const std::string bad = t.write("calib.txt", "P0: 718.8 0 607.1 0 0 718.8 185.2\n");
    expect_failure(run("render --sequence-poses " + poses + " --calib " + bad +
                       " --first 0 --last 2 --out " + t.file("out")),
                   {"calib.txt", "expected 12"});
  }
  SECTION("bad option values") {
    expect_failure(run(base + " --first 0 --last 2 --panorama-spacing -5 --out " + t.file("out")),
                   {"--panorama-spacing"});
    expect_failure(run(base + " --first 0 --last 2 --panorama-size 100 --out " + t.file("out")),
                   {"--panorama-size"});
    expect_failure(run(base + " --last 2 --out " + t.file("out")), {"--first"});
  }
}

#endif
