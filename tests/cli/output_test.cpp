// Atomic outputs of the geodrift command: a run killed at random moments (SIGINT, SIGTERM,
// SIGKILL) leaves --out absent, as it was, or complete; write failures are clear errors that
// lose nothing.
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "support/cli_run.hpp"
#include "support/test_files.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kData = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";

/// Every regular file under `dir` (relative path -> content); empty when `dir` is absent.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> m;
  if (!fs::exists(dir)) return m;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::ifstream in(e.path(), std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    m[fs::relative(e.path(), dir).string()] = s.str();
  }
  return m;
}

/// Names in `dir` that are geodrift staging folders.
std::vector<std::string> staging_folders(const fs::path& dir) {
  std::vector<std::string> v;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find("geodrift-tmp") != std::string::npos)
      v.push_back(e.path().filename().string());
  return v;
}

std::vector<std::string> simulate_args(int seed, const std::string& out, bool force,
                                       const std::string& frames = "") {
  std::vector<std::string> a{"simulate",   "--sequence", "02",     "--interval",         "100",
                             "--data-dir", kData,        "--seed", std::to_string(seed), "--out",
                             out};
  if (force) a.push_back("--force");
  if (!frames.empty()) a.insert(a.end(), {"--frames", frames});
  return a;
}

/// Runs geodrift to the end; returns its exit code and puts its output in *log_text.
int run_to_end(const geodrift::test::TempDir& t, const std::vector<std::string>& args,
               std::string* log_text = nullptr, long fsize_limit = 0) {
  const std::string log = t.file("log.txt");
  const int code =
      geodrift::test::wait_cli(geodrift::test::spawn_cli(GEODRIFT_CLI_EXE, args, log, fsize_limit));
  if (log_text) {
    std::ifstream in(log);
    std::ostringstream s;
    s << in.rdbuf();
    *log_text = s.str();
  }
  return code;
}

}  // namespace

TEST_CASE("simulate killed at random moments leaves --out absent, as it was, or complete",
          "[cli]") {
  geodrift::test::TempDir t;
  // References: complete outputs of seed 3 (the "old" output) and seed 4 (the "new" one).
  const auto t0 = std::chrono::steady_clock::now();
  REQUIRE(run_to_end(t, simulate_args(4, t.file("ref4"), false)) == 0);
  const double full_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  REQUIRE(run_to_end(t, simulate_args(3, t.file("ref3"), false)) == 0);
  auto ref3 = snapshot(t.file("ref3")), ref4 = snapshot(t.file("ref4"));
  REQUIRE(ref3.size() == 7);
  REQUIRE(ref3 != ref4);
  INFO("a full run takes " << full_s << " s");

  std::mt19937 rng(25);
  std::uniform_real_distribution<double> when(0.0, 1.1 * full_s);
  const int kSignals[] = {SIGINT, SIGTERM, SIGKILL};
  int finished = 0, interrupted = 0, killed_with_leftover = 0;
  const auto kill_at_random = [&](const std::vector<std::string>& args, int i) {
    const int sig = kSignals[i % 3];
    const double delay = when(rng);
    // Staging folders an earlier SIGKILL left (removed only by a run that gets far enough).
    const auto before = staging_folders(t.path());
    const pid_t pid = geodrift::test::spawn_cli(GEODRIFT_CLI_EXE, args, t.file("log.txt"));
    std::this_thread::sleep_for(std::chrono::duration<double>(delay));
    ::kill(pid, sig);
    const int code = geodrift::test::wait_cli(pid);
    INFO("run " << i << ": signal " << sig << " after " << delay << " s, exit " << code);
    std::vector<std::string> left;  // this run's own staging folder, if it survived
    for (const auto& f : staging_folders(t.path()))
      if (std::find(before.begin(), before.end(), f) == before.end()) left.push_back(f);
    if (code == 0) {
      ++finished;
    } else if (sig == SIGKILL) {
      CHECK(code == -SIGKILL);
      killed_with_leftover += left.empty() ? 0 : 1;
    } else {
      // 128 + signal from geodrift's cleanup; -signal when it landed before main() ran.
      CHECK((code == 128 + sig || code == -sig));
      interrupted += code == 128 + sig ? 1 : 0;
      CHECK(left.empty());  // SIGINT/SIGTERM remove the staging folder
    }
  };

  SECTION("a fresh --out is absent or complete") {
    // 20 runs, more (up to 60) until 5 kills landed mid-run: on a loaded machine many land
    // before main() installs its handlers, and the check below needs some that did not.
    for (int i = 0; i < 20 || (interrupted + killed_with_leftover < 5 && i < 60); ++i) {
      fs::remove_all(t.file("out"));
      kill_at_random(simulate_args(4, t.file("out"), false), i);
      const auto got = snapshot(t.file("out"));
      CHECK((got.empty() || got == ref4));
    }
  }
  SECTION("--force over a complete --out leaves the old or the new output") {
    // The user's own file in --out must survive the replacement.
    ref3["mine.txt"] = ref4["mine.txt"] = "precious\n";
    const auto reset = [&] {
      fs::remove_all(t.file("out"));
      fs::copy(t.file("ref3"), t.file("out"), fs::copy_options::recursive);
      t.write("out/mine.txt", "precious\n");
    };
    reset();
    for (int i = 0; i < 20 || (interrupted + killed_with_leftover < 5 && i < 60); ++i) {
      kill_at_random(simulate_args(4, t.file("out"), true), i);
      const auto got = snapshot(t.file("out"));
      const bool old_one = got == ref3, new_one = got == ref4;
      CHECK((old_one || new_one));
      if (!old_one) reset();
    }
  }
  WARN("kill test: " << finished << " runs finished first, " << interrupted
                     << " SIGINT/SIGTERM cleanups, " << killed_with_leftover
                     << " SIGKILLs left a staging folder");
  CHECK(interrupted + killed_with_leftover >= 5);  // kills did land mid-run
  // A later run on the same --out removes the staging folders SIGKILL left behind.
  REQUIRE(run_to_end(t, simulate_args(4, t.file("out"), true, "0:300")) == 0);
  CHECK(staging_folders(t.path()).empty());
}

TEST_CASE("an unwritable --out or a failed write is a clear error that loses nothing", "[cli]") {
  geodrift::test::TempDir t;
  std::string log;
  SECTION("--out under a regular file (ENOTDIR, also as root)") {
    t.write("file", "x\n");
    CHECK(run_to_end(t, simulate_args(3, t.file("file/out"), false, "0:300"), &log) == 1);
    INFO(log);
    CHECK(log.find(t.file("file")) != std::string::npos);
    CHECK(log.find("Not a directory") != std::string::npos);
    CHECK(staging_folders(t.path()).empty());
  }
  SECTION("a write beyond RLIMIT_FSIZE (EFBIG, as a full disk)") {
    CHECK(run_to_end(t, simulate_args(3, t.file("out"), false, "0:1000"), &log, 20000) == 1);
    INFO(log);
    CHECK(log.find("File too large") != std::string::npos);
    CHECK(log.find(t.file("out") + "/") != std::string::npos);  // --out's path, not staging
    CHECK(log.find("geodrift-tmp") == std::string::npos);
    CHECK(geodrift::test::no_outputs(t.path(), "out"));
  }
  SECTION("the same with --force keeps the previous output intact") {
    REQUIRE(run_to_end(t, simulate_args(3, t.file("out"), false, "0:300")) == 0);
    const auto before = snapshot(t.file("out"));
    CHECK(run_to_end(t, simulate_args(4, t.file("out"), true, "0:1000"), &log, 20000) == 1);
    INFO(log);
    CHECK(log.find("File too large") != std::string::npos);
    CHECK(snapshot(t.file("out")) == before);
    CHECK(staging_folders(t.path()).empty());
  }
}

namespace {

/// `files` with the wall-clock fields blanked, the only parts of geodrift's outputs that may
/// differ between runs on the same inputs (docs/building.md, "Atomic outputs and
/// determinism"): in report.json every number of a key containing "seconds" and the
/// command line (it names --out and --threads); in RESULTS.md the "Runtime:" and "Correction
/// time per seed" lines and the command line.
std::map<std::string, std::string> without_timings(std::map<std::string, std::string> files) {
  const std::regex seconds(R"(("[a-z_]*seconds[a-z_]*": )(-?[0-9][0-9.eE+-]*|null|nan))");
  const std::regex command(R"("command_line": "[^"\n]*")");
  const std::regex timing_lines(
      R"((^|\n)(Runtime:|Correction time per seed|    geodrift experiment)[^\n]*)");
  for (auto& [name, text] : files) {
    if (name.find("report.json") != std::string::npos) {
      text = std::regex_replace(text, seconds, "$1T");
      text = std::regex_replace(text, command, "\"command_line\": C");
    }
    if (name == "RESULTS.md") text = std::regex_replace(text, timing_lines, "$1T");
  }
  return files;
}

}  // namespace

TEST_CASE("simulate, correct and experiment give identical outputs on identical inputs", "[cli]") {
  geodrift::test::TempDir t;
  const auto run_ok = [&](const std::vector<std::string>& args) {
    std::string log;
    const int code = run_to_end(t, args, &log);
    INFO(log);
    REQUIRE(code == 0);
  };
  // simulate has no --threads: two runs, byte-identical (no timings in its files).
  run_ok(simulate_args(3, t.file("sim"), false, "0:1000"));
  run_ok(simulate_args(3, t.file("sim2"), false, "0:1000"));
  const auto sim = snapshot(t.file("sim"));
  REQUIRE(sim.size() == 7);
  CHECK(sim == snapshot(t.file("sim2")));

  // correct has no --threads: two runs with the same command line (the second after the
  // first's output is moved away), identical but for report.json's timings.
  const std::vector<std::string> correct{"correct",
                                         "--trajectory",
                                         t.file("sim/trajectory_kitti.txt"),
                                         "--map",
                                         t.file("sim/colmap"),
                                         "--anchors",
                                         t.file("sim/anchors.csv"),
                                         "--out",
                                         t.file("corr")};
  run_ok(correct);
  fs::rename(t.file("corr"), t.file("corr1"));
  run_ok(correct);
  const auto c1 = snapshot(t.file("corr1")), c2 = snapshot(t.file("corr"));
  REQUIRE(c1.count("report.json"));
  CHECK(without_timings(c1) == without_timings(c2));
  for (const auto& [name, text] : c1)
    if (name != "report.json") CHECK(text == c2.at(name));

  // experiment: --threads 1 and 2 (seeds in parallel) give the same tables and figures.
  const auto experiment = [&](const std::string& threads, const std::string& out) {
    run_ok({"experiment", "--sequences", "02", "--intervals", "300", "--seeds", "1,2", "--methods",
            "init,ours", "--data-dir", kData, "--threads", threads, "--out", t.file(out)});
    return snapshot(t.file(out));
  };
  const auto e1 = experiment("1", "exp1"), e2 = experiment("2", "exp2");
  REQUIRE(e1.count("RESULTS.md"));
  CHECK(without_timings(e1) == without_timings(e2));
  // The correction-time line ends its paragraph even when --methods leaves out the last method;
  // the local scale line (Ours has a pose graph) follows it as its own paragraph.
  const std::string& md = e1.at("RESULTS.md");
  CHECK(md.find(" (by interval)\n\nLocal scale SD used by the pose graph") != std::string::npos);
  CHECK(md.find("by interval: 300: ") != std::string::npos);
  CHECK(md.find("\n\nSimulated drift") != std::string::npos);
}
