#pragma once

// The KITTI odometry camera of sequences 00-02 (P0 of calib.txt: fx = fy = 718.856,
// cx = 607.1928, cy = 185.2157) at its 1241x376 image size, as the rendered test worlds use it.

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

}  // namespace geodrift::test
