// `geodrift geotags build|query` through the built executable: exit codes, messages, no
// partial or overwritten outputs.
#include <catch2/catch.hpp>

#if defined(GEODRIFT_CLI_EXE)
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include "support/test_files.hpp"

using namespace geodrift;

namespace {
struct Run {
  int code = -1;
  std::string out;
};
Run run(const std::string& args) {
  const std::string cmd = std::string(GEODRIFT_CLI_EXE) + " " + args + " 2>&1";
  Run r;
  FILE* p = ::popen(cmd.c_str(), "r");
  REQUIRE(p != nullptr);
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  const int st = ::pclose(p);
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}
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
  CHECK(r.out.find("build or query") != std::string::npos);
  r = run("geotags build --out " + tmp.file("x.gdb"));
  CHECK(r.code == 2);
  CHECK(r.out.find("--geotags") != std::string::npos);
  r = run("geotags build --geotags " + tmp.file("none") + " --out " + tmp.file("x.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.out.find("does not exist") != std::string::npos);
  r = run("geotags build --geotags " + tmp.path().string() + " --out " + tmp.file("x.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.out.find("geotags.csv") != std::string::npos);
  test::write_text(tmp.file("bad.gdb"), "not a database");
  r = run("geotags query --db " + tmp.file("bad.gdb") + " --image " + tmp.file("bad.gdb"));
  CHECK(r.code == 1);
  CHECK(r.out.find("not a geodrift geotag database") != std::string::npos);
  r = run("geotags build --geotags " + tmp.file("bad.gdb") + " --out " + tmp.file("bad.gdb") + " " +
          kCam);
  CHECK(r.code == 1);
  CHECK(r.out.find("refusing to overwrite") != std::string::npos);
  CHECK(test::read_text(tmp.file("bad.gdb")) == "not a database");
  CHECK(tmp.num_entries() == 1);
}

TEST_CASE("run CLI: the geo-tag cost options are validated before any work",
          "[geotag][cli][errors]") {
  test::TempDir tmp;
  for (const char* bad : {"--geotag-every 0", "--geotag-every -3", "--geotag-top-k 0"}) {
    const Run r = run("run --images " + tmp.path().string() + " --geotags " + tmp.path().string() +
                      " " + bad + " --out " + tmp.file("out"));
    INFO(bad << ": " << r.out);
    CHECK(r.code == 2);
    CHECK(r.out.find(std::string(bad).substr(0, std::string(bad).find(' '))) != std::string::npos);
  }
  CHECK(tmp.num_entries() == 0);
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
  INFO(r.out);
  REQUIRE(r.code == 0);
  CHECK(r.out.find("29 views") != std::string::npos);
  CHECK(tmp.num_entries() == 1);
  r = run("geotags query --db " + db + " --image " + std::string(GEODRIFT_DATA_DIR) +
          "/opensfm_lund/images/07.jpg --top-k 2");
  INFO(r.out);
  REQUIRE(r.code == 0);
  CHECK(r.out.find("1,6,") != std::string::npos);  // rank 1 is view 6 = 07.jpg
  CHECK(r.out.find("07.jpg") != std::string::npos);
  r = run("geotags query --db " + db + " --image nope.png");
  CHECK(r.code == 1);
  CHECK(r.out.find("nope.png") != std::string::npos);
}
#endif
