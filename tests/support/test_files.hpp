#pragma once

// Helpers shared by the tests (io, sim, ...): a temporary directory, file writing/reading, random
// poses and checks on error messages.

#include <unistd.h>

#include <Eigen/Geometry>
#include <atomic>
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"

namespace geodrift::test {

/// A fresh directory under the system temp dir, removed on destruction.
class TempDir {
 public:
  TempDir() {
    static std::atomic<int> counter{0};
    path_ =
        std::filesystem::temp_directory_path() / ("geodrift_io_test_" + std::to_string(::getpid()) +
                                                  "_" + std::to_string(counter.fetch_add(1)));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }
  /// Writes `text` to the file `name` in the directory and returns its path.
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream out(file(name), std::ios::binary);
    out << text;
    REQUIRE(out.good());
    return file(name);
  }
  const std::filesystem::path& path() const { return path_; }
  /// Number of entries in the directory (to detect leftover temporary files).
  int num_entries() const {
    int n = 0;
    for (const auto& e : std::filesystem::directory_iterator(path_)) (void)e, ++n;
    return n;
  }

 private:
  std::filesystem::path path_;
};

inline void write_text(const std::string& path, const std::string& content) {
  std::ofstream out(path, std::ios::binary);
  out << content;
  REQUIRE(out.good());
}

inline std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

inline lie::SE3d random_pose(std::mt19937& rng, double translation_scale = 100.0) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> u(-translation_scale, translation_scale);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return lie::SE3d(lie::SO3d(q), Eigen::Vector3d(u(rng), u(rng), u(rng)));
}

inline double pose_distance(const lie::SE3d& a, const lie::SE3d& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff();
}

/// Runs f; requires geodrift::InvalidArgument whose message names "<path>:<line>:" and contains
/// `fragment`.
template <class F>
void require_parse_error(const F& f, const std::string& path, int line,
                         const std::string& fragment) {
  bool thrown = false;
  try {
    f();
  } catch (const geodrift::InvalidArgument& e) {
    thrown = true;
    const std::string msg = e.what();
    INFO("message: " << msg);
    CHECK(msg.find(path + ":" + std::to_string(line) + ":") != std::string::npos);
    CHECK(msg.find(fragment) != std::string::npos);
  } catch (const std::exception& e) {
    FAIL("threw a non-InvalidArgument exception: " << e.what());
  }
  INFO("expected InvalidArgument at " << path << ":" << line << " containing '" << fragment << "'");
  CHECK(thrown);
}

/// Runs f; requires geodrift::Error (not InvalidArgument) whose message names `path`.
template <class F>
void require_io_error(const F& f, const std::string& path) {
  bool thrown = false;
  try {
    f();
  } catch (const geodrift::InvalidArgument& e) {
    FAIL("expected an I/O Error, got InvalidArgument: " << e.what());
  } catch (const geodrift::Error& e) {
    thrown = true;
    INFO("message: " << e.what());
    CHECK(std::string(e.what()).find(path) != std::string::npos);
  }
  CHECK(thrown);
}

}  // namespace geodrift::test
