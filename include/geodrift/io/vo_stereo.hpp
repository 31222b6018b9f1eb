#pragma once

/// @file
/// Readers for GTSAM's stereo visual-odometry example format (GTSAM examples/Data
/// VO_calibration*.txt, VO_camera_poses*.txt, VO_stereo_factors*.txt; real KITTI 00 tracks).
///
///   calibration: fx fy skew cx cy baseline [16 numbers: a 4x4 row-major pose, ignored]
///   poses:       one line per camera: id, then the 4x4 row-major T_wc (camera -> world,
///                GTSAM Pose3 of the left camera; x right, y down, z forward)
///   factors:     one line per stereo observation: cam_id landmark_id uL uR v X Y Z
///                (uL, uR: column in the left/right image, v: common row [px]; (X, Y, Z): the
///                landmark triangulated in the observing camera's frame [m], which GTSAM's
///                StereoVOExample uses to initialise the landmark as T_wc·(X, Y, Z)).
/// geodrift keeps poses as T_cw (DESIGN.md): VoCameraPose::T_cw() converts at the edge. For
/// monocular bundle adjustment use the left observation (uL, v) with the pinhole K from the
/// calibration.

#include <Eigen/Core>
#include <Eigen/SVD>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <istream>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::io {

/// Stereo rig intrinsics of the left camera (the right one is shifted by `baseline` along x).
struct VoCalibration {
  double fx = 0, fy = 0, skew = 0, cx = 0, cy = 0;  ///< pixels
  double baseline = 0;                              ///< metres
};

/// One line of a poses file.
struct VoCameraPose {
  int id = 0;
  Eigen::Matrix4d T_wc = Eigen::Matrix4d::Identity();  ///< camera -> world, as in the file

  /// World -> camera (geodrift's convention).
  Eigen::Matrix4d T_cw() const {
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    const Eigen::Matrix3d R = T_wc.topLeftCorner<3, 3>();
    T.topLeftCorner<3, 3>() = R.transpose();
    T.topRightCorner<3, 1>() = -R.transpose() * T_wc.topRightCorner<3, 1>();
    return T;
  }
};

/// One line of a stereo factors file.
struct VoStereoObservation {
  int camera = 0;                                          ///< pose id
  int landmark = 0;                                        ///< landmark id
  double u_left = 0, u_right = 0, v = 0;                   ///< pixels
  Eigen::Vector3d point_camera = Eigen::Vector3d::Zero();  ///< landmark in camera frame [m]
};

namespace detail_vo {

[[noreturn]] inline void fail(const std::string& name, int line, const std::string& what) {
  std::ostringstream os;
  os << name << ":" << line << ": " << what;
  throw InvalidArgument(os.str());
}

/// Splits a line into finite doubles; throws naming the bad field.
inline std::vector<double> numbers(const std::string& text, const std::string& name, int line) {
  std::vector<double> out;
  std::istringstream is(text);
  std::string w;
  while (is >> w) {
    char* end = nullptr;
    const double v = std::strtod(w.c_str(), &end);
    if (end == w.c_str() || *end != '\0' || !std::isfinite(v)) {
      fail(name, line,
           "field " + std::to_string(out.size() + 1) + ": '" + w + "' is not a finite number");
    }
    out.push_back(v);
  }
  return out;
}

inline int as_id(double v, const std::string& name, int line, const char* what) {
  if (!(v >= 0.0 && v <= 2147483647.0 && v == std::floor(v))) {
    std::ostringstream os;
    os << what << " " << v << " is not a non-negative integer";
    fail(name, line, os.str());
  }
  return static_cast<int>(v);
}

inline std::ifstream open(const std::string& path, const char* kind) {
  std::ifstream in(path);
  GEODRIFT_CHECK(in.is_open(), "cannot open " << kind << " file '" << path << "'");
  return in;
}

}  // namespace detail_vo

/// Parses a calibration stream (first non-empty line). @throws InvalidArgument
/// "<name>:<line>: <what>" if it has fewer than 6 numbers, fx/fy <= 0 or baseline <= 0.
inline VoCalibration parse_vo_calibration(std::istream& in, const std::string& name) {
  std::string text;
  int line = 0;
  while (std::getline(in, text)) {
    ++line;
    const std::vector<double> v = detail_vo::numbers(text, name, line);
    if (v.empty()) continue;
    if (v.size() != 6 && v.size() != 22) {
      detail_vo::fail(name, line,
                      "calibration needs 6 numbers (fx fy skew cx cy baseline), optionally "
                      "followed by a 4x4 pose (22 in all); got " +
                          std::to_string(v.size()));
    }
    VoCalibration c{v[0], v[1], v[2], v[3], v[4], v[5]};
    if (!(c.fx > 0 && c.fy > 0 && c.baseline > 0)) {
      detail_vo::fail(name, line, "fx, fy and baseline must be > 0");
    }
    return c;
  }
  detail_vo::fail(name, line, "no calibration line");
}

/// Parses a poses stream. @throws InvalidArgument "<name>:<line>: <what>" on a line that is
/// not 17 numbers, a non-integer or duplicate id, or a rotation block that is not a rotation
/// (‖RᵀR − I‖ > 1e-4 or det < 0) or a last row other than (0 0 0 1).
inline std::vector<VoCameraPose> parse_vo_camera_poses(std::istream& in, const std::string& name) {
  std::vector<VoCameraPose> out;
  std::unordered_map<int, int> line_of_id;
  std::string text;
  int line = 0;
  while (std::getline(in, text)) {
    ++line;
    const std::vector<double> v = detail_vo::numbers(text, name, line);
    if (v.empty()) continue;
    if (v.size() != 17) {
      detail_vo::fail(
          name, line,
          "pose line needs 17 numbers (id + 4x4 row-major), got " + std::to_string(v.size()));
    }
    VoCameraPose p;
    p.id = detail_vo::as_id(v[0], name, line, "pose id");
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) p.T_wc(r, c) = v[static_cast<std::size_t>(1 + 4 * r + c)];
    }
    const Eigen::Matrix3d R = p.T_wc.topLeftCorner<3, 3>();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-4 || R.determinant() < 0) {
      detail_vo::fail(name, line, "the 3x3 block is not a rotation matrix");
    }
    if (p.T_wc.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
      detail_vo::fail(name, line, "the last row of the 4x4 pose is not (0 0 0 1)");
    }
    // Re-orthonormalise (files carry 6 significant digits).
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
    p.T_wc.topLeftCorner<3, 3>() = svd.matrixU() * svd.matrixV().transpose();
    const auto ins = line_of_id.emplace(p.id, line);
    if (!ins.second) {
      detail_vo::fail(name, line,
                      "duplicate pose id " + std::to_string(p.id) + " (first on line " +
                          std::to_string(ins.first->second) + ")");
    }
    out.push_back(p);
  }
  GEODRIFT_CHECK(!out.empty(), name << ": no pose line");
  return out;
}

/// Parses a stereo factors stream. @throws InvalidArgument "<name>:<line>: <what>" on a line
/// that is not 8 numbers, non-integer ids, or a landmark not in front of the camera (Z <= 0).
inline std::vector<VoStereoObservation> parse_vo_stereo_factors(std::istream& in,
                                                                const std::string& name) {
  std::vector<VoStereoObservation> out;
  std::string text;
  int line = 0;
  while (std::getline(in, text)) {
    ++line;
    const std::vector<double> v = detail_vo::numbers(text, name, line);
    if (v.empty()) continue;
    if (v.size() != 8) {
      detail_vo::fail(name, line,
                      "stereo factor needs 8 numbers (cam_id landmark_id uL uR v X Y Z), got " +
                          std::to_string(v.size()));
    }
    VoStereoObservation o;
    o.camera = detail_vo::as_id(v[0], name, line, "camera id");
    o.landmark = detail_vo::as_id(v[1], name, line, "landmark id");
    o.u_left = v[2];
    o.u_right = v[3];
    o.v = v[4];
    o.point_camera = Eigen::Vector3d(v[5], v[6], v[7]);
    if (!(o.point_camera.z() > 0.0)) {
      std::ostringstream os;
      os << "landmark depth Z = " << o.point_camera.z() << " must be > 0";
      detail_vo::fail(name, line, os.str());
    }
    out.push_back(o);
  }
  GEODRIFT_CHECK(!out.empty(), name << ": no stereo factor line");
  return out;
}

/// Reads a calibration file. @throws InvalidArgument naming the path.
inline VoCalibration read_vo_calibration(const std::string& path) {
  std::ifstream in = detail_vo::open(path, "VO calibration");
  return parse_vo_calibration(in, path);
}
/// Reads a poses file. @throws InvalidArgument naming the path.
inline std::vector<VoCameraPose> read_vo_camera_poses(const std::string& path) {
  std::ifstream in = detail_vo::open(path, "VO camera poses");
  return parse_vo_camera_poses(in, path);
}
/// Reads a stereo factors file. @throws InvalidArgument naming the path.
inline std::vector<VoStereoObservation> read_vo_stereo_factors(const std::string& path) {
  std::ifstream in = detail_vo::open(path, "VO stereo factors");
  return parse_vo_stereo_factors(in, path);
}

}  // namespace geodrift::io
