#pragma once

// KITTI for the tests and benchmarks: the odometry camera of sequences 00-02 (P0 of calib.txt:
// fx = fy = 718.856, cx = 607.1928, cy = 185.2157) at its 1241x376 image size, and a ground-truth
// pose file as the camera-to-KITTI isometries render::World::from_kitti takes.

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "geodrift/io/trajectory.hpp"
#include "geodrift/map/camera.hpp"

namespace geodrift::test {

inline map::Camera kitti_camera() {
  map::Camera c;
  c.fx = c.fy = 718.856;
  c.cx = 607.1928;
  c.cy = 185.2157;
  c.width = 1241;
  c.height = 376;
  return c;
}

/// The first `max_poses` (all when < 0) poses of a KITTI ground-truth file as T_K_c.
inline std::vector<Eigen::Isometry3d> kitti_T_K_c(const std::string& poses_path,
                                                  int max_poses = -1) {
  std::vector<Eigen::Isometry3d> T_K_c;
  for (const io::TrajectoryPose& p :
       io::read_trajectory(poses_path, io::TrajectoryFormat::kKitti).poses) {
    if (max_poses >= 0 && static_cast<int>(T_K_c.size()) >= max_poses) break;
    Eigen::Isometry3d T;
    T.matrix() = p.T_cw.inverse().matrix();
    T_K_c.push_back(T);
  }
  return T_K_c;
}

}  // namespace geodrift::test
