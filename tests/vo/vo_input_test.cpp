// Inputs and clean failures: calibration files, image folders, unreadable video, black frames,
// pure rotation (the VO never initialises and says why), and `geodrift run` on bad input.

#include <sys/wait.h>

#include <catch2/catch.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <regex>

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

TEST_CASE("Calibration YAML: OpenCV, ROS camera_info, lists, ORB-SLAM2/3, and clear errors",
          "[vo]") {
  test::TempDir t;
  const auto load = [&](const std::string& name, const std::string& text) {
    test::write_text(t.file(name), text);
    return vo::load_calibration(t.file(name));
  };
  // OpenCV's block form with a data list over two lines and comments.
  vo::Calibration c = load("cv.yaml",
                           "%YAML:1.0\n---\n# calibrated 2026\ncamera_matrix: !!opencv-matrix\n"
                           "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 7.1e+02, 0., 6.0e+02,\n"
                           "       0., 7.2e+02, 1.8e+02, 0., 0., 1. ]  # row-major\n"
                           "distortion_coefficients: !!opencv-matrix\n   rows: 5\n   cols: 1\n"
                           "   dt: d\n   data: [ -0.3, 0.1, 0.001, -0.002, 0. ]\n"
                           "image_width: 1241\nimage_height: 376\n");
  CHECK(c.camera.fx == 710.0);
  CHECK(c.camera.fy == 720.0);
  CHECK(c.camera.cx == 600.0);
  CHECK(c.camera.cy == 180.0);
  CHECK(c.camera.width == 1241);
  CHECK(c.camera.height == 376);
  REQUIRE(c.distortion.size() == 5);
  CHECK(c.distortion[3] == -0.002);

  // ROS camera_info: no tag, no %YAML header.
  c = load("ros.yaml",
           "image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\ncamera_matrix:\n"
           "  rows: 3\n  cols: 3\n  data: [500, 0, 320, 0, 505, 240, 0, 0, 1]\n"
           "distortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
           "  data: [0.1, -0.2, 0, 0, 0]\nprojection_matrix:\n  rows: 3\n  cols: 4\n"
           "  data: [500, 0, 320, 0, 0, 505, 240, 0, 0, 0, 1, 0]\n");
  CHECK(c.camera.fy == 505.0);
  CHECK(c.camera.width == 640);
  CHECK(c.distortion.size() == 5);

  // Plain lists.
  c = load("list.yml", "K: [400, 0, 300, 0, 401, 200, 0, 0, 1]\nD: [0.01, 0, 0, 0]\n");
  CHECK(c.camera.fy == 401.0);
  CHECK(c.distortion.size() == 4);

  // ORB-SLAM2 and ORB-SLAM3 settings (other keys, nested blocks and matrices are skipped).
  c = load("orb2.yaml",
           "%YAML:1.0\nCamera.fx: 718.856\nCamera.fy: 718.856\nCamera.cx: 607.1928\n"
           "Camera.cy: 185.2157\nCamera.k1: 0.0\nCamera.k2: 0.0\nCamera.p1: 0.0\n"
           "Camera.p2: 0.0\nCamera.width: 1241\nCamera.height: 376\nCamera.fps: 10.0\n"
           "ORBextractor.nFeatures: 2000\nViewer.KeyFrameSize: 0.1\n");
  CHECK(c.camera.cx == 607.1928);
  CHECK(c.camera.width == 1241);
  CHECK(c.distortion.size() == 4);
  c = load("orb3.yaml",
           "%YAML:1.0\nFile.version: \"1.0\"\nCamera.type: \"PinHole\"\n"
           "Camera1.fx: 458.654\nCamera1.fy: 457.296\nCamera1.cx: 367.215\n"
           "Camera1.cy: 248.375\nCamera1.k1: -0.28340811\nCamera1.k2: 0.07395907\n"
           "Camera1.p1: 0.00019359\nCamera1.p2: 1.76187114e-05\nCamera.width: 752\n"
           "Camera.height: 480\nIMU.T_b_c1: !!opencv-matrix\n   rows: 4\n   cols: 4\n"
           "   dt: f\n   data: [0.0148655429818, -0.999880929698, 0.00414029679422,\n"
           "         -0.0216401454975, 0.999557249008, 0.0149672133247,\n"
           "         0.025715529948, -0.0257744366974, 0.00375618835797, 0.999660727178,\n"
           "         0.00981073058949, 0.0, 0.0, 0.0, 1.0]\n");
  CHECK(c.camera.fy == 457.296);
  CHECK(c.camera.height == 480);
  CHECK(c.distortion.size() == 4);

  const auto error = [&](const std::string& name, const std::string& text) {
    return error_of([&] { load(name, text); });
  };
  CHECK_THAT(error("fish.yaml",
                   "Camera.type: \"KannalaBrandt8\"\nCamera1.fx: 1\n"
                   "Camera1.fy: 1\nCamera1.cx: 1\nCamera1.cy: 1\n"),
             Catch::Contains("fish.yaml:1: Camera.type 'KannalaBrandt8' is not supported"));
  CHECK_THAT(error("part.yaml", "Camera.fx: 500\nCamera.fy: 500\n"),
             Catch::Contains("part.yaml: Camera.fx is given but not all of Camera.fy, cx, cy"));
  CHECK_THAT(error("open.yaml", "K: [500, 0, 320,\n 0, 500, 240,\n"),
             Catch::Contains("open.yaml:1: 'K': the list opened with '[' is never closed"));
  CHECK_THAT(error("nan.yaml", "K: [500, 0, 320, 0, x500, 240, 0, 0, 1]\n"),
             Catch::Contains("nan.yaml:1: 'K' item 'x500' is not a number"));
  CHECK_THAT(error("nine.yaml", "K: [500, 0, 320, 0, 500, 240]\n"),
             Catch::Contains("nine.yaml:1: 'K' lists 6 numbers, expected 9"));
  CHECK_THAT(error("count.yaml", "K: !!opencv-matrix\n  rows: 3\n  cols: 3\n  data: [1, 2]\n"),
             Catch::Contains("count.yaml:4: 'K' data lists 2 numbers, rows x cols is 3x3"));
  CHECK_THAT(error("twice.yaml", "K: [1, 0, 1, 0, 1, 1, 0, 0, 1]\ncamera_matrix: [1]\n"),
             Catch::Contains("twice.yaml:2: 'camera_matrix' repeats 'K' of line 1"));
  CHECK_THAT(error("dmat.yaml",
                   "K: [1, 0, 1, 0, 1, 1, 0, 0, 1]\nD: !!opencv-matrix\n  rows: 2\n"
                   "  cols: 2\n  data: [0, 0, 0, 0]\n"),
             Catch::Contains("dmat.yaml:2: distortion 'D' is 2x2, expected one row or one column"));
  CHECK_THAT(error("inf.yaml", "K: [inf, 0, 1, 0, 1, 1, 0, 0, 1]\n"),
             Catch::Contains("are not finite and positive"));
  CHECK_THAT(error("none.yaml", "%YAML:1.0\nfoo: 1\nbar:\n  - 1\n"),
             Catch::Contains("has no 'P0:' line"));
  // A calibration file is small; a large file is refused before it is read.
  {
    std::ofstream big(t.file("big.yaml"), std::ios::binary);
    big.seekp((std::streamoff{17} << 20) - 1);
    big.put('\n');
  }
  CHECK_THAT(error_of([&] { vo::load_calibration(t.file("big.yaml")); }),
             Catch::Contains("a calibration file is at most 16 MiB"));
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

  // Determinism: the same frames with --threads 2 (local BA on two threads) give byte-identical
  // files; report.json differs only in its command line, the threads parameter and timings.
  const Run two = run("run --images " + t.file("drive") + " --threads 2 --out " + t.file("out2"));
  INFO(two.output);
  REQUIRE(two.code == 0);
  std::size_t compared = 0;
  for (const auto& e : fs::recursive_directory_iterator(t.path() / "out")) {
    if (!e.is_regular_file()) continue;
    const fs::path rel = fs::relative(e.path(), t.path() / "out");
    std::string a = test::read_text(e.path().string());
    std::string b = test::read_text((t.path() / "out2" / rel).string());
    if (rel == "report.json") {
      const std::regex varying(R"(("command_line": "[^"\n]*")|("threads": [0-9]+)|)"
                               R"(("timings_s": \{[^}]*\}))");
      a = std::regex_replace(a, varying, "V");
      b = std::regex_replace(b, varying, "V");
    }
    INFO(rel.string());
    CHECK(a == b);
    ++compared;
  }
  CHECK(compared == 8);
}
#endif
