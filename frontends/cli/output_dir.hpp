#pragma once
/// @file
/// Atomic outputs for the subcommands: every `--out` folder (or file) is written into a hidden
/// temporary folder beside it and renamed into place only when complete, so `--out` is at any
/// moment either absent, the user's previous content, or the complete new output.
///
/// The pieces, all in this file:
/// - AtomicOutputDir: the staging folder `.<out-name>.geodrift-tmp-<pid>` in --out's parent
///   (same filesystem, so rename(2) is atomic), commit() moving it into place, and the
///   removal of stale staging folders that killed runs (SIGKILL, power loss) left behind.
/// - install_signal_cleanup(): SIGINT/SIGTERM remove the staging folders and exit 130/143.
/// - describe_output_error(): the error message of a failed write, naming --out's path (not
///   the staging folder's) and the OS reason.
///
/// Not covered: durability across power loss (no fsync), and concurrent geodrift runs on the
/// same --out (the last commit wins; neither leaves a partial folder).

#include <fcntl.h>  // AT_FDCWD
#include <signal.h>
#include <stdio.h>  // renameat2, RENAME_EXCHANGE (glibc >= 2.28 with _GNU_SOURCE)
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <geodrift/error.hpp>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace geodrift::cli {

namespace detail {

/// Process-wide state shared by the outputs and the signal thread. Allocated once and never
/// freed: the signal thread may still use it while static destructors run at exit.
struct OutputRegistry {
  std::mutex mutex;
  /// Folders removed when SIGINT/SIGTERM arrives: staging folders, and after a --force swap
  /// the previous output until it is deleted.
  std::vector<std::filesystem::path> doomed;
  /// The last output that failed: its staging folder, --out, and errno when the failure
  /// unwound through it (write errors of the io writers carry no OS reason, see
  /// describe_output_error()).
  std::string failed_stage, failed_out;
  int failed_errno = 0;
};

inline OutputRegistry& output_registry() {
  static OutputRegistry* r = new OutputRegistry;  // leaked on purpose (see above)
  return *r;
}

inline void unregister_doomed(const std::filesystem::path& p) {
  auto& d = output_registry().doomed;
  for (auto it = d.begin(); it != d.end(); ++it)
    if (*it == p) {
      d.erase(it);
      return;
    }
}

/// True when no process has id `pid` (kill(pid, 0) fails with ESRCH). A live process of
/// another user (EPERM) counts as alive: when unsure, a staging folder is kept.
inline bool process_is_dead(long pid) {
  if (pid <= 0 || pid != static_cast<long>(static_cast<pid_t>(pid))) return false;
  return ::kill(static_cast<pid_t>(pid), 0) == -1 && errno == ESRCH;
}

/// Copies `from` to `to` as hard links (directories recursively, symlinks as symlinks), or as
/// plain copies where the filesystem refuses links. Used to carry the user's own files of an
/// existing --out into the new output before the swap.
inline void link_or_copy(const std::filesystem::path& from, const std::filesystem::path& to) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::copy(from, to,
           fs::copy_options::recursive | fs::copy_options::copy_symlinks |
               fs::copy_options::create_hard_links,
           ec);
  if (!ec) return;
  fs::remove_all(to, ec);
  fs::copy(from, to, fs::copy_options::recursive | fs::copy_options::copy_symlinks, ec);
  if (ec)
    throw Error("--force: cannot carry '" + from.string() +
                "' over into the new output: " + ec.message());
}

}  // namespace detail

namespace detail {

/// Write end of the pipe that the signal handler writes the signal number to.
inline int& signal_pipe_write_end() {
  static int fd = -1;
  return fd;
}

/// The SIGINT/SIGTERM handler: only write(2), which is async-signal-safe.
inline void on_exit_signal(int sig) {
  const int saved = errno;
  const unsigned char b = static_cast<unsigned char>(sig);
  [[maybe_unused]] const ssize_t n = ::write(signal_pipe_write_end(), &b, 1);
  errno = saved;
}

}  // namespace detail

/// Makes SIGINT and SIGTERM remove every registered staging folder, then exit with 128 +
/// signal (130, 143). Call first thing in main().
///
/// Design (self-pipe): the handler only writes the signal number into a pipe, which is
/// async-signal-safe, whichever thread runs it (libraries start threads before main(), so
/// blocking the signals in main's thread alone would not keep them off other threads). A
/// dedicated thread reads the pipe; it is not a signal handler, so it may lock the registry's
/// mutex and call std::filesystem, which a handler could not. The mutex also orders it with
/// commit(): the thread sees a staging folder either before its rename into place (and
/// removes it) or after (and removes only the previous output). A signal that is ignored at
/// start (SIG_IGN, as for background jobs of a non-interactive shell) stays ignored.
inline void install_signal_cleanup() {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0) return;  // default actions stay
  detail::signal_pipe_write_end() = fds[1];
  std::thread([fd = fds[0]] {
    unsigned char b = 0;
    while (::read(fd, &b, 1) != 1) {
    }
    const int sig = b;
    auto& reg = detail::output_registry();
    {
      const std::lock_guard<std::mutex> lock(reg.mutex);
      for (const auto& p : reg.doomed) {
        // The writing threads keep running until _exit below and may be creating or deleting
        // entries by path (commit() may be deleting the previous output), so first move the
        // folder to a name only this thread knows, then remove it there. Should a writer have
        // recreated the path meanwhile, remove that too; anything surviving is a stale folder
        // of a dead process, which the next run removes.
        std::error_code ec;
        std::filesystem::path del = p;
        del += "-del";
        std::filesystem::rename(p, del, ec);
        std::filesystem::remove_all(ec ? p : del, ec);
        for (int k = 0; k < 5 && std::filesystem::exists(p, ec); ++k)
          std::filesystem::remove_all(p, ec);
      }
      reg.doomed.clear();
    }
    ::_exit(128 + sig);
  }).detach();
  for (int sig : {SIGINT, SIGTERM}) {
    struct sigaction old {};
    if (::sigaction(sig, nullptr, &old) == 0 && old.sa_handler == SIG_IGN) continue;
    struct sigaction sa {};
    sa.sa_handler = detail::on_exit_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    ::sigaction(sig, &sa, nullptr);
  }
}

/// The output folder of a subcommand, written atomically:
/// - everything is written into the staging folder `.<out-name>.geodrift-tmp-<pid>` beside
///   --out (path());
/// - commit() renames it to --out. With `force` over an existing folder the two are swapped
///   in one step (renameat2 RENAME_EXCHANGE; where the filesystem refuses it, --out is first
///   renamed aside to `...-old`, which the next run restores if killed in between) and the
///   previous output is then deleted, so --out is never half-replaced. Files of the previous
///   --out that the new output does not have (the user's own) are carried over;
/// - without commit() (an exception), the staging folder is removed and --out is left as it
///   was; on SIGINT/SIGTERM see install_signal_cleanup(); a killed run (SIGKILL) leaves only
///   the hidden staging folder, which the next run on the same --out removes once the
///   process that made it is gone.
///
/// With Kind::kFile, --out is one file: it is written at path(out-name) inside the staging
/// folder and commit() renames it over --out (an atomic replacement).
class AtomicOutputDir {
 public:
  enum class Kind { kDirectory, kFile };

  /// Checks --out, removes stale staging folders of dead runs and creates the staging folder.
  /// @throws Error naming the path and the OS reason: --out a file (kDirectory) or a folder
  ///         (kFile), an existing --out without `force` (a non-empty folder, or a file), a
  ///         parent that is missing or not a folder, or a staging folder that cannot be made.
  AtomicOutputDir(const std::string& out, bool force, Kind kind = Kind::kDirectory)
      : kind_(kind), force_(force) {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (out.empty()) throw Error("--out is empty");
    fs::path p(out);
    if (p.filename().empty()) p = p.parent_path();  // "dir/" -> "dir"
    // A symbolic link is followed: the folder (or file) it names is replaced, the link stays.
    if (fs::is_symlink(fs::symlink_status(p, ec))) {
      const fs::path target = fs::canonical(p, ec);
      if (!ec) p = target;
    }
    out_ = p;
    const fs::path parent = p.has_parent_path() ? p.parent_path() : fs::path(".");
    if (!fs::is_directory(parent, ec)) {
      if (!ec)
        ec = std::make_error_code(fs::exists(parent) ? std::errc::not_a_directory
                                                     : std::errc::no_such_file_or_directory);
      throw Error("--out '" + out + "': cannot use the parent folder '" + parent.string() +
                  "': " + ec.message());
    }
    const fs::file_status st = fs::symlink_status(p, ec);
    if (fs::exists(st)) {
      const bool dir = fs::is_directory(fs::status(p, ec));
      if (kind == Kind::kDirectory && !dir)
        throw Error("--out '" + out +
                    "' exists and is not a directory (refusing to replace a file)");
      if (kind == Kind::kFile && dir) throw Error("--out '" + out + "' is a directory");
      if (kind == Kind::kFile && !force)
        throw Error("--out '" + out + "' exists (refusing to overwrite; use --force)");
      if (kind == Kind::kDirectory && !fs::is_empty(p, ec) && !force)
        throw Error("--out '" + out +
                    "' exists and is not empty (refusing to overwrite; use --force to replace "
                    "the files geodrift writes there)");
    }
    prefix_ = "." + p.filename().string() + ".geodrift-tmp-";
    remove_stale(parent);
    const std::string pid = std::to_string(::getpid());
    stage_ = parent / (prefix_ + pid);
    aside_ = parent / (prefix_ + pid + "-old");
    auto& reg = detail::output_registry();
    const std::lock_guard<std::mutex> lock(reg.mutex);
    fs::remove_all(stage_, ec);  // left by an earlier process with our pid (stale)
    if (!fs::create_directory(stage_, ec) || ec) {
      if (!ec) ec = std::make_error_code(std::errc::file_exists);
      throw Error("--out '" + out + "': cannot create the temporary folder '" + stage_.string() +
                  "': " + ec.message());
    }
    reg.doomed.push_back(stage_);
  }
  AtomicOutputDir(const AtomicOutputDir&) = delete;
  AtomicOutputDir& operator=(const AtomicOutputDir&) = delete;

  /// Removes the staging folder unless committed. When an exception is unwinding, records
  /// errno and the paths for describe_output_error().
  ~AtomicOutputDir() {
    const int err = errno;  // first: the failed write's errno, before anything resets it
    if (committed_) return;
    auto& reg = detail::output_registry();
    std::error_code ec;
    const std::lock_guard<std::mutex> lock(reg.mutex);
    if (std::uncaught_exceptions() > 0) {
      reg.failed_stage = stage_.string();
      reg.failed_out = out_.string();
      reg.failed_errno = err;
    }
    std::filesystem::remove_all(stage_, ec);  // our own staging folder only
    detail::unregister_doomed(stage_);
  }

  /// Path of `name` inside the staging folder (for Kind::kFile, path(out().filename())).
  std::string path(const std::string& name) const { return (stage_ / name).string(); }
  std::string staging_dir() const { return stage_.string(); }
  const std::filesystem::path& out() const { return out_; }

  /// Moves the output into place (see the class comment).
  /// @throws Error naming --out and the OS reason; --out is then left as it was.
  void commit() {
    namespace fs = std::filesystem;
    std::error_code ec;
    auto& reg = detail::output_registry();
    if (kind_ == Kind::kFile) {
      const fs::path file = stage_ / out_.filename();
      {
        const std::lock_guard<std::mutex> lock(reg.mutex);
        fs::rename(file, out_, ec);  // atomically replaces an existing file
      }
      if (ec)
        throw Error("cannot move the output into place at '" + out_.string() +
                    "': " + ec.message());
      finish(stage_);
      return;
    }
    if (!force_ || !fs::exists(fs::symlink_status(out_, ec))) {
      const std::lock_guard<std::mutex> lock(reg.mutex);
      fs::rename(stage_, out_, ec);  // fails if --out appeared meanwhile and is not empty
      if (ec)
        throw Error("cannot move the output into place at '" + out_.string() +
                    "': " + ec.message());
      committed_ = true;
      detail::unregister_doomed(stage_);
      return;
    }
    // --force over an existing folder. First carry the user's own entries over, so the swap
    // below is the only moment --out changes.
    for (const auto& e : fs::directory_iterator(out_, ec)) {
      const fs::path dst = stage_ / e.path().filename();
      if (!fs::exists(fs::symlink_status(dst, ec))) detail::link_or_copy(e.path(), dst);
    }
    fs::permissions(stage_, fs::status(out_, ec).permissions(), ec);
    fs::path old;  // where the previous output is after the swap
    {
      const std::lock_guard<std::mutex> lock(reg.mutex);
      if (::renameat2(AT_FDCWD, stage_.c_str(), AT_FDCWD, out_.c_str(), RENAME_EXCHANGE) == 0) {
        old = stage_;  // still registered: removed on a signal
      } else if (errno == EINVAL || errno == ENOSYS || errno == ENOTSUP) {
        // The filesystem cannot exchange: rename the previous output aside first. The next
        // run puts `...-old` back if this process dies before the second rename.
        fs::rename(out_, aside_, ec);
        if (ec)
          throw Error("cannot replace '" + out_.string() +
                      "': renaming it aside failed: " + ec.message());
        fs::rename(stage_, out_, ec);
        if (ec) {
          std::error_code ec2;
          fs::rename(aside_, out_, ec2);
          throw Error("cannot move the output into place at '" + out_.string() +
                      "': " + ec.message());
        }
        detail::unregister_doomed(stage_);
        reg.doomed.push_back(aside_);
        old = aside_;
      } else {
        throw Error("cannot replace '" + out_.string() + "': " + std::strerror(errno));
      }
      committed_ = true;
    }
    // Entries created in the previous output after the carry-over above: move them over too.
    for (const auto& e : fs::directory_iterator(old, ec)) {
      const fs::path dst = out_ / e.path().filename();
      std::error_code ec2;
      if (!fs::exists(fs::symlink_status(dst, ec2))) fs::rename(e.path(), dst, ec2);
    }
    finish(old);
  }

 private:
  /// Removes `dir` (the previous output or the emptied staging folder) and unregisters it.
  void finish(const std::filesystem::path& dir) {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
    auto& reg = detail::output_registry();
    const std::lock_guard<std::mutex> lock(reg.mutex);
    detail::unregister_doomed(dir);
    committed_ = true;
  }

  /// Removes staging folders of this --out whose process is gone; a `...-old` folder (the
  /// previous output renamed aside) is put back as --out when --out is missing.
  void remove_stale(const std::filesystem::path& parent) const {
    namespace fs = std::filesystem;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(parent, ec)) {
      const std::string name = e.path().filename().string();
      if (name.compare(0, prefix_.size(), prefix_) != 0) continue;
      const std::string rest = name.substr(prefix_.size());
      std::size_t digits = 0;
      while (digits < rest.size() && rest[digits] >= '0' && rest[digits] <= '9') ++digits;
      if (digits == 0 || digits > 9) continue;
      const long pid = std::stol(rest.substr(0, digits));
      if (pid != static_cast<long>(::getpid()) && !detail::process_is_dead(pid)) continue;
      std::error_code ec2;
      if (rest.substr(digits) == "-old" && !fs::exists(fs::symlink_status(out_, ec2))) {
        fs::rename(e.path(), out_, ec2);
        if (!ec2) continue;
      }
      fs::remove_all(e.path(), ec2);
    }
  }

  Kind kind_;
  bool force_;
  std::filesystem::path out_, stage_, aside_;
  std::string prefix_;
  bool committed_ = false;
};

/// Closes `f` (flushing it) and checks that everything reached the file.
/// @throws Error naming `path` and the OS reason (e.g. "No space left on device").
inline void close_checked(std::ofstream& f, const std::string& path) {
  errno = 0;
  f.close();
  if (f.fail())
    throw Error("cannot write '" + path +
                "': " + (errno != 0 ? std::strerror(errno) : "I/O error"));
}

/// The message for an exception that ended a subcommand. Paths inside the staging folder
/// become the --out paths they stand for, and a write error without an OS reason (the io
/// writers report an ofstream failure as "iostream error") gets the errno recorded when the
/// failure unwound through the AtomicOutputDir, e.g. "No space left on device" or "File too
/// large". That errno is the failed write's: between the write and the destructor only the
/// removal of the writer's temporary file runs, which does not set errno when it succeeds.
inline std::string describe_output_error(const std::exception& e) {
  std::string msg = e.what();
  auto& reg = detail::output_registry();
  const std::lock_guard<std::mutex> lock(reg.mutex);
  if (reg.failed_stage.empty()) return msg;
  bool about_output = false;
  for (std::size_t p = msg.find(reg.failed_stage); p != std::string::npos;
       p = msg.find(reg.failed_stage, p + reg.failed_out.size())) {
    msg.replace(p, reg.failed_stage.size(), reg.failed_out);
    about_output = true;
  }
  if (about_output && msg.find("iostream error") != std::string::npos && reg.failed_errno != 0)
    msg += std::string(" (") + std::strerror(reg.failed_errno) + ")";
  return msg;
}

}  // namespace geodrift::cli
