// Inputs and clean failures: calibration files, image folders, unreadable video, black frames,
// pure rotation (the VO never initialises and says why), and `geodrift run` on bad input.

#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "corridor.hpp"
#include "geodrift/error.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/vo/input.hpp"
#include "geodrift/vo/odometry.hpp"
#include "support/cli_run.hpp"
#include "support/test_files.hpp"

using namespace geodrift;
namespace fs = std::filesystem;

namespace {

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

const char* kKittiCalib =
    "P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00\n"
    "P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 "
    "0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 "
    "0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00\n";

}  // namespace

TEST_CASE("Calibration files: KITTI P0, K/D text, OpenCV YAML, and clear errors", "[vo]") {
  test::TempDir t;
  test::write_text(t.file("calib.txt"), kKittiCalib);
  const vo::Calibration k = vo::load_calibration(t.file("calib.txt"));
  CHECK(k.camera.fx == Approx(718.856));
  CHECK(k.camera.fy == Approx(718.856));
  CHECK(k.camera.cx == Approx(607.1928));
  CHECK(k.camera.cy == Approx(185.2157));
  CHECK_FALSE(k.has_distortion());

  test::write_text(t.file("kd.txt"),
                   "K: 500 0 320 0 510 240 0 0 1\nD: -0.1 0.01 0 0\nsize: 640 480\n");
  const vo::Calibration kd = vo::load_calibration(t.file("kd.txt"));
  CHECK(kd.camera.fy == Approx(510));
  CHECK(kd.camera.width == 640);
  CHECK(kd.has_distortion());

  {
    cv::FileStorage fs(t.file("cam.yaml"), cv::FileStorage::WRITE);
    fs << "camera_matrix" << cv::Mat(cv::Matx33d(400, 0, 300, 0, 400, 200, 0, 0, 1));
    fs << "distortion_coefficients" << cv::Mat(cv::Matx<double, 1, 5>(0.05, 0, 0, 0, 0));
    fs << "image_width" << 600 << "image_height" << 400;
  }
  const vo::Calibration y = vo::load_calibration(t.file("cam.yaml"));
  CHECK(y.camera.fx == Approx(400));
  CHECK(y.camera.height == 400);
  CHECK(y.distortion.size() == 5);

  CHECK_THAT(error_of([&] { vo::load_calibration(t.file("missing.txt")); }),
             Catch::Contains("does not exist"));
  test::write_text(t.file("bad.txt"), "nothing here\n");
  CHECK_THAT(error_of([&] { vo::load_calibration(t.file("bad.txt")); }),
             Catch::Contains("no 'P0:' line"));
  test::write_text(t.file("short.txt"), "P0: 1 2 3\n");
  CHECK_THAT(error_of([&] { vo::load_calibration(t.file("short.txt")); }),
             Catch::Contains("expected 12"));
}

TEST_CASE("Frame sources: KITTI folder order and times, unreadable video", "[vo]") {
  test::TempDir t;
  fs::create_directories(t.path() / "image_0");
  for (int i : {2, 0, 1}) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", i);
    cv::imwrite((t.path() / "image_0" / name).string(), cv::Mat(10, 12, CV_8UC1, cv::Scalar(i)));
  }
  test::write_text(t.file("times.txt"), "0.0\n0.1\n0.2\n");
  auto src = vo::open_image_folder(t.path().string());
  CHECK(src->size() == 3);
  vo::Frame f;
  for (int i = 0; i < 3; ++i) {
    REQUIRE(src->next(&f));
    CHECK(f.gray.at<std::uint8_t>(0, 0) == i);
    CHECK(f.timestamp == Approx(0.1 * i));
  }
  CHECK_FALSE(src->next(&f));
  CHECK_THAT(error_of([&] { vo::open_image_folder(t.file("nope")); }),
             Catch::Contains("does not exist"));
  test::write_text(t.file("video.mp4"), "this is not a video");
  CHECK_THAT(error_of([&] { vo::open_video(t.file("video.mp4")); }), Catch::Contains("video.mp4"));
  CHECK_THAT(error_of([&] { vo::open_video(t.file("none.avi")); }),
             Catch::Contains("does not exist"));
}

TEST_CASE("A video file is read frame by frame, in grey, with container timestamps", "[vo]") {
  // OpenCV's built-in MJPEG writer needs no codec library, so the file exists on every machine.
  test::TempDir t;
  const std::string path = t.file("drive.avi");
  {
    cv::VideoWriter w(path, cv::CAP_OPENCV_MJPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                      cv::Size(64, 48), true);
    REQUIRE(w.isOpened());
    for (int i = 0; i < 5; ++i) w.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar::all(40 * i + 20)));
  }
  auto src = vo::open_video(path);
  CHECK(src->size() == -1);
  vo::Frame f;
  int n = 0;
  while (src->next(&f)) {
    CHECK(f.index == n);
    CHECK(f.gray.type() == CV_8UC1);
    CHECK(f.gray.size() == cv::Size(64, 48));
    CHECK(std::abs(f.gray.at<std::uint8_t>(24, 32) - (40 * n + 20)) <= 3);  // JPEG rounding
    CHECK(f.timestamp == Approx(0.1 * n).margin(1e-6));
    ++n;
  }
  CHECK(n == 5);
}

TEST_CASE("Black frames and pure rotation never initialise, with the reason", "[vo]") {
  const map::Camera cam = test::corridor_camera();
  {
    vo::Odometry odo(cam);
    for (int i = 0; i < 5; ++i) {
      vo::Frame f;
      f.index = i;
      f.gray = cv::Mat(cam.height, cam.width, CV_8UC1, cv::Scalar(0));
      const vo::FrameResult r = odo.process(f);
      CHECK_FALSE(r.has_pose());
      CHECK_THAT(r.message, Catch::Contains("black or textureless"));
    }
    CHECK_FALSE(odo.initialized());
  }
  {
    // The camera turns in place (yaw up to 12 degrees, some pitch): every pair is a homography.
    const test::Corridor world;
    vo::Odometry odo(cam);
    std::string last;
    for (int i = 0; i < 25; ++i) {
      Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
      T.linear() = (Eigen::AngleAxisd(0.5 * i * M_PI / 180, Eigen::Vector3d::UnitY()) *
                    Eigen::AngleAxisd(0.1 * i * M_PI / 180, Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
      T.translation() = Eigen::Vector3d(0, 0, 3);
      vo::Frame f;
      f.index = i;
      f.gray = world.render(cam, T);
      const vo::FrameResult r = odo.process(f);
      CHECK_FALSE(r.has_pose());
    }
    CHECK_FALSE(odo.initialized());
    INFO(odo.last_init_failure());
    CHECK(odo.init_attempts() > 5);
    CHECK((odo.last_init_failure().find("parallax") != std::string::npos ||
           odo.last_init_failure().find("pure rotation") != std::string::npos));
  }
}

#ifdef GEODRIFT_CLI_EXE
namespace {
using Run = test::CliRun;
Run run(const std::string& args) { return test::run_cli(GEODRIFT_CLI_EXE, args); }
}  // namespace

TEST_CASE("geodrift run fails cleanly on bad input and leaves no output", "[vo][cli]") {
  test::TempDir t;
  const map::Camera cam = test::corridor_camera();
  // An image folder of black frames, one of a pure rotation, and one without calibration.
  const test::Corridor world;
  for (const char* d : {"black", "rotation", "nocalib"}) fs::create_directories(t.path() / d);
  for (int i = 0; i < 12; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", i);
    cv::imwrite((t.path() / "black" / name).string(),
                cv::Mat(cam.height, cam.width, CV_8UC1, cv::Scalar(0)));
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() =
        Eigen::AngleAxisd(0.8 * i * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
    const cv::Mat img = world.render(cam, T);
    cv::imwrite((t.path() / "rotation" / name).string(), img);
    cv::imwrite((t.path() / "nocalib" / name).string(), img);
  }
  const std::string calib = "K: 360 0 320 0 360 120 0 0 1\n";
  test::write_text((t.path() / "black" / "calib.txt").string(), calib);
  test::write_text((t.path() / "rotation" / "calib.txt").string(), calib);
  test::write_text(t.file("bad.mp4"), "not a video");
  const std::string out = t.file("out");
  struct Case {
    std::string args, expect;
  } cases[] = {
      {"--images " + t.file("black") + " --out " + out, "black or textureless"},
      {"--images " + t.file("rotation") + " --out " + out, "could not initialise"},
      {"--images " + t.file("nocalib") + " --out " + out, "no calibration"},
      {"--images " + t.file("rotation") + " --calib " + t.file("nope.txt") + " --out " + out,
       "does not exist"},
      {"--video " + t.file("bad.mp4") + " --calib " + t.file("rotation/calib.txt") + " --out " +
           out,
       "cannot open video"},
      {"--images " + t.file("rotation") + " --geotags " + t.file("x") + " --out " + out,
       "cannot open geotag database"},
  };
  for (const Case& c : cases) {
    const Run r = run("run " + c.args);
    INFO(c.args << "\n" << r.output);
    CHECK(r.code != 0);
    CHECK_THAT(r.output, Catch::Contains(c.expect));
    CHECK(test::no_outputs(t.path(), "out"));
  }
}
#endif

#ifdef GEODRIFT_CLI_EXE
TEST_CASE("geodrift run on an image folder writes the reconstruction, keyframes with frame index",
          "[vo][cli]") {
  test::TempDir t;
  const map::Camera cam = test::corridor_camera();
  const test::Corridor world;
  const int n = 60;
  fs::create_directories(t.path() / "drive");
  for (int i = 0; i < n; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", i);
    cv::imwrite((t.path() / "drive" / name).string(), world.render(cam, test::Corridor::pose(i)));
  }
  test::write_text((t.path() / "drive" / "calib.txt").string(), "K: 360 0 320 0 360 120 0 0 1\n");
  const Run r = run("run --images " + t.file("drive") + " --out " + t.file("out"));
  INFO(r.output);
  REQUIRE(r.code == 0);
  for (const char* f :
       {"trajectory_kitti.txt", "trajectory_tum.txt", "keyframes_kitti.txt", "model/cameras.txt",
        "model/images.txt", "model/points3D.txt", "points.ply", "report.json"})
    CHECK(fs::exists(t.path() / "out" / f));
  const io::Trajectory all = io::read_trajectory(t.file("out/trajectory_kitti.txt"));
  const io::Trajectory kfs = io::read_trajectory(t.file("out/keyframes_kitti.txt"));
  CHECK(all.poses.size() >= static_cast<std::size_t>(0.95 * n));
  // Keyframes carry the frame index they were taken at (eval matches poses by it).
  REQUIRE(kfs.has_frame_index);
  REQUIRE(kfs.poses.size() >= 5);
  CHECK(kfs.poses.back().frame > static_cast<int>(kfs.poses.size()));
  for (std::size_t i = 1; i < kfs.poses.size(); ++i)
    CHECK(kfs.poses[i].frame > kfs.poses[i - 1].frame);
  // A second run into the same folder is refused: nothing the user has is overwritten.
  const Run again = run("run --images " + t.file("drive") + " --out " + t.file("out"));
  CHECK(again.code != 0);
}
#endif
