#pragma once

/// @file
/// Reader for "Bundle Adjustment in the Large" problem files (problem-*.txt, Agarwal et al.
/// 2010, https://grail.cs.washington.edu/projects/bal/), and the BAL camera model.
///
/// File layout (whitespace separated; line breaks only matter for error messages):
///   <num_cameras> <num_points> <num_observations>
///   <camera_index> <point_index> <x> <y>           (num_observations lines)
///   <9 camera parameters>                          (per camera: angle-axis w (3), t (3), f, k1,
///   k2) <3 point coordinates>                          (per point)
///
/// BAL camera model (world -> pixel), as published:
///   P = R(w)·X + t            R(w) = exp([w]x), world -> camera
///   p = −P.xy / P.z           the camera looks down −z (x right, y UP)
///   r = 1 + k1‖p‖² + k2‖p‖⁴
///   pixel = f·r·p             origin at the image centre, y up
/// The reader returns the raw file values unchanged (BalProblem). For geodrift's camera
/// convention (DESIGN.md: x right, y down, z forward, T_cw) use BalCamera::R_cw_opencv() /
/// t_cw_opencv(): the flip F = diag(1, −1, −1) gives R_cv = F·R, t_cv = F·t, and the BAL pixel
/// (u, v) becomes (u, −v) around a principal point at 0. Radial distortion is not part of
/// geodrift's pinhole model: either keep it in a BAL-specific residual (bal_project() is the
/// exact model) or remove it from the observations with undistort_bal_pixel(), which inverts
/// the radial polynomial exactly (Newton) at fixed intrinsics; the pinhole cost on undistorted
/// pixels is then a re-weighting of the BAL cost by the local distortion scale (≈ 1 for the
/// small k1, k2 of the real data sets).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::io {

/// One BAL camera: 9 numbers, in file order.
struct BalCamera {
  Eigen::Vector3d angle_axis = Eigen::Vector3d::Zero();  ///< w: R = exp([w]x), world -> camera
  Eigen::Vector3d t = Eigen::Vector3d::Zero();           ///< P = R·X + t
  double f = 1.0;                                        ///< focal length [px]
  double k1 = 0.0;                                       ///< radial distortion, ‖p‖² term
  double k2 = 0.0;                                       ///< radial distortion, ‖p‖⁴ term

  /// R(w), BAL's world -> camera rotation (camera looking down −z).
  Eigen::Matrix3d R_bal() const {
    const double theta = angle_axis.norm();
    if (theta < 1e-300) return Eigen::Matrix3d::Identity();
    return Eigen::AngleAxisd(theta, angle_axis / theta).toRotationMatrix();
  }
  /// World -> camera rotation in geodrift's camera frame (x right, y down, z forward).
  Eigen::Matrix3d R_cw_opencv() const {
    return Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal() * R_bal();
  }
  /// World -> camera translation in geodrift's camera frame.
  Eigen::Vector3d t_cw_opencv() const { return Eigen::Vector3d(t.x(), -t.y(), -t.z()); }
};

/// One observation line: point `point` seen by camera `camera` at BAL pixel (x, y) (origin at
/// the image centre, y up).
struct BalObservation {
  int camera = 0;
  int point = 0;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
};

/// A BAL problem, raw file values.
struct BalProblem {
  std::vector<BalCamera> cameras;
  std::vector<Eigen::Vector3d> points;  ///< world coordinates
  std::vector<BalObservation> observations;
};

/// BAL's projection of world point X by camera c (the exact published model, with distortion).
/// Returns false (and leaves *pixel untouched) if the point is not in front of the camera
/// (P.z >= 0 in BAL's −z-forward frame).
inline bool bal_project(const BalCamera& c, const Eigen::Vector3d& X, Eigen::Vector2d* pixel) {
  const Eigen::Vector3d P = c.R_bal() * X + c.t;
  if (!(P.z() < 0.0)) return false;
  const Eigen::Vector2d p = -P.head<2>() / P.z();
  const double r2 = p.squaredNorm();
  *pixel = c.f * (1.0 + c.k1 * r2 + c.k2 * r2 * r2) * p;
  return true;
}

/// Removes BAL radial distortion from an observed pixel: returns f·p where p solves
/// f·(1 + k1‖p‖² + k2‖p‖⁴)·p = pixel (Newton on the radius, started at the distorted radius).
/// Still in BAL's pixel frame (origin at the centre, y up); negate y for geodrift's frame.
/// @throws InvalidArgument if f <= 0 or the radial polynomial is not invertible there
///         (Newton does not converge, e.g. strong barrel distortion far from the centre).
inline Eigen::Vector2d undistort_bal_pixel(const BalCamera& c, const Eigen::Vector2d& pixel) {
  GEODRIFT_CHECK(c.f > 0.0, "BAL camera focal length " << c.f << " must be > 0");
  const double rd = pixel.norm() / c.f;  // distorted normalised radius
  if (rd == 0.0) return pixel;
  double r = rd;
  for (int it = 0; it < 50; ++it) {
    const double r2 = r * r;
    const double g = r * (1.0 + c.k1 * r2 + c.k2 * r2 * r2) - rd;
    const double dg = 1.0 + 3.0 * c.k1 * r2 + 5.0 * c.k2 * r2 * r2;
    GEODRIFT_CHECK(dg > 0.0, "BAL radial distortion (k1 " << c.k1 << ", k2 " << c.k2
                                                          << ") not invertible at radius " << rd);
    const double step = g / dg;
    r -= step;
    if (std::abs(step) <= 1e-15 * (1.0 + r)) return pixel * (r / rd);
  }
  GEODRIFT_CHECK(false, "BAL undistortion did not converge at radius " << rd << " (k1 " << c.k1
                                                                       << ", k2 " << c.k2 << ")");
  return pixel;
}

namespace detail_bal {

/// Whitespace token reader that knows the line of each token.
class Tokens {
 public:
  Tokens(std::istream& in, const std::string& name) : in_(in), name_(name) {}

  [[noreturn]] void fail(const std::string& what) const {
    std::ostringstream os;
    os << name_ << ":" << line_ << ": " << what;
    throw InvalidArgument(os.str());
  }

  /// Next token; `what` describes it for the end-of-file message.
  std::string next(const std::string& what) {
    std::string tok;
    int ch;
    while ((ch = in_.get()) != EOF) {
      if (ch == '\n') {
        if (!tok.empty()) {
          in_.unget();
          last_token_line_ = line_;
          return tok;
        }
        ++line_;
      } else if (std::isspace(ch)) {
        if (!tok.empty()) {
          last_token_line_ = line_;
          return tok;
        }
      } else {
        tok.push_back(static_cast<char>(ch));
      }
    }
    if (tok.empty()) {
      line_ = last_token_line_;  // report the end of the last line with content
      fail("unexpected end of file, expected " + what);
    }
    last_token_line_ = line_;
    return tok;
  }

  double next_double(const std::string& what) {
    const std::string s = next(what);
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end == s.c_str() || *end != '\0' || !std::isfinite(v)) {
      fail(what + ": '" + s + "' is not a finite number");
    }
    return v;
  }

  long next_int(const std::string& what) {
    const std::string s = next(what);
    char* end = nullptr;
    const long v = std::strtol(s.c_str(), &end, 10);
    if (end == s.c_str() || *end != '\0') fail(what + ": '" + s + "' is not an integer");
    return v;
  }

  /// True if only whitespace remains.
  bool at_end() {
    int ch;
    while ((ch = in_.peek()) != EOF && std::isspace(ch)) {
      if (ch == '\n') ++line_;
      in_.get();
    }
    return ch == EOF;
  }

  int line() const { return line_; }

 private:
  std::istream& in_;
  std::string name_;
  int line_ = 1;
  int last_token_line_ = 1;
};

}  // namespace detail_bal

/// Parses a BAL problem from a stream; `name` (a path) is used in error messages.
/// @throws InvalidArgument "<name>:<line>: <what>" on a malformed or truncated file: negative
///         or non-integer counts, camera/point index out of range, non-finite numbers, missing
///         or trailing values, a camera without observations is allowed, f <= 0 is not.
inline BalProblem parse_bal(std::istream& in, const std::string& name) {
  detail_bal::Tokens tok(in, name);
  const long nc = tok.next_int("number of cameras");
  const long np = tok.next_int("number of points");
  const long no = tok.next_int("number of observations");
  if (nc <= 0 || np <= 0 || no <= 0 || nc > 100000000L || np > 1000000000L || no > 2000000000L) {
    std::ostringstream os;
    os << "header counts (cameras " << nc << ", points " << np << ", observations " << no
       << ") must be positive";
    tok.fail(os.str());
  }
  BalProblem p;
  // The header counts are only claims until the values are read: grow with the file instead of
  // allocating them up front (a 20-byte header could otherwise ask for tens of GB).
  constexpr long kReserveMax = 1L << 16;
  p.observations.reserve(static_cast<std::size_t>(std::min(no, kReserveMax)));
  for (long k = 0; k < no; ++k) {
    BalObservation& o = p.observations.emplace_back();
    const std::string what = "observation " + std::to_string(k);
    const long c = tok.next_int(what + " camera index");
    if (c < 0 || c >= nc) {
      tok.fail(what + ": camera index " + std::to_string(c) + " outside [0, " + std::to_string(nc) +
               ")");
    }
    const long q = tok.next_int(what + " point index");
    if (q < 0 || q >= np) {
      tok.fail(what + ": point index " + std::to_string(q) + " outside [0, " + std::to_string(np) +
               ")");
    }
    o.camera = static_cast<int>(c);
    o.point = static_cast<int>(q);
    o.pixel.x() = tok.next_double(what + " x");
    o.pixel.y() = tok.next_double(what + " y");
  }
  static const char* kCamFields[9] = {"w1", "w2", "w3", "t1", "t2", "t3", "f", "k1", "k2"};
  p.cameras.reserve(static_cast<std::size_t>(std::min(nc, kReserveMax)));
  for (long k = 0; k < nc; ++k) {
    double v[9];
    for (int m = 0; m < 9; ++m) {
      v[m] = tok.next_double("camera " + std::to_string(k) + " parameter " + kCamFields[m]);
    }
    if (!(v[6] > 0.0)) {
      tok.fail("camera " + std::to_string(k) + ": focal length " + std::to_string(v[6]) +
               " must be > 0");
    }
    BalCamera& cam = p.cameras.emplace_back();
    cam.angle_axis = Eigen::Vector3d(v[0], v[1], v[2]);
    cam.t = Eigen::Vector3d(v[3], v[4], v[5]);
    cam.f = v[6];
    cam.k1 = v[7];
    cam.k2 = v[8];
  }
  p.points.reserve(static_cast<std::size_t>(std::min(np, kReserveMax)));
  for (long k = 0; k < np; ++k) {
    Eigen::Vector3d& X = p.points.emplace_back();
    for (int m = 0; m < 3; ++m) {
      X[m] = tok.next_double("point " + std::to_string(k) + " coordinate " + std::to_string(m));
    }
  }
  if (!tok.at_end()) tok.fail("trailing content after the last point");
  return p;
}

/// Reads a BAL problem file. @throws InvalidArgument naming the path (see parse_bal).
inline BalProblem read_bal(const std::string& path) {
  std::ifstream in(path);
  GEODRIFT_CHECK(in.is_open(), "cannot open BAL file '" << path << "'");
  return parse_bal(in, path);
}

}  // namespace geodrift::io
