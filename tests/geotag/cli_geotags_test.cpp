// `geodrift geotags build|query` through the built executable: exit codes, messages, no
// partial or overwritten outputs.
#include <catch2/catch.hpp>

#if defined(GEODRIFT_CLI_EXE)
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "support/cli_run.hpp"
#include "support/test_files.hpp"

using namespace geodrift;

namespace {
using Run = test::CliRun;
Run run(const std::string& args) { return test::run_cli(GEODRIFT_CLI_EXE, args); }
const std::string kLund = std::string(GEODRIFT_DATA_DIR) + "/opensfm_lund/lund_exif_gps.csv";
const std::string kCam = "--camera 718.856,718.856,607.19,185.22,1241,376";
}  // namespace

TEST_CASE("geotags CLI: usage and input errors exit non-zero with a message",
          "[geotag][cli][errors]") {
  test::TempDir tmp;
  Run r = run("geotags");
  CHECK(r.code == 2);
  r = run("geotags frobnicate");
  CHECK(r.code == 2);
  CHECK(r.output.find("build or query") != std::string::npos);
  r = run("geotags build --out " + tmp.file("x.gdb"));
  CHECK(r.code == 2);
  CHECK(r.output.find("--geotags") != std::string::npos);
  r = run("geotags build --geotags " + tmp.file("none") + " --out " + tmp.file("x.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.output.find("does not exist") != std::string::npos);
  r = run("geotags build --geotags " + tmp.path().string() + " --out " + tmp.file("x.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.output.find("geotags.csv") != std::string::npos);
  test::write_text(tmp.file("bad.gdb"), "not a database");
  r = run("geotags query --db " + tmp.file("bad.gdb") + " --image " + tmp.file("bad.gdb"));
  CHECK(r.code == 1);
  CHECK(r.output.find("not a geodrift geotag database") != std::string::npos);
  r = run("geotags build --geotags " + tmp.file("bad.gdb") + " --out " + tmp.file("bad.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.output.find("refusing to overwrite") != std::string::npos);
  CHECK(test::read_text(tmp.file("bad.gdb")) == "not a database");
  CHECK(tmp.num_entries() == 1);
}

TEST_CASE("run CLI: the geo-tag cost options are validated before any work",
          "[geotag][cli][errors]") {
  test::TempDir tmp;
  for (const char* bad :
       {"--geotag-every 0", "--geotag-every -3", "--geotag-top-k 0", "--photo-hfov-deg 0",
        "--photo-hfov-deg 180", "--photo-hfov-deg nan", "--weights lambda"}) {
    const Run r = run("run --images " + tmp.path().string() + " --geotags " + tmp.path().string() +
                      " " + bad + " --out " + tmp.file("out"));
    INFO(bad << ": " << r.output);
    CHECK(r.code == 2);
    CHECK(r.output.find(std::string(bad).substr(0, std::string(bad).find(' '))) !=
          std::string::npos);
  }
  CHECK(tmp.num_entries() == 0);
  // A database file already holds the views' intrinsics: a field of view for it is refused.
  test::write_text(tmp.file("some.gdb"), "not read");
  const Run r = run("run --images " + tmp.path().string() + " --geotags " + tmp.file("some.gdb") +
                    " --photo-hfov-deg 60 --out " + tmp.file("out"));
  INFO(r.output);
  CHECK(r.code == 2);
  CHECK(r.output.find("--geotags folder") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(tmp.file("out")));
}

TEST_CASE("geotags CLI: build on the Lund photos and query one of them", "[geotag][cli][data]") {
  if (!std::filesystem::exists(kLund)) {
    WARN("Lund data not found at " << kLund);
    return;
  }
  test::TempDir tmp;
  const std::string db = tmp.file("lund.gdb");
  Run r = run("geotags build --geotags " + kLund + " " + kCam +
              " --photo-hfov-deg 60 --branching 12 --depth 3 --sift 800 --orb 300 --out " + db);
  INFO(r.output);
  REQUIRE(r.code == 0);
  CHECK(r.output.find("29 views") != std::string::npos);
  CHECK(tmp.num_entries() == 1);
  r = run("geotags query --db " + db + " --image " + std::string(GEODRIFT_DATA_DIR) +
          "/opensfm_lund/images/07.jpg --top-k 2");
  INFO(r.output);
  REQUIRE(r.code == 0);
  CHECK(r.output.find("1,6,") != std::string::npos);  // rank 1 is view 6 = 07.jpg
  CHECK(r.output.find("07.jpg") != std::string::npos);
  r = run("geotags query --db " + db + " --image nope.png");
  CHECK(r.code == 1);
  CHECK(r.output.find("nope.png") != std::string::npos);
}

TEST_CASE("geotags CLI: a folder of geo-tagged JPEGs without CSV builds from EXIF",
          "[geotag][cli][exif][data]") {
  const std::string images = std::string(GEODRIFT_DATA_DIR) + "/opensfm_lund/images/";
  if (!std::filesystem::exists(images + "01.jpg")) {
    WARN("Lund images not found at " << images);
    return;
  }
  test::TempDir tmp;
  namespace fs = std::filesystem;
  fs::create_directories(tmp.path() / "photos");
  for (const char* n : {"02.jpg", "06.jpg", "10.jpg", "14.jpg", "18.jpg", "22.jpg"})
    fs::copy_file(images + n, tmp.path() / "photos" / n);
  // A JPEG without EXIF GPS: skipped with a warning naming it, never silently.
  // (01.jpg re-encoded by OpenCV, which writes no metadata.)
  REQUIRE(
      cv::imwrite((tmp.path() / "photos" / "nogps.jpg").string(), cv::imread(images + "01.jpg")));
  const std::string db = tmp.file("photos.gdb");
  Run r = run("geotags build --geotags " + (tmp.path() / "photos").string() + " " + kCam +
              " --branching 8 --depth 3 --sift 600 --orb 300 --out " + db);
  INFO(r.output);
  REQUIRE(r.code == 0);
  CHECK(r.output.find("6 sources (0 panoramas, 6 photos), 6 views") != std::string::npos);
  CHECK(r.output.find("warning: skipped") != std::string::npos);
  CHECK(r.output.find("nogps.jpg: no EXIF") != std::string::npos);
  CHECK(r.output.find("1 JPEGs skipped") != std::string::npos);
  r = run("geotags query --db " + db + " --image " + images + "10.jpg --top-k 3");
  INFO(r.output);
  REQUIRE(r.code == 0);
  // Rank 1 is view 2 = 10.jpg, a photo (direction -1) without heading (empty cell), at its
  // EXIF position (lund_exif_gps.csv: 55.698574, 13.195050).
  const auto first = r.output.find("\n1,2,");
  REQUIRE(first != std::string::npos);
  const std::string line = r.output.substr(first + 1, r.output.find('\n', first + 1) - first - 1);
  CHECK(line.find("10.jpg,-1,,55.69857") != std::string::npos);
  CHECK(line.find(",13.19505") != std::string::npos);
}

TEST_CASE("run CLI: a --geotags folder of JPEGs none of which has EXIF GPS is refused by name",
          "[geotag][cli][exif][errors]") {
  test::TempDir tmp;
  namespace fs = std::filesystem;
  fs::create_directories(tmp.path() / "drive");
  fs::create_directories(tmp.path() / "photos");
  cv::Mat frame(120, 160, CV_8U);
  cv::randu(frame, 0, 255);
  for (const char* f : {"000000.png", "000001.png"})
    REQUIRE(cv::imwrite((tmp.path() / "drive" / f).string(), frame));
  test::write_text((tmp.path() / "drive" / "calib.txt").string(), "K: 150 0 80 0 150 60 0 0 1\n");
  REQUIRE(cv::imwrite((tmp.path() / "photos" / "plain.jpg").string(), frame));
  const Run r = run("run --images " + tmp.file("drive") + " --geotags " + tmp.file("photos") +
                    " --out " + tmp.file("out"));
  INFO(r.output);
  CHECK(r.code == 1);
  CHECK(r.output.find("none of its 1 JPEG files is usable") != std::string::npos);
  CHECK(r.output.find("plain.jpg: no EXIF") != std::string::npos);
  CHECK(test::no_outputs(tmp.path(), "out"));
}
#endif
