#pragma once

// Running the built `geodrift` executable from a test: its exit code and output, and the check
// that a failed run left nothing behind.

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

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

/// Starts `exe args...` without a shell (so signals reach geodrift itself), stdout and stderr
/// to `log`, and returns its pid. `fsize_limit_bytes` > 0 sets RLIMIT_FSIZE in the child with
/// SIGXFSZ ignored, so a write beyond it fails with EFBIG ("disk full" without a full disk).
inline pid_t spawn_cli(const std::string& exe, const std::vector<std::string>& args,
                       const std::string& log, long fsize_limit_bytes = 0) {
  std::vector<std::string> all{exe};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  REQUIRE(pid >= 0);
  if (pid == 0) {  // child: only async-signal-safe calls until exec
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      ::dup2(fd, 1);
      ::dup2(fd, 2);
    }
    if (fsize_limit_bytes > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      struct rlimit rl;
      rl.rlim_cur = rl.rlim_max = static_cast<rlim_t>(fsize_limit_bytes);
      ::setrlimit(RLIMIT_FSIZE, &rl);
    }
    ::execv(exe.c_str(), argv.data());
    ::_exit(127);
  }
  return pid;
}

/// Waits for `pid`; returns its exit code, or -signal when a signal ended it.
inline int wait_cli(pid_t pid) {
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
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
