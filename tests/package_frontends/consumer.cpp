// Uses one entry point of each installed frontend: renders a small frame of a street world,
// builds its K-VLD scale space, cuts a view from a synthetic panorama and starts a VO on it.
#include <cstdio>
#include <geodrift/geotag/panorama.hpp>
#include <geodrift/kvld/kvld.hpp>
#include <geodrift/render/render.hpp>
#include <geodrift/render/world.hpp>
#include <geodrift/vo/odometry.hpp>
#include <vector>

int main() {
  using namespace geodrift;
  std::vector<Eigen::Isometry3d> T_K_c(40, Eigen::Isometry3d::Identity());
  for (int i = 0; i < 40; ++i) T_K_c[i].translation() = Eigen::Vector3d(0, 0, 1.0 * i);
  render::WorldOptions wo;
  wo.seed = 3;
  const render::World world = render::World::from_kitti(T_K_c, wo);
  map::Camera cam;
  cam.fx = cam.fy = 60;
  cam.cx = 40;
  cam.cy = 30;
  cam.width = 80;
  cam.height = 60;
  const cv::Mat img =
      render::render_pinhole(world, world.frame_T_cw(5), cam, render::Appearance::video());
  const kvld::ImageScale scale(img);
  const cv::Mat pano(64, 128, CV_8UC1, cv::Scalar(128));
  const cv::Mat view = geotag::cut_panorama_view(pano, cam, 0.0);
  vo::Odometry odometry(cam);
  const bool ok = img.cols == 80 && img.rows == 60 && view.cols == 80 && view.rows == 60 &&
                  cv::countNonZero(img) > 0;
  std::printf("frontends consumer: %s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
