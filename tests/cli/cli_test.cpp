// The geodrift command end to end: bad input gives a clear message, a non-zero exit and no
// output; simulate -> correct -> eval on a stretch of KITTI 02 improves on INIT only.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/test_files.hpp"

namespace fs = std::filesystem;

namespace {

using Run = geodrift::test::CliRun;
Run run(const std::string& args) { return geodrift::test::run_cli(GEODRIFT_CLI_EXE, args); }

/// A small KITTI trajectory in M: 40 poses on a curve in M's x-z plane (y down, as a camera
/// driving on flat ground), 0.5 M units apart.
std::string trajectory_text(int n = 40) {
  std::ostringstream os;
  for (int i = 0; i < n; ++i) {
    const double t = 0.04 * i;
    const double x = 10 * std::sin(t), z = 10 * (1 - std::cos(t)) + 0.5 * i;
    os << "1 0 0 " << x << " 0 1 0 0 0 0 1 " << z << "\n";
  }
  return os.str();
}

/// Anchors in W (x,y,z; needs --origin): W = 2 · (x_M, z_M, -y_M).
std::string anchors_text(const std::vector<int>& frames) {
  std::ostringstream os;
  os << "frame,x,y,z,sigma_m\n";
  for (int f : frames) {
    const double t = 0.04 * f;
    os << f << "," << 2 * 10 * std::sin(t) << "," << 2 * (10 * (1 - std::cos(t)) + 0.5 * f)
       << ",0,0.05\n";
  }
  return os.str();
}

/// Mean 2D error from `geodrift eval --json` output.
double mean_2d(const std::string& json) {
  const std::string key = "\"error_2d\": {\"mean\": ";
  const auto p = json.find(key);
  REQUIRE(p != std::string::npos);
  return std::stod(json.substr(p + key.size()));
}

/// Every number following `"key": ` in a JSON text, in order.
std::vector<double> json_numbers(const std::string& json, const std::string& key) {
  std::vector<double> v;
  const std::string k = "\"" + key + "\": ";
  for (auto p = json.find(k); p != std::string::npos; p = json.find(k, p + 1)) {
    std::size_t q = p + k.size();
    if (json[q] == '[') ++q;  // the first element of an array
    v.push_back(std::stod(json.substr(q)));
  }
  return v;
}

/// Total LM iterations of report.json's steps of `kind` ("pgo", "ba").
int step_iterations(const std::string& json, const std::string& kind) {
  int n = 0;
  const std::string k = "{\"kind\": \"" + kind + "\"";
  for (auto p = json.find(k); p != std::string::npos; p = json.find(k, p + 1))
    n += static_cast<int>(json_numbers(json.substr(p, json.find('}', p) - p), "iterations").at(0));
  return n;
}

}  // namespace

TEST_CASE("geodrift correct rejects bad input with a message, non-zero exit, no output", "[cli]") {
  geodrift::test::TempDir t;
  const std::string traj = t.write("traj.txt", trajectory_text());
  const std::string good = t.write("good.csv", anchors_text({5, 15, 25, 35}));
  const std::string base = "correct --origin 49.0,8.4,100 --trajectory " + traj;
  const auto correct = [&](const std::string& anchors, const std::string& extra = "") {
    return run(base + " --anchors " + anchors + " --out " + t.file("out") + " " + extra);
  };
  const auto expect_failure = [&](const Run& r, const std::vector<std::string>& words) {
    INFO(r.output);
    CHECK(r.code != 0);
    for (const auto& w : words) CHECK(r.output.find(w) != std::string::npos);
    CHECK(geodrift::test::no_outputs(t.path(), "out"));
  };

  SECTION("the good input works (so the failures below are the input's)") {
    const Run r = correct(good, "--mode init");
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(fs::exists(t.file("out/trajectory.csv")));
    CHECK(fs::exists(t.file("out/report.json")));
  }
  SECTION("fewer than 4 anchors") {
    expect_failure(correct(t.write("a.csv", anchors_text({5, 15, 25}))),
                   {"a.csv", "fewer than 4 anchors"});
  }
  SECTION("coincident anchors") {
    expect_failure(correct(t.write("a.csv", anchors_text({5, 5, 5, 5}))),
                   {"a.csv", "coincident", "unobservable"});
  }
  SECTION("collinear (vertical) anchors") {
    expect_failure(
        correct(t.write("a.csv", "frame,x,y,z\n5,1,2,0\n15,1,2,3\n25,1,2,6\n35,1,2,9\n")),
        {"a.csv", "collinear", "unobservable"});
  }
  SECTION("an anchor outside the trajectory's range") {
    expect_failure(correct(t.write("a.csv", anchors_text({5, 15, 25, 35, 60}))),
                   {"a.csv:6", "outside the trajectory"});
  }
  SECTION("NaN and short lines in the anchors file") {
    expect_failure(
        correct(t.write("a.csv", "frame,x,y,z\n5,1,2,0\n15,nan,2,3\n25,5,2,6\n35,9,2,9\n")),
        {"a.csv:3"});
    expect_failure(correct(t.write("b.csv", "frame,x,y,z\n5,1,2,0\n15,3,2\n25,5,2,6\n35,9,2,9\n")),
                   {"b.csv:3"});
  }
  SECTION("NaN and short lines in the trajectory") {
    std::string text = trajectory_text();
    const auto third = text.find('\n', text.find('\n', text.find('\n') + 1) + 1) + 1;  // line 4
    std::string nan = text;
    nan.replace(third, 1, "nan");
    const std::string tn = t.write("nan.txt", nan);
    expect_failure(run("correct --origin 49,8.4,100 --trajectory " + tn + " --anchors " + good +
                       " --out " + t.file("out")),
                   {"nan.txt:4"});
    std::string shrt = text;
    shrt.insert(third, "1 0 0 1 0 1 0\n");
    const std::string ts = t.write("short.txt", shrt);
    expect_failure(run("correct --origin 49,8.4,100 --trajectory " + ts + " --anchors " + good +
                       " --out " + t.file("out")),
                   {"short.txt:4"});
  }
  SECTION("NaN and short lines in the times file") {
    std::string times;
    for (int i = 0; i < 40; ++i)
      times += (i == 7 ? std::string("nan") : std::to_string(0.1 * i)) + "\n";
    expect_failure(correct(good, "--times " + t.write("times.txt", times)), {"times.txt:8"});
    times.clear();
    for (int i = 0; i < 39; ++i) times += std::to_string(0.1 * i) + "\n";
    expect_failure(correct(good, "--times " + t.write("t2.txt", times)),
                   {"t2.txt", "39 timestamps for 40"});
  }
  SECTION("a missing file") {
    expect_failure(correct(t.file("no_such_anchors.csv")), {"no_such_anchors.csv"});
    expect_failure(run("correct --trajectory " + t.file("no_such_traj.txt") + " --anchors " + good +
                       " --out " + t.file("out")),
                   {"no_such_traj.txt"});
    expect_failure(correct(good, "--map " + t.file("no_such_map")), {"no_such_map"});
  }
  SECTION("bad values of the correction options") {
    expect_failure(correct(good, "--ba-min-parallax 90"), {"--ba-min-parallax", "[0, 90)"});
    expect_failure(correct(good, "--ba-min-parallax -1"), {"--ba-min-parallax", "[0, 90)"});
    expect_failure(correct(good, "--ba-min-parallax 1deg"), {"--ba-min-parallax", "1deg"});
    expect_failure(correct(good, "--ba-cost-tolerance-sd -0.5"),
                   {"--ba-cost-tolerance-sd", ">= 0"});
    expect_failure(correct(good, "--ba-cost-tolerance-sd nan"),
                   {"--ba-cost-tolerance-sd", "not a finite number"});
    expect_failure(correct(good, "--first-window later"), {"--first-window", "later"});
    expect_failure(correct(good, "--min-window-keyframes -1"),
                   {"--min-window-keyframes", "[0, 1000000]"});
    expect_failure(correct(good, "--min-window-keyframes 2000000"),
                   {"--min-window-keyframes", "[0, 1000000]"});
    expect_failure(correct(good, "--min-window-keyframes 30.5"),
                   {"--min-window-keyframes", "not an integer"});
  }
  SECTION("an unknown option or mode") {
    const Run r = correct(good, "--bogus 1");
    expect_failure(r, {"unknown option", "--bogus"});
    CHECK(r.code == 2);
    expect_failure(correct(good, "--mode fast"), {"unknown correction mode", "fast"});
    expect_failure(correct(good, "--mode init+ba"), {"needs --map"});
  }
  SECTION("--out an existing file is refused and left untouched") {
    const std::string f = t.write("out", "precious\n");
    const Run r = correct(good);
    INFO(r.output);
    CHECK(r.code != 0);
    CHECK(r.output.find("not a directory") != std::string::npos);
    std::ifstream in(f);
    std::string s;
    std::getline(in, s);
    CHECK(s == "precious");
  }
  SECTION("--out a non-empty folder needs --force, which keeps other files") {
    fs::create_directories(t.file("out"));
    t.write("out/mine.txt", "precious\n");
    const Run r = correct(good, "--mode init");
    INFO(r.output);
    CHECK(r.code != 0);
    CHECK(r.output.find("not empty") != std::string::npos);
    CHECK_FALSE(fs::exists(t.file("out/trajectory.csv")));
    const Run f = correct(good, "--mode init --force");
    INFO(f.output);
    CHECK(f.code == 0);
    CHECK(fs::exists(t.file("out/trajectory.csv")));
    CHECK(fs::exists(t.file("out/mine.txt")));
  }
  SECTION("every subcommand has --help") {
    for (const char* c : {"correct", "eval", "simulate"}) {
      const Run r = run(std::string(c) + " --help");
      CHECK(r.code == 0);
      CHECK(r.output.find("usage: geodrift") != std::string::npos);
    }
    CHECK(run("frobnicate").code == 2);
  }
}

TEST_CASE("simulate -> correct -> eval on KITTI 02: correction beats INIT only", "[cli]") {
  geodrift::test::TempDir t;
  const std::string data = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const Run sim = run("simulate --sequence 02 --frames 0:1000 --interval 100 --seed 3 --data-dir " +
                      data + " --out " + t.file("sim"));
  INFO(sim.output);
  REQUIRE(sim.code == 0);
  for (const char* f :
       {"trajectory_kitti.txt", "anchors.csv", "ground_truth_kitti.txt", "ground_truth_w.txt",
        "colmap/cameras.txt", "colmap/images.txt", "colmap/points3D.txt"})
    CHECK(fs::exists(t.file("sim/") + f));
  const std::string in = "--trajectory " + t.file("sim/trajectory_kitti.txt") + " --anchors " +
                         t.file("sim/anchors.csv");
  const auto correct_eval = [&](const std::string& name, const std::string& extra) {
    const Run c = run("correct " + in + " " + extra + " --out " + t.file(name));
    INFO(c.output);
    REQUIRE(c.code == 0);
    const Run e = run("eval --json --result " + t.file(name) + " --ground-truth " +
                      t.file("sim/ground_truth_kitti.txt") + " --kitti-to-w");
    INFO(e.output);
    REQUIRE(e.code == 0);
    return mean_2d(e.output);
  };
  const std::string map = "--map " + t.file("sim/colmap");
  const double init = correct_eval("init", map + " --mode init");
  const double ours = correct_eval("ours", map);
  const double traj_only = correct_eval("traj", "");
  INFO("mean 2D error: init " << init << " m, ours " << ours << " m, trajectory-only " << traj_only
                              << " m");
  CHECK(ours < init);
  CHECK(traj_only < init);
  for (const char* f :
       {"trajectory.csv", "trajectory_kitti.txt", "trajectory_tum.txt", "track.geojson",
        "track.kml", "points.ply", "topview.svg", "scale.svg", "report.json"})
    CHECK(fs::exists(t.file("ours/") + f));
  CHECK_FALSE(fs::exists(t.file("traj/points.ply")));

  // The three options reach the Corrector and report.json records them.
  {
    const std::string rep = geodrift::test::read_text(t.file("ours/report.json"));
    CHECK(rep.find("\"first_window\": \"from-start\"") != std::string::npos);
    REQUIRE(json_numbers(rep, "ba_min_parallax_deg").size() == 1);
    CHECK(json_numbers(rep, "ba_min_parallax_deg")[0] == Approx(1.146));
    CHECK(json_numbers(rep, "ba_cost_tolerance_sd")[0] == Approx(1.0));
    REQUIRE(json_numbers(rep, "min_window_keyframes").size() == 1);
    CHECK(json_numbers(rep, "min_window_keyframes")[0] == 30);
    const Run c = run("correct " + in + " " + map +
                      " --first-window paper --ba-min-parallax 0 --ba-cost-tolerance-sd 1000"
                      " --min-window-keyframes 0"
                      " --out " +
                      t.file("opts"));
    INFO(c.output);
    REQUIRE(c.code == 0);
    const std::string rep2 = geodrift::test::read_text(t.file("opts/report.json"));
    CHECK(rep2.find("\"first_window\": \"paper\"") != std::string::npos);
    CHECK(json_numbers(rep2, "ba_min_parallax_deg")[0] == 0.0);
    CHECK(json_numbers(rep2, "ba_cost_tolerance_sd")[0] == 1000.0);
    CHECK(json_numbers(rep2, "min_window_keyframes")[0] == 0);
    // Default: some BA window leaves low-parallax points out; with 0 none does.
    const auto skipped = json_numbers(rep, "skipped_points");
    const auto skipped2 = json_numbers(rep2, "skipped_points");
    REQUIRE(!skipped.empty());
    CHECK(*std::max_element(skipped.begin(), skipped.end()) > 0);
    CHECK(*std::max_element(skipped2.begin(), skipped2.end()) == 0);
    // The first window after INIT: from keyframe 0 by default, later with the paper's.
    const auto windows = json_numbers(rep, "window_keyframes");
    const auto windows2 = json_numbers(rep2, "window_keyframes");
    REQUIRE(windows.size() >= 2);  // [0] is INIT's (-1), [1] the first PGO's first keyframe
    REQUIRE(windows2.size() >= 2);
    CHECK(windows[1] == 0);
    CHECK(windows2[1] > 0);
    // Anchors here are ~33 keyframes apart, so the default window (3 anchors) is longer than 30
    // keyframes and later windows start after keyframe 0; a minimum length longer than the
    // path lengthens every window back to the first keyframe.
    CHECK(*std::max_element(windows.begin() + 1, windows.end()) > 0);
    const Run w = run("correct " + in + " " + map + " --min-window-keyframes 1000000 --out " +
                      t.file("longwin"));
    INFO(w.output);
    REQUIRE(w.code == 0);
    const std::string rep3 = geodrift::test::read_text(t.file("longwin/report.json"));
    CHECK(json_numbers(rep3, "min_window_keyframes")[0] == 1000000);
    const auto windows3 = json_numbers(rep3, "window_keyframes");
    REQUIRE(windows3.size() == windows.size());
    CHECK(*std::max_element(windows3.begin() + 1, windows3.end()) == 0);
    // A tolerance of 1000 SD stops each BA at its first accepted step.
    int ba_steps = 0;
    for (auto p = rep2.find("{\"kind\": \"ba\""); p != std::string::npos;
         p = rep2.find("{\"kind\": \"ba\"", p + 1))
      ++ba_steps;
    REQUIRE(ba_steps > 0);
    INFO("BA iterations: default " << step_iterations(rep, "ba") << ", tolerance 1000 SD "
                                   << step_iterations(rep2, "ba"));
    CHECK(step_iterations(rep2, "ba") < step_iterations(rep, "ba"));
    // Two BA passes at most (CorrectorOptions::ba_two_pass), each stopped at its first step.
    CHECK(step_iterations(rep2, "ba") <= 4 * ba_steps);
  }

  // A NaN in the map is named by file and line, and nothing is written.
  fs::copy(t.file("sim/colmap"), t.file("badmap"));
  {
    std::ifstream is(t.file("badmap/points3D.txt"));
    std::vector<std::string> lines;
    std::string l;
    while (std::getline(is, l)) lines.push_back(l);
    is.close();
    std::size_t k = 0;
    while (k < lines.size() && (lines[k].empty() || lines[k][0] == '#')) ++k;
    REQUIRE(k + 1 < lines.size());
    const std::size_t x0 = lines[k + 1].find(' ') + 1, x1 = lines[k + 1].find(' ', x0);
    lines[k + 1].replace(x0, x1 - x0, "nan");  // the second point's X := nan
    std::ofstream os(t.file("badmap/points3D.txt"));
    for (const auto& x : lines) os << x << "\n";
    const Run bad = run("correct " + in + " --map " + t.file("badmap") + " --out " + t.file("bad"));
    INFO(bad.output);
    CHECK(bad.code != 0);
    CHECK(bad.output.find("points3D.txt:" + std::to_string(k + 2)) != std::string::npos);
    CHECK(geodrift::test::no_outputs(t.path(), "bad"));
  }

  // Every input frame appears; with --keyframe-step the others are interpolated.
  const Run c = run("correct " + in + " --keyframe-step 3 --out " + t.file("step"));
  INFO(c.output);
  REQUIRE(c.code == 0);
  std::ifstream csv(t.file("step/trajectory.csv"));
  std::string line;
  int rows = 0, interpolated = 0;
  while (std::getline(csv, line))
    if (!line.empty() && std::isdigit(static_cast<unsigned char>(line[0]))) {
      ++rows;
      interpolated += line.find(",interpolated,") != std::string::npos;
    }
  int poses = 0;
  std::ifstream tk(t.file("sim/trajectory_kitti.txt"));
  while (std::getline(tk, line)) poses += !line.empty() && line[0] != '#';
  CHECK(rows == poses);
  CHECK(interpolated > poses / 2);
}
