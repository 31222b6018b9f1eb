#pragma once

/// @file
/// Bundle-adjustment benchmark problems (data only; the solvers build their problems from it):
///  - make_synthetic_ba: seeded synthetic BA, cameras along a gently curving road, every point
///    seen by `obs_per_point` consecutive cameras (issue 3: 500 cameras × 50,000 points × 5);
///  - make_kitti_ba: the real KITTI 00 tracks of GTSAM's VO_*00s files, left observations only,
///    start = the file's poses perturbed with seeded noise.
/// Poses are world -> camera T_cw (x right, y down, z forward); one pinhole K for all cameras;
/// residual r = π(T_cw·X) − uv (solver::ReprojectionResidual) with a Huber loss. Cameras 0 and
/// 1 are held constant (monocular gauge: 6 dof + scale).

#include <Eigen/Core>
#include <cmath>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "geodrift/io/vo_stereo.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/so3.hpp"

namespace geodrift::bench {

struct BaData {
  struct Obs {
    int camera = 0, point = 0;
    Eigen::Vector2d uv = Eigen::Vector2d::Zero();
  };
  std::vector<lie::SE3d> poses;         ///< start values, T_cw
  std::vector<Eigen::Vector3d> points;  ///< start values, W
  std::vector<Obs> observations;        ///< in generation / file order
  double fx = 500, fy = 500, cx = 320, cy = 240;
  std::vector<int> fixed_cameras{0, 1};
  double huber = 2.0;  ///< Huber threshold [px]
};

/// Synthetic BA. Cameras 1 m apart along a road that slowly turns (yaw sin-wave ±15°), facing
/// forward; each point is placed in the image of the LAST of its `obs_per_point` consecutive
/// cameras at depth 6-40 m (so every earlier camera, further back, also sees it), observed with
/// N(0, pixel_noise²) noise. Start: cameras 2.. perturbed by N(0, 0.3°) rotation and N(0, 5 cm)
/// translation per axis; points by N(0, 10 cm) per axis.
inline BaData make_synthetic_ba(int cameras, int points, int obs_per_point, unsigned seed,
                                double pixel_noise = 0.5) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  BaData d;
  const double width = 640, height = 480;
  std::vector<lie::SE3d> truth;
  double x = 0, y = 0;
  for (int k = 0; k < cameras; ++k) {
    const double yaw = 0.26 * std::sin(2.0 * M_PI * k / 150.0);
    const double c = std::cos(yaw), s = std::sin(yaw);
    Eigen::Matrix3d R_wc;
    R_wc.col(0) = Eigen::Vector3d(s, -c, 0.0);
    R_wc.col(1) = Eigen::Vector3d(0.0, 0.0, -1.0);
    R_wc.col(2) = Eigen::Vector3d(c, s, 0.0);
    const lie::SO3d R_cw(Eigen::Matrix3d(R_wc.transpose()));
    const Eigen::Vector3d centre(x, y, 1.6);
    truth.emplace_back(R_cw, -(R_cw.act(centre)));
    x += c;
    y += s;
  }
  const int span = obs_per_point;
  for (int p = 0; p < points; ++p) {
    const int first = static_cast<int>(u01(rng) * (cameras - span + 1)) % (cameras - span + 1);
    const int last = first + span - 1;
    const double u = width * u01(rng), v = height * u01(rng), z = 6.0 + 34.0 * u01(rng);
    const Eigen::Vector3d P_last((u - d.cx) / d.fx * z, (v - d.cy) / d.fy * z, z);
    const Eigen::Vector3d X = truth[static_cast<std::size_t>(last)].inverse().act(P_last);
    d.points.push_back(X + 0.1 * Eigen::Vector3d(n01(rng), n01(rng), n01(rng)));
    for (int c = first; c <= last; ++c) {
      const Eigen::Vector3d P = truth[static_cast<std::size_t>(c)].act(X);
      const Eigen::Vector2d uv(d.fx * P.x() / P.z() + d.cx + pixel_noise * n01(rng),
                               d.fy * P.y() / P.z() + d.cy + pixel_noise * n01(rng));
      d.observations.push_back({c, p, uv});
    }
  }
  for (int k = 0; k < cameras; ++k) {
    lie::SE3d T = truth[static_cast<std::size_t>(k)];
    if (k >= 2) {
      Eigen::Matrix<double, 6, 1> e;
      for (int a = 0; a < 3; ++a) e[a] = 0.3 * M_PI / 180.0 * n01(rng);
      for (int a = 3; a < 6; ++a) e[a] = 0.05 * n01(rng);
      T = lie::SE3d::exp(e) * T;
    }
    d.poses.push_back(T);
  }
  return d;
}

/// KITTI 00 from GTSAM's VO files in `dir` (…/gtsam_examples_data/): 77 poses, left
/// observations. Start: poses 2.. perturbed by N(0, 0.5°) and N(0, 0.2 m) per axis;
/// points = first observation's camera-frame point through the perturbed pose. Landmarks with
/// fewer than 3 observations are dropped (monocular depth undetermined / barely determined).
inline BaData make_kitti_ba(const std::string& dir, unsigned seed) {
  const io::VoCalibration K = io::read_vo_calibration(dir + "/VO_calibration00s.txt");
  const std::vector<io::VoCameraPose> poses =
      io::read_vo_camera_poses(dir + "/VO_camera_poses00s.txt");
  const std::vector<io::VoStereoObservation> obs =
      io::read_vo_stereo_factors(dir + "/VO_stereo_factors00s.txt");
  BaData d;
  d.fx = K.fx;
  d.fy = K.fy;
  d.cx = K.cx;
  d.cy = K.cy;
  std::mt19937 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  std::map<int, int> pose_index;
  for (const io::VoCameraPose& p : poses) {
    pose_index[p.id] = static_cast<int>(d.poses.size());
    const Eigen::Matrix4d T_cw = p.T_cw();
    lie::SE3d T(lie::SO3d(Eigen::Matrix3d(T_cw.topLeftCorner<3, 3>())),
                T_cw.topRightCorner<3, 1>());
    if (d.poses.size() >= 2) {
      Eigen::Matrix<double, 6, 1> e;
      for (int a = 0; a < 3; ++a) e[a] = 0.5 * M_PI / 180.0 * n01(rng);
      for (int a = 3; a < 6; ++a) e[a] = 0.2 * n01(rng);
      T = lie::SE3d::exp(e) * T;
    }
    d.poses.push_back(T);
  }
  // Landmarks seen fewer than 3 times are dropped (one observation leaves the depth free).
  std::map<int, int> count;
  for (const io::VoStereoObservation& o : obs) ++count[o.landmark];
  std::map<int, int> point_index;
  for (const io::VoStereoObservation& o : obs) {
    if (count[o.landmark] < 3) continue;
    const int c = pose_index.at(o.camera);
    auto it = point_index.find(o.landmark);
    if (it == point_index.end()) {
      it = point_index.emplace(o.landmark, static_cast<int>(d.points.size())).first;
      d.points.push_back(d.poses[static_cast<std::size_t>(c)].inverse().act(o.point_camera));
    }
    d.observations.push_back({c, it->second, Eigen::Vector2d(o.u_left, o.v)});
  }
  return d;
}

}  // namespace geodrift::bench
