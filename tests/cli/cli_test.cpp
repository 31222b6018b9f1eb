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
#include <iomanip>
#include <limits>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/correction/time_offset.hpp"
#include "geodrift/io/anchors.hpp"
#include "geodrift/io/csv.hpp"
#include "geodrift/io/trajectory.hpp"
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

/// Every number following `"key": ` in a JSON text, in order (null: NaN).
std::vector<double> json_numbers(const std::string& json, const std::string& key) {
  std::vector<double> v;
  const std::string k = "\"" + key + "\": ";
  for (auto p = json.find(k); p != std::string::npos; p = json.find(k, p + 1)) {
    std::size_t q = p + k.size();
    if (json[q] == '[') ++q;  // the first element of an array
    v.push_back(json.compare(q, 4, "null") == 0 ? std::numeric_limits<double>::quiet_NaN()
                                                : std::stod(json.substr(q)));
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
  SECTION("4 anchors, one of them 500 m off: the error says so and names the lines") {
    std::ostringstream text;
    text << anchors_text({5, 15});  // the header (line 1) and lines 2, 3
    const double t25 = 0.04 * 25;   // line 4: frame 25, its W position + 500 m east
    text << "25," << 500 + 2 * 10 * std::sin(t25) << "," << 2 * (10 * (1 - std::cos(t25)) + 12.5)
         << ",0,0.05\n";
    const std::string last = anchors_text({35});
    text << last.substr(last.find('\n') + 1);
    expect_failure(
        correct(t.write("a.csv", text.str())),
        {"a.csv", "INIT did not succeed", "3 of 4 left", "inconsistent", "check lines 2, 3, 4, 5"});
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
  SECTION("a trajectory that jumps (a new map after lost tracking) unless --allow-jumps") {
    // From pose 30 on (lines 31..40) `shift` units east.
    const auto shifted = [&](double shift) {
      std::istringstream in(trajectory_text());
      std::string line, text;
      for (int i = 0; std::getline(in, line); ++i) {
        if (i >= 30) {
          std::istringstream f(line);
          std::vector<double> v(12);
          for (double& x : v) f >> x;
          v[3] += shift;
          std::ostringstream o;
          for (double x : v) o << x << " ";
          line = o.str();
        }
        text += line + "\n";
      }
      return text;
    };
    const std::string tj = t.write("jump.txt", shifted(500));
    const std::string early = t.write("early.csv", anchors_text({3, 8, 13, 18}));
    const auto command = [&](const std::string& traj) {
      return "correct --origin 49,8.4,100 --mode init --trajectory " + traj + " --anchors " +
             early + " --out " + t.file("out");
    };
    const std::string cmd = command(tj);
    expect_failure(run(cmd), {"jump.txt", "jumps between lines 30 and 31", "frames 29 and 30",
                              "new SLAM map", "--allow-jumps"});
    const Run r = run(cmd + " --allow-jumps");
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(r.output.find("warning") != std::string::npos);
    const std::string json = geodrift::test::read_text(t.file("out/report.json"));
    CHECK(json_numbers(json, "line_from") == std::vector<double>{30});
    CHECK(json_numbers(json, "frame_to") == std::vector<double>{30});
    REQUIRE(json_numbers(json, "ratio").size() == 1);
    CHECK(json_numbers(json, "ratio")[0] > 10);
    CHECK(json.find("\"jump\": true") != std::string::npos);
    // A 4-unit leap (about 7x the step): a warning naming it, and the correction runs.
    const Run s = run(command(t.write("suspect.txt", shifted(4))) + " --force");
    INFO(s.output);
    REQUIRE(s.code == 0);
    CHECK(s.output.find("suspect step between lines 30 and 31") != std::string::npos);
    const std::string json2 = geodrift::test::read_text(t.file("out/report.json"));
    REQUIRE(json_numbers(json2, "ratio").size() == 1);
    CHECK(json_numbers(json2, "ratio")[0] > 4);
    CHECK(json_numbers(json2, "ratio")[0] < 10);
    CHECK(json2.find("\"jump\": false") != std::string::npos);
    CHECK(
        geodrift::test::read_text(t.file("out/topview.svg")).find("SUSPECT STEP before line 31") !=
        std::string::npos);
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

  // Uncertainty (issue 24 item 4): every row of trajectory.csv has sd_east/sd_north/cov_en, the
  // ellipses are in topview.svg, and the true positions mostly lie inside the 95 % ellipses
  // (1000 frames of 02, seed 3: 337 of 337 measured); report.json lists every anchor.
  {
    const auto rows = geodrift::io::read_trajectory_csv(t.file("ours/trajectory.csv"));
    const auto gt = geodrift::io::read_trajectory(t.file("sim/ground_truth_w.txt"));
    REQUIRE(!rows.empty());
    // The simulator's W and correct's W are the same UTM zone shifted to different origins:
    // compare in UTM (the ground truth's origin is in its header).
    const std::string head = geodrift::test::read_text(t.file("sim/ground_truth_w.txt"));
    const std::size_t at = head.find("E0 ");
    REQUIRE(at != std::string::npos);
    double e0 = 0, n0 = 0;
    REQUIRE(std::sscanf(head.c_str() + at, "E0 %lf N0 %lf", &e0, &n0) == 2);
    std::map<int, Eigen::Vector3d> truth;  // frame -> true centre in UTM (easting, northing)
    for (const auto& g : gt.poses)
      truth[g.frame] = g.T_cw.inverse().translation() + Eigen::Vector3d(e0, n0, 0);
    int inside = 0, n = 0;
    for (const auto& r : rows) {
      REQUIRE(std::isfinite(r.sd_east));
      REQUIRE(std::isfinite(r.sd_north));
      REQUIRE(std::isfinite(r.cov_en));
      CHECK(std::abs(r.cov_en) <= r.sd_east * r.sd_north + 1e-9);
      if (!truth.count(r.frame)) continue;
      const Eigen::Vector2d d =
          Eigen::Vector2d(r.easting, r.northing) - truth.at(r.frame).head<2>();
      Eigen::Matrix2d S;
      S << r.sd_east * r.sd_east, r.cov_en, r.cov_en, r.sd_north * r.sd_north;
      ++n;
      inside += d.dot(S.inverse() * d) <= 5.991;
    }
    INFO(inside << " of " << n << " poses inside their 95 % ellipse");
    CHECK(inside >= 0.8 * n);  // measured: 337 of 337
    CHECK(geodrift::test::read_text(t.file("ours/topview.svg")).find("<ellipse") !=
          std::string::npos);
    const std::string rep = geodrift::test::read_text(t.file("ours/report.json"));
    CHECK(rep.find("\"uncertainty\": {\"ok\": true") != std::string::npos);
    const std::size_t num_anchors =
        geodrift::io::read_anchors_csv(t.file("sim/anchors.csv")).records.size();
    CHECK(json_numbers(rep, "residual_2d_m").size() == num_anchors);
    // Each anchor's leave-one-out prediction χ² (null where the others do not predict it):
    // their mean is 2·prediction_factor, which the drift factor was set to bring within a
    // quarter of its sampling error 1/√n of 1.
    const std::vector<double> entries = json_numbers(rep, "prediction_chi2");
    CHECK(entries.size() == num_anchors);
    std::vector<double> chi2;
    for (const double c : entries)
      if (std::isfinite(c)) chi2.push_back(c);
    REQUIRE(chi2.size() >= 5);
    double mean_chi2 = 0;
    for (const double c : chi2) mean_chi2 += c / static_cast<double>(chi2.size());
    const double factor = json_numbers(rep, "prediction_factor").at(0);
    CHECK(mean_chi2 / 2 == Approx(factor).epsilon(1e-6));
    CHECK(std::abs(factor - 1) <= 0.25 / std::sqrt(static_cast<double>(chi2.size())) + 1e-9);
    const Run c = run("correct " + in + " --no-uncertainty --out " + t.file("nounc"));
    INFO(c.output);
    REQUIRE(c.code == 0);
    for (const auto& r : geodrift::io::read_trajectory_csv(t.file("nounc/trajectory.csv")))
      REQUIRE(std::isnan(r.sd_east));
    CHECK(geodrift::test::read_text(t.file("nounc/topview.svg")).find("<ellipse") ==
          std::string::npos);
  }

  // Ground truth that ends before the last anchor: nothing to say after it (n/a and null, not
  // a mean of zero over no keyframes).
  {
    std::istringstream gt(geodrift::test::read_text(t.file("sim/ground_truth_kitti.txt")));
    std::string line, head;
    for (int i = 0; i < 700 && std::getline(gt, line); ++i) head += line + "\n";
    geodrift::test::write_text(t.file("gt_700.txt"), head);
    const std::string args = "eval --result " + t.file("ours") + " --ground-truth " +
                             t.file("gt_700.txt") + " --kitti-to-w";
    const Run e = run(args);
    INFO(e.output);
    REQUIRE(e.code == 0);
    CHECK(e.output.find("2D error after last anchor n/a (no keyframe after frame") !=
          std::string::npos);
    const Run j = run(args + " --json");
    INFO(j.output);
    REQUIRE(j.code == 0);
    CHECK(j.output.find("\"error_2d_after_last_anchor\": null") != std::string::npos);
  }

  // --weights drift reaches the Corrector (it once had no effect: only the paper's weights were
  // ever set), and report.json says which weights were used.
  {
    const double drift = correct_eval("drift", map + " --weights drift");
    const std::string rep_d = geodrift::test::read_text(t.file("drift/report.json"));
    const std::string rep_p = geodrift::test::read_text(t.file("ours/report.json"));
    CHECK(rep_d.find("\"edge_weights\": \"drift\"") != std::string::npos);
    CHECK(rep_p.find("\"edge_weights\": \"metric\"") != std::string::npos);  // the default
    CHECK(geodrift::test::read_text(t.file("drift/trajectory_kitti.txt")) !=
          geodrift::test::read_text(t.file("ours/trajectory_kitti.txt")));
    CHECK(drift < init);
  }

  // --local-scale: cross-validated by default, a given SD reaches the Corrector, a bad one is
  // a usage error; report.json says which and how it was chosen.
  {
    const std::string rep = geodrift::test::read_text(t.file("ours/report.json"));
    CHECK(rep.find("\"local_scale\": {\"sd\": ") != std::string::npos);
    CHECK((rep.find("\"chosen_by\": \"cross-validation\"") != std::string::npos ||
           rep.find("\"chosen_by\": \"default\", \"note\": ") != std::string::npos));
    correct_eval("local", map + " --local-scale 0.04");
    const std::string rep_l = geodrift::test::read_text(t.file("local/report.json"));
    CHECK(rep_l.find("\"local_scale\": {\"sd\": 0.04, \"length_m\": 25, \"chosen_by\": "
                     "\"--local-scale\"") != std::string::npos);
    const Run bad = run("correct " + in + " --local-scale -1 --out " + t.file("bad_local"));
    CHECK(bad.code != 0);
    CHECK(bad.output.find("--local-scale") != std::string::npos);
    CHECK_FALSE(fs::exists(t.file("bad_local")));
  }

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
                      " --min-window-keyframes 0 --fixed-windows"
                      " --out " +
                      t.file("opts"));
    INFO(c.output);
    REQUIRE(c.code == 0);
    const std::string rep2 = geodrift::test::read_text(t.file("opts/report.json"));
    CHECK(rep2.find("\"first_window\": \"paper\"") != std::string::npos);
    CHECK(json_numbers(rep2, "ba_min_parallax_deg")[0] == 0.0);
    CHECK(json_numbers(rep2, "ba_cost_tolerance_sd")[0] == 1000.0);
    CHECK(json_numbers(rep2, "min_window_keyframes")[0] == 0);
    CHECK(rep.find("\"adaptive_windows\": true") != std::string::npos);
    CHECK(rep2.find("\"adaptive_windows\": false") != std::string::npos);
    REQUIRE(json_numbers(rep, "grown_windows").size() == 1);
    CHECK(json_numbers(rep2, "grown_windows")[0] == 0);
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
    // Window steps discarded and run again over more keyframes (adaptive windows) are reported
    // too, each with its window's first keyframe; windows from the first keyframe are never run
    // again.
    std::size_t discarded = 0;
    for (auto at = rep.find("(discarded:"); at != std::string::npos;
         at = rep.find("(discarded:", at + 1))
      ++discarded;
    REQUIRE(windows3.size() + discarded == windows.size());
    CHECK(*std::max_element(windows3.begin() + 1, windows3.end()) == 0);
    // Every BA window stops on the cost tolerance (not the iteration limit): its last accepted
    // step lowered the cost by less than 1000 SDs of ½χ². (A window that starts 5,000x above
    // its noise level takes several accepted steps before a step gains that little.)
    int ba_steps = 0, tolerance_stops = 0;
    for (auto p = rep2.find("{\"kind\": \"ba\""); p != std::string::npos;
         p = rep2.find("{\"kind\": \"ba\"", p + 1)) {
      ++ba_steps;
      tolerance_stops +=
          rep2.substr(p, rep2.find('}', p) - p).find("function tolerance") != std::string::npos;
    }
    REQUIRE(ba_steps > 0);
    INFO("BA iterations: default " << step_iterations(rep, "ba") << ", tolerance 1000 SD "
                                   << step_iterations(rep2, "ba"));
    CHECK(step_iterations(rep2, "ba") < step_iterations(rep, "ba"));
    CHECK(tolerance_stops == ba_steps);
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

namespace {

/// Camera centre in W (metres) of a known path at time s seconds after its start: a gentle S
/// curve at 5 m/s with a small height oscillation.
Eigen::Vector3d known_path(double s) {
  return Eigen::Vector3d(20.0 * std::sin(0.1 * s), 5.0 * s, 0.2 * std::sin(0.7 * s));
}

/// One TUM line "t x y z qx qy qz qw": camera yawed by 0.1·s about W's z (up).
std::string tum_line(double t, const Eigen::Vector3d& c, double s) {
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.1 * s, Eigen::Vector3d::UnitZ()));
  std::ostringstream os;
  os << std::fixed << std::setprecision(6) << t << std::setprecision(12) << ' ' << c.x() << ' '
     << c.y() << ' ' << c.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w()
     << "\n";
  return os.str();
}

}  // namespace

TEST_CASE("eval associates a TUM keyframe result with 100 Hz ground truth by timestamp",
          "[cli][eval]") {
  geodrift::test::TempDir t;
  // Ground truth: 10 s at 100 Hz from a EuRoC-like epoch, with a dropout of poses 496..524
  // (0.29 s without ground truth).
  const double t0 = 1403636579.763555;
  const int n_gt = 1001;
  const auto gt_kept = [](int i) { return i < 496 || i > 524; };
  std::string gt_tum = "# ground truth, W, metres\n", gt_kitti, gt_times;
  for (int i = 0; i < n_gt; ++i) {
    if (!gt_kept(i)) continue;
    const double s = 0.01 * i;
    gt_tum += tum_line(t0 + s, known_path(s), s);
    // The same poses as KITTI lines (camera -> world [R | t]) and a times.txt.
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.1 * s, Eigen::Vector3d::UnitZ()).matrix();
    const Eigen::Vector3d c = known_path(s);
    std::ostringstream k;
    k << std::setprecision(12);
    for (int r = 0; r < 3; ++r)
      k << R(r, 0) << ' ' << R(r, 1) << ' ' << R(r, 2) << ' ' << c(r) << (r < 2 ? ' ' : '\n');
    gt_kitti += k.str();
    std::ostringstream tt;
    tt << std::fixed << std::setprecision(6) << t0 + s << "\n";
    gt_times += tt.str();
  }
  const std::string gt = t.write("gt_tum.txt", gt_tum);
  // Result: every 3rd ground-truth pose (ORB-SLAM-like KeyFrameTrajectory.txt), timestamps
  // jittered by up to ±4 ms (seeded), positions off by a constant (0.3, 0.4, 0.2) m: the 2D
  // error of every matched keyframe is exactly 0.5 m. Keyframes 498..522 fall in the dropout
  // (>= 26 ms from any ground truth), and one more pose lies 0.5 s after the ground truth ends.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.004, 0.004);
  const Eigen::Vector3d offset(0.3, 0.4, 0.2);
  std::string res_tum = "# keyframes\n";
  int n_res = 0, in_dropout = 0;
  for (int i = 0; i < n_gt; i += 3, ++n_res) {
    const double s = 0.01 * i;
    res_tum += tum_line(t0 + s + jitter(rng), known_path(s) + offset, s);
    in_dropout += gt_kept(i) ? 0 : 1;
  }
  res_tum += tum_line(t0 + 10.5, known_path(10.5) + offset, 10.5);
  ++n_res;
  REQUIRE(n_res == 335);
  REQUIRE(in_dropout == 9);
  const std::string res = t.write("KeyFrameTrajectory.txt", res_tum);
  const std::string base = "eval --result " + res + " --ground-truth " + gt;

  SECTION("auto picks time association; mean 2D error 0.5 m over the 325 matched keyframes") {
    const Run r = run(base + " --json");
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(r.output.find("\"method\": \"time\"") != std::string::npos);
    CHECK(json_numbers(r.output, "matched") == std::vector<double>{325});
    CHECK(json_numbers(r.output, "unmatched") == std::vector<double>{10});
    CHECK(json_numbers(r.output, "unmatched_lost_to_closer") == std::vector<double>{0});
    CHECK(json_numbers(r.output, "result_poses") == std::vector<double>{335});
    CHECK(json_numbers(r.output, "ground_truth_poses") == std::vector<double>{n_gt - 29});
    CHECK(json_numbers(r.output, "max_time_diff_s") == std::vector<double>{0.01});
    REQUIRE(json_numbers(r.output, "max_abs_time_diff_s").size() == 1);
    CHECK(json_numbers(r.output, "max_abs_time_diff_s")[0] <= 0.004 + 1e-6);
    CHECK(json_numbers(r.output, "keyframes_evaluated") == std::vector<double>{325});
    CHECK(mean_2d(r.output) == Approx(0.5).margin(1e-6));
    // The "max" of error_2d is the 3rd number after "error_2d": all errors are 0.5.
    const std::string e2d = r.output.substr(r.output.find("\"error_2d\""));
    CHECK(json_numbers(e2d, "max")[0] == Approx(0.5).margin(1e-6));
    CHECK(json_numbers(e2d, "sd")[0] == Approx(0.0).margin(1e-6));
    // A constant offset is a similarity: the global Sim3 error vanishes.
    const std::string g = r.output.substr(r.output.find("\"global_sim3_error_2d\""));
    CHECK(json_numbers(g, "mean")[0] == Approx(0.0).margin(1e-6));
    // ATE without alignment: the 3D offset, |(0.3, 0.4, 0.2)|.
    CHECK(json_numbers(r.output, "ate_rmse")[0] == Approx(std::sqrt(0.29)).margin(1e-6));
  }
  SECTION("the text output states the association and the counts") {
    const Run r = run(base);
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(r.output.find("association                by time: nearest ground-truth pose within "
                        "0.01 s") != std::string::npos);
    CHECK(r.output.find("matched poses              325 of 335 (10 unmatched") !=
          std::string::npos);
    CHECK(r.output.find("Ave 0.500") != std::string::npos);
  }
  SECTION("a KITTI ground truth with --gt-times associates the same way") {
    const std::string k = t.write("gt_kitti.txt", gt_kitti);
    const std::string times = t.write("times.txt", gt_times);
    const Run r =
        run("eval --json --result " + res + " --ground-truth " + k + " --gt-times " + times);
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(r.output.find("\"method\": \"time\"") != std::string::npos);
    CHECK(json_numbers(r.output, "matched") == std::vector<double>{325});
    CHECK(mean_2d(r.output) == Approx(0.5).margin(1e-6));
    // Without the times, auto falls back to frame (line order): the wrong poses are paired.
    const Run f = run("eval --json --result " + res + " --ground-truth " + k);
    INFO(f.output);
    REQUIRE(f.code == 0);
    CHECK(f.output.find("\"method\": \"frame\"") != std::string::npos);
    CHECK(mean_2d(f.output) > 5.0);
    // A times file with a repeated stamp is an error naming the file and line.
    std::string bad = gt_times;
    const auto second = bad.find('\n') + 1;
    bad.replace(second, bad.find('\n', second) - second, bad.substr(0, bad.find('\n')));
    const Run b = run("eval --result " + res + " --ground-truth " + k + " --gt-times " +
                      t.write("bad_times.txt", bad));
    INFO(b.output);
    CHECK(b.code == 1);
    CHECK(b.output.find("bad_times.txt:2: timestamp") != std::string::npos);
    CHECK(b.output.find("does not increase") != std::string::npos);
  }
  SECTION("each ground-truth pose is used once; the tolerance decides; nothing matched fails") {
    // 50 ms reaches from keyframes 498 and 522 (30 ms into the dropout) to ground-truth poses
    // 495 and 525, but keyframes 495 and 525 are nearer to those (<= 4 ms) and keep them.
    const Run r = run(base + " --json --max-time-diff 0.05");
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(json_numbers(r.output, "matched") == std::vector<double>{325});
    CHECK(json_numbers(r.output, "unmatched") == std::vector<double>{10});
    CHECK(json_numbers(r.output, "unmatched_lost_to_closer") == std::vector<double>{2});
    CHECK(mean_2d(r.output) == Approx(0.5).margin(1e-6));
    // 0.6 s reaches from the pose 0.5 s after the end to the last ground-truth pose (which no
    // keyframe took): 326 matched, and that pair's error pulls the mean above 0.5 m.
    const Run w = run(base + " --json --max-time-diff 0.6");
    INFO(w.output);
    REQUIRE(w.code == 0);
    CHECK(json_numbers(w.output, "matched") == std::vector<double>{326});
    CHECK(json_numbers(w.output, "unmatched_lost_to_closer") == std::vector<double>{9});
    CHECK(json_numbers(w.output, "max_abs_time_diff_s")[0] == Approx(0.5).margin(1e-5));
    CHECK(mean_2d(w.output) > 0.5 + 1e-3);
    const Run n = run(base + " --time-offset 100");
    INFO(n.output);
    CHECK(n.code == 1);
    CHECK(n.output.find("only 0 keyframes of " + res) != std::string::npos);
    CHECK(n.output.find(gt) != std::string::npos);
    CHECK(n.output.find("within 0.01 s") != std::string::npos);
  }
  SECTION("forced frame association pairs by line order") {
    const Run r = run(base + " --json --associate frame");
    INFO(r.output);
    REQUIRE(r.code == 0);
    CHECK(r.output.find("\"method\": \"frame\"") != std::string::npos);
    CHECK(json_numbers(r.output, "matched") == std::vector<double>{335});
    CHECK(mean_2d(r.output) > 5.0);
    const Run bad = run(base + " --associate frame --max-time-diff 0.02");
    CHECK(bad.code == 2);
    CHECK(bad.output.find("time association only") != std::string::npos);
  }
  SECTION("bad options and timestamps are clear errors") {
    for (const char* opt : {"--max-time-diff -0.001", "--max-time-diff nan", "--time-offset inf",
                            "--associate nearest"}) {
      const Run r = run(base + " " + opt);
      INFO(opt << ": " << r.output);
      CHECK(r.code == 2);
    }
    // A repeated timestamp in the result (line 3 repeats line 2's).
    std::istringstream in(res_tum);
    std::string l1, l2, l3, rest;
    std::getline(in, l1);
    std::getline(in, l2);
    std::getline(in, l3);
    const std::string dup =
        l1 + "\n" + l2 + "\n" + l2.substr(0, l2.find(' ')) + l3.substr(l3.find(' ')) + "\n";
    const Run r = run("eval --result " + t.write("dup.txt", dup) + " --ground-truth " + gt);
    INFO(r.output);
    CHECK(r.code == 1);
    CHECK(r.output.find("dup.txt:3: timestamp") != std::string::npos);
    CHECK(r.output.find("does not increase") != std::string::npos);
    // --associate time with a ground truth that has no timestamps.
    const std::string k = t.write("gt_kitti.txt", gt_kitti);
    const Run nt = run("eval --result " + res + " --ground-truth " + k + " --associate time");
    INFO(nt.output);
    CHECK(nt.code == 1);
    CHECK(nt.output.find("gt_kitti.txt has no timestamps") != std::string::npos);
  }
}

TEST_CASE("correct finds an offset between the anchors' clock and the trajectory's",
          "[cli][time_offset]") {
  // 150 s of KITTI 02 as a TUM trajectory in M (the ground truth at a tenth of its unit), and
  // timestamped anchors every 5 s whose clock runs 0.7 s behind the camera's: each was taken
  // where the camera was 0.7 s after its timestamp (7–9 m further along the road).
  namespace io = geodrift::io;
  namespace lie = geodrift::lie;
  namespace correction = geodrift::correction;
  geodrift::test::TempDir t;
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const io::Trajectory gt = io::read_trajectory(dir + "/poses/02.txt");
  std::ifstream tf(dir + "/times/02.txt");
  std::vector<double> times;
  std::vector<Eigen::Vector3d> w;  // ground truth in W = (x, z, -y) of KITTI's camera frame
  std::string vo_tum, gt_tum;
  for (std::size_t k = 0; k < 1500; ++k) {
    double s;
    REQUIRE(static_cast<bool>(tf >> s));
    times.push_back(s);
    const lie::SE3d T_wc = gt.poses[k].T_cw.inverse();
    const Eigen::Vector3d c = T_wc.translation();
    w.emplace_back(c.x(), c.z(), -c.y());
    const Eigen::Quaterniond q = T_wc.rotation().quaternion();
    std::ostringstream v, g;
    v << std::fixed << std::setprecision(6) << s << std::setprecision(9) << ' ' << 0.1 * c.x()
      << ' ' << 0.1 * c.y() << ' ' << 0.1 * c.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z()
      << ' ' << q.w() << "\n";
    g << std::fixed << std::setprecision(6) << s << std::setprecision(9) << ' ' << w.back().x()
      << ' ' << w.back().y() << ' ' << w.back().z() << " 0 0 0 1\n";
    vo_tum += v.str();
    gt_tum += g.str();
  }
  std::ostringstream an;
  an << std::setprecision(12) << "timestamp,x,y,z,sigma_m\n";
  for (std::size_t k = 50; k < 1500; k += 50) {
    const Eigen::Vector3d p = correction::detail::centre_at(times, w, times[k] + 0.7);
    an << times[k] << ',' << p.x() << ',' << p.y() << ',' << p.z() << ",0.3\n";
  }
  const std::string traj = t.write("KeyFrameTrajectory.txt", vo_tum);
  const std::string gt_path = t.write("gt.txt", gt_tum);
  const std::string anchors = t.write("anchors.csv", an.str());
  const std::string base = "correct --origin 49.0,8.4,100 --trajectory " + traj + " --anchors " +
                           anchors + " --no-uncertainty --out ";
  const auto error_2d = [&](const std::string& out) {
    const Run e = run("eval --result " + t.file(out + "/trajectory_tum.txt") + " --ground-truth " +
                      gt_path + " --json");
    REQUIRE(e.code == 0);
    return mean_2d(e.output);
  };
  const Run plain = run(base + t.file("plain"));
  INFO(plain.output);
  REQUIRE(plain.code == 0);
  CHECK(plain.output.find("warning: " + anchors + ": the anchors fit the path best with +0.7") !=
        std::string::npos);
  CHECK(plain.output.find("--anchor-time-offset 0.70") != std::string::npos);
  const std::string report = geodrift::test::read_text(t.file("plain/report.json"));
  const std::string clock = report.substr(report.find("\"anchor_time_offset\""));
  CHECK(json_numbers(clock, "applied")[0] == 0.0);
  CHECK(json_numbers(clock, "estimate")[0] == Approx(0.7).margin(0.05));
  CHECK(json_numbers(clock, "sd")[0] < 0.05);
  CHECK(clock.find("\"significant\": true") < clock.find('}'));

  const Run given = run(base + t.file("given") + " --anchor-time-offset 0.7");
  const Run autom = run(base + t.file("auto") + " --anchor-time-offset auto");
  INFO(given.output << autom.output);
  REQUIRE(given.code == 0);
  REQUIRE(autom.code == 0);
  CHECK(given.output.find("warning") == std::string::npos);  // nothing left to warn about
  CHECK(autom.output.find("applied (--anchor-time-offset auto)") != std::string::npos);
  const std::string ra = geodrift::test::read_text(t.file("auto/report.json"));
  const std::string ca = ra.substr(ra.find("\"anchor_time_offset\""));
  CHECK(json_numbers(ca, "applied")[0] == Approx(0.7).margin(0.05));
  const double e_plain = error_2d("plain"), e_given = error_2d("given"), e_auto = error_2d("auto");
  INFO("mean 2D error: offset ignored " << e_plain << " m, given " << e_given << " m, auto "
                                        << e_auto << " m");
  CHECK(e_given < 0.5 * e_plain);
  CHECK(e_auto < 0.5 * e_plain);
  CHECK(std::abs(e_auto - e_given) < 0.1);
}

TEST_CASE("correct refuses a bad --anchor-time-offset with a message and no output",
          "[cli][time_offset]") {
  geodrift::test::TempDir t;
  const std::string traj = t.write("traj.txt", trajectory_text());
  const std::string by_frame = t.write("frames.csv", anchors_text({0, 10, 20, 30, 39}));
  const std::string base =
      "correct --origin 49.0,8.4,100 --trajectory " + traj + " --anchors " + by_frame;
  // Not a number.
  const Run bad = run(base + " --anchor-time-offset soon --out " + t.file("bad"));
  CHECK(bad.code != 0);
  CHECK(bad.output.find("--anchor-time-offset") != std::string::npos);
  CHECK_FALSE(fs::exists(t.file("bad")));
  // An offset for anchors that are all placed by their frame.
  const Run nf = run(base + " --anchor-time-offset 0.5 --out " + t.file("nf"));
  CHECK(nf.code != 0);
  CHECK(nf.output.find("no anchor of " + by_frame + " is placed by its timestamp") !=
        std::string::npos);
  CHECK_FALSE(fs::exists(t.file("nf")));
}

TEST_CASE("correct refuses files that do not belong together: clock, mirror, T_cw",
          "[cli][input_checks]") {
  // 150 s of KITTI 02 as a TUM trajectory in M (the ground truth at a tenth of its unit) and
  // anchors every 10 s from the ground truth in W = (x, z, -y) of KITTI's camera frame. Each
  // file parses and every anchor lies inside the trajectory; only together are they wrong.
  namespace io = geodrift::io;
  namespace lie = geodrift::lie;
  geodrift::test::TempDir t;
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const io::Trajectory gt = io::read_trajectory(dir + "/poses/02.txt");
  std::ifstream tf(dir + "/times/02.txt");
  // tum(f): the trajectory with pose T written as f(T_wc) and timestamps times `unit`.
  std::vector<double> times;
  for (std::size_t k = 0; k < 1500; ++k) {
    double s;
    REQUIRE(static_cast<bool>(tf >> s));
    times.push_back(s);
  }
  const auto tum = [&](double unit, const auto& f) {
    std::ostringstream os;
    os << std::setprecision(12);
    for (std::size_t k = 0; k < times.size(); ++k) {
      lie::SE3d T_wc = gt.poses[k].T_cw.inverse();
      T_wc = lie::SE3d(T_wc.rotation(), 0.1 * T_wc.translation());
      const lie::SE3d T = f(T_wc);
      const Eigen::Quaterniond q = T.rotation().quaternion();
      const Eigen::Vector3d c = T.translation();
      os << unit * times[k] << ' ' << c.x() << ' ' << c.y() << ' ' << c.z() << ' ' << q.x() << ' '
         << q.y() << ' ' << q.z() << ' ' << q.w() << "\n";
    }
    return os.str();
  };
  const auto as_is = [](const lie::SE3d& T_wc) { return T_wc; };
  const auto anchors = [&](bool swap_xy) {
    std::ostringstream os;
    os << std::setprecision(12) << "timestamp,x,y,z,sigma_m\n";
    for (std::size_t k = 50; k < times.size(); k += 100) {
      const Eigen::Vector3d c = gt.poses[k].T_cw.inverse().translation();
      const double x = c.x(), y = c.z();
      os << times[k] << ',' << (swap_xy ? y : x) << ',' << (swap_xy ? x : y) << ',' << -c.y()
         << ",0.3\n";
    }
    return os.str();
  };
  const std::string good = t.write("anchors.csv", anchors(false));
  const std::string traj = t.write("traj.txt", tum(1.0, as_is));
  const auto correct = [&](const std::string& trajectory, const std::string& anchor_file,
                           const std::string& out, const std::string& extra = "") {
    return run("correct --origin 49.0,8.4,100 --trajectory " + trajectory + " --anchors " +
               anchor_file + " --out " + t.file(out) + extra);
  };
  const Run ok = correct(traj, good, "ok");
  INFO(ok.output);
  REQUIRE(ok.code == 0);

  // Nanoseconds in the trajectory, seconds in the anchors (ORB-SLAM3's EuRoC-style output):
  // every anchor would land within the first 0.1 s.
  const Run ns = correct(t.write("traj_ns.txt", tum(1e9, as_is)), good, "ns");
  INFO(ns.output);
  CHECK(ns.code == 1);
  CHECK(ns.output.find(good + ":2: the anchors' timestamps span") != std::string::npos);
  CHECK(ns.output.find("look like seconds and the trajectory's like nanoseconds") !=
        std::string::npos);
  CHECK_FALSE(fs::exists(t.file("ns")));

  // x and y swapped: the anchors are the path's mirror image, which the pose graph fits by
  // turning the path over. Refused; accepted with --allow-upside-down, the cameras then upside
  // down in the output.
  const std::string swapped = t.write("swapped.csv", anchors(true));
  const Run mirror = correct(traj, swapped, "mirror");
  INFO(mirror.output);
  CHECK(mirror.code == 1);
  CHECK(mirror.output.find("fit the path only turned over") != std::string::npos);
  CHECK(mirror.output.find("the anchors of " + swapped) != std::string::npos);
  CHECK(mirror.output.find("latitude and longitude swapped") != std::string::npos);
  CHECK_FALSE(fs::exists(t.file("mirror")));
  const Run allowed = correct(traj, swapped, "allowed", " --allow-upside-down");
  INFO(allowed.output);
  CHECK(allowed.code == 0);

  // World-to-camera poses (T_cw) where camera-to-world are expected: the "centres" trace
  // another curve, which no drift bends onto the anchors. Here the screening's graph is rank
  // deficient (the first "centres" coincide), and the uncertainty's drift factor tells.
  const Run inverted = correct(
      t.write("traj_cw.txt", tum(1.0, [](const lie::SE3d& T_wc) { return T_wc.inverse(); })), good,
      "inverted");
  INFO(inverted.output);
  CHECK(inverted.code == 1);
  CHECK(inverted.output.find("does not have the anchors' shape") != std::string::npos);
  CHECK(inverted.output.find("the correction stretched it by") != std::string::npos);
  CHECK(inverted.output.find("World-to-camera poses where camera-to-world are expected") !=
        std::string::npos);
  CHECK_FALSE(fs::exists(t.file("inverted")));

  // Cameras in OpenGL's axes (y up, z backwards) are not a mirror: they move along -z. The
  // path is corrected, to the same positions as in OpenCV's axes.
  const Run gl = correct(
      t.write("traj_gl.txt", tum(1.0,
                                 [](const lie::SE3d& T_wc) {
                                   return T_wc *
                                          lie::SE3d(lie::SO3d::exp(Eigen::Vector3d(M_PI, 0, 0)),
                                                    Eigen::Vector3d::Zero());
                                 })),
      good, "gl");
  INFO(gl.output);
  REQUIRE(gl.code == 0);
  const io::Trajectory a = io::read_trajectory(t.file("ok/trajectory_tum.txt"));
  const io::Trajectory b = io::read_trajectory(t.file("gl/trajectory_tum.txt"));
  REQUIRE(a.poses.size() == b.poses.size());
  double worst = 0;
  for (std::size_t k = 0; k < a.poses.size(); ++k)
    worst = std::max(
        worst,
        (a.poses[k].T_cw.inverse().translation() - b.poses[k].T_cw.inverse().translation()).norm());
  INFO("largest distance between the OpenCV and OpenGL runs: " << worst << " m");
  CHECK(worst < 0.05);
}
