#pragma once

// Running the built `geodrift` executable from a test: its exit code and output, and the check
// that a failed run left nothing behind.

#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <string>

namespace geodrift::test {

struct CliRun {
  int code = -1;       ///< exit status; -1 when the process did not exit normally
  std::string output;  ///< stdout and stderr, interleaved
};

/// Runs `'exe' args 2>&1` through the shell (args are passed as written, so quote paths with
/// spaces yourself).
inline CliRun run_cli(const std::string& exe, const std::string& args) {
  const std::string cmd = "'" + exe + "' " + args + " 2>&1";
  CliRun r;
  FILE* p = ::popen(cmd.c_str(), "r");
  REQUIRE(p != nullptr);
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// True when `dir` holds neither `out_name` nor a geodrift staging folder ("*geodrift-tmp*"):
/// what a failed command must leave.
inline bool no_outputs(const std::filesystem::path& dir, const std::string& out_name) {
  if (std::filesystem::exists(dir / out_name)) return false;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().find("geodrift-tmp") != std::string::npos) return false;
  return true;
}

}  // namespace geodrift::test
