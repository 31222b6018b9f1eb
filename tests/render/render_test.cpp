// geodrift::render: determinism, geometry (projection, depth, ground), panorama/pinhole
// consistency, feature richness for ORB, dataset files read back through the repo's readers.
#include "geodrift/render/render.hpp"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/geo/kitti.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/render/dataset.hpp"
#include "geodrift/render/world.hpp"
#include "geodrift/sim/kitti_protocol.hpp"
#include "support/test_files.hpp"

namespace fs = std::filesystem;
using namespace geodrift;

namespace {

const std::string kPoses = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti/poses/02.txt";
const std::string kCalib = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti/calib_seq00-02.txt";
const std::string kTimes = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti/times/02.txt";

const sim::KittiSequence& sequence02() {
  static const sim::KittiSequence seq = sim::load_kitti_sequence(kPoses, kCalib, kTimes, "02");
  return seq;
}

/// The world around frames [first, last] of KITTI 02.
render::World world02(int first, int last, std::uint64_t seed = 1) {
  render::WorldOptions o;
  o.seed = seed;
  o.first_frame = first;
  o.last_frame = last;
  return render::World::from_kitti(sequence02().T_K_c, o);
}

Eigen::Vector3d camera_point(const lie::SE3d& T_cw, const Eigen::Vector3d& p_w) {
  return T_cw.rotation().matrix() * p_w + T_cw.translation();
}

bool identical(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

}  // namespace

TEST_CASE("render: the same seed gives bit-identical frames and panoramas, another seed not",
          "[render]") {
  const render::World w1 = world02(200, 230, 7), w1b = world02(200, 230, 7),
                      w2 = world02(200, 230, 8);
  const map::Camera cam = sequence02().camera;
  render::RenderOptions one, two;
  one.threads = 1;
  two.threads = 2;
  const cv::Mat a =
      render::render_pinhole(w1, w1.frame_T_cw(215), cam, render::Appearance::video(), one);
  const cv::Mat b =
      render::render_pinhole(w1b, w1b.frame_T_cw(215), cam, render::Appearance::video(), two);
  const cv::Mat c =
      render::render_pinhole(w2, w2.frame_T_cw(215), cam, render::Appearance::video(), two);
  REQUIRE(a.type() == CV_8UC1);
  REQUIRE(a.cols == 1241);
  REQUIRE(a.rows == 376);
  CHECK(identical(a, b));
  // Another seed: another street (buildings, cars), so most of the image changes.
  cv::Mat diff;
  cv::absdiff(a, c, diff);
  CHECK(cv::countNonZero(diff > 20) > static_cast<int>(a.total() / 5));
  // Panoramas, through PNG encoding too.
  render::PanoramaOptions po;
  po.width = 256;
  po.height = 128;
  const Eigen::Vector3d centre =
      w1.route_point(w1.frame_arclength(215)) + Eigen::Vector3d(0, 0, 0.85);
  const cv::Mat p1 =
      render::render_panorama(w1, centre, 0.3, render::Appearance::street_view(), po);
  const cv::Mat p2 =
      render::render_panorama(w1b, centre, 0.3, render::Appearance::street_view(), po);
  REQUIRE(p1.type() == CV_8UC3);
  CHECK(identical(p1, p2));
  std::vector<uchar> e1, e2;
  cv::imencode(".png", p1, e1);
  cv::imencode(".png", p2, e2);
  CHECK(e1 == e2);
}

TEST_CASE("render: building corners project where the renderer draws them", "[render]") {
  const int frame = 300;
  const render::World w = world02(frame - 20, frame + 20);
  const map::Camera cam = sequence02().camera;
  const lie::SE3d T_cw = w.frame_T_cw(frame);
  const render::Appearance app = render::Appearance::video();
  const cv::Mat depth = render::render_depth(w, T_cw, cam, app);
  const cv::Mat img = render::render_pinhole(w, T_cw, cam, app);
  int inside_checked = 0, edges_checked = 0;
  for (const render::BuildingInfo& b : w.buildings()) {
    const std::vector<Eigen::Vector3d> corners = b.corners();
    for (int k = 0; k < 4; ++k) {
      // A point on the vertical edge 2.5 m above the ground, and one 0.4 m inside the face
      // towards the next corner.
      const Eigen::Vector3d edge = corners[k] + Eigen::Vector3d(0, 0, 2.8);
      const Eigen::Vector3d next = corners[(k + 1) % 4] + Eigen::Vector3d(0, 0, 2.8);
      const Eigen::Vector3d inside = edge + 0.4 * (next - edge).normalized();
      const Eigen::Vector3d pc = camera_point(T_cw, inside);
      if (pc.z() < 4 || pc.z() > 45) continue;
      const Eigen::Vector2d uv = cam.project(pc);
      if (uv.x() < 5 || uv.y() < 5 || uv.x() > cam.width - 6 || uv.y() > cam.height - 6) continue;
      const float d = depth.at<float>(static_cast<int>(std::lround(uv.y())),
                                      static_cast<int>(std::lround(uv.x())));
      // Visible (not hidden by a tree, car, pole or another building) when the depth matches.
      if (!(std::abs(d - pc.z()) < 0.02 * pc.z() + 0.05)) continue;
      ++inside_checked;
      // The depth at the exact pixel of a point of the face (bilinear surroundings agree).
      INFO("corner point at " << uv.transpose() << " depth " << d << " expected " << pc.z());
      // The vertical edge itself: where the face starts, the depth (or face) changes.
      const Eigen::Vector3d ec = camera_point(T_cw, edge);
      const Eigen::Vector2d ue = cam.project(ec);
      if (ue.x() < 4 || ue.x() > cam.width - 5) continue;
      const int row = static_cast<int>(std::lround(ue.y()));
      const int col = static_cast<int>(std::lround(ue.x()));
      // Outside the face (beyond the edge, away from `inside`) the ray misses this face: depth
      // differs from the face plane by more than 0.5 m if the background is far.
      const int away = (cam.project(pc).x() > ue.x()) ? -1 : 1;
      const float d_out = depth.at<float>(row, col + 3 * away);
      if (!(std::abs(d_out - ec.z()) > 2.0)) continue;  // convex corner with its side face visible
      ++edges_checked;
      // The image has its strongest horizontal step within 1.5 px of the projected edge.
      int best_col = -1;
      double best = -1;
      for (int c = col - 4; c <= col + 4; ++c) {
        const double g =
            std::abs(static_cast<double>(img.at<uchar>(row, c + 1)) - img.at<uchar>(row, c - 1));
        if (g > best) {
          best = g;
          best_col = c;
        }
      }
      INFO("edge projected at u = " << ue.x() << ", strongest step at " << best_col << " (step "
                                    << best << ")");
      CHECK(std::abs(best_col - ue.x()) <= 1.5);
      // Depth continuity on the face side: 2 px inside, the depth is that of the face.
      const float d_in = depth.at<float>(row, col - 2 * away);
      CHECK(std::abs(d_in - ec.z()) < 0.05 * ec.z());
    }
  }
  INFO("points checked: " << inside_checked << ", edges: " << edges_checked);
  CHECK(inside_checked >= 4);
  CHECK(edges_checked >= 1);
}

TEST_CASE("render: the ground is 1.65 m below the camera and depth agrees with the pose",
          "[render]") {
  const render::World w = world02(0, 400);
  const map::Camera cam = sequence02().camera;
  for (int frame : {0, 150, 390}) {
    const lie::SE3d T_cw = w.frame_T_cw(frame);
    const Eigen::Matrix3d R_wc = T_cw.rotation().matrix().transpose();
    const Eigen::Vector3d c = -(R_wc * T_cw.translation());
    CHECK(c.z() - w.ground_height(c.x(), c.y()) == Approx(1.65).margin(0.01));
    const cv::Mat depth = render::render_depth(w, T_cw, cam, render::Appearance::video());
    // Bottom rows near the centre see the road: the 3D point of the depth lies on the ground.
    int checked = 0;
    for (int row : {300, 340, 370})
      for (int col : {560, 607, 660}) {
        const double z = depth.at<float>(row, col);
        const Eigen::Vector3d ray((col - cam.cx) / cam.fx, (row - cam.cy) / cam.fy, 1.0);
        const Eigen::Vector3d p = c + R_wc * (z * ray);
        const render::RayHit h = w.trace(c, R_wc * ray.normalized(), render::Appearance::video());
        INFO("hit kind " << static_cast<int>(h.kind) << " at " << h.t);
        if (h.kind != render::SurfaceKind::kGround) continue;
        ++checked;
        INFO("frame " << frame << " pixel (" << col << ", " << row << ") depth " << z);
        CHECK(p.z() == Approx(w.ground_height(p.x(), p.y())).margin(0.005));
        // The world's ground is the route's height (minus 1.65 m) at the nearest route point:
        // along the central rays that is the route ahead, so the depth solves
        // c_z + t·d_z = z_route(s + t·(d_xy · tangent)) - 1.65 (fixed-point iteration, an
        // independent computation from the public route geometry).
        const Eigen::Vector3d dw = R_wc * ray.normalized();
        const double s = w.nearest_route_point(c.x(), c.y()).s;
        const double along = dw.head<2>().dot(w.route_tangent(s));
        double t_route = 1.65 / -dw.z();
        for (int it = 0; it < 50; ++it)
          t_route = (w.route_point(s + t_route * along).z() - 1.65 - c.z()) / dw.z();
        CHECK(z == Approx(t_route / ray.norm()).epsilon(0.01));
      }
    INFO("frame " << frame);
    CHECK(checked >= 6);
  }
}

TEST_CASE("render: a panorama pixel equals the pinhole render of its direction", "[render]") {
  const render::World w = world02(500, 560, 3);
  const render::Appearance app = render::Appearance::street_view();
  const std::vector<render::PanoramaSite> sites = render::panorama_sites(w, 500, 560, 20.0);
  REQUIRE(sites.size() >= 2);
  const render::PanoramaSite& site = sites[1];
  render::PanoramaOptions po;
  po.width = 512;
  po.height = 256;
  po.render.antialias = render::Antialias::kNone;
  const cv::Mat pano = render::render_panorama(w, site.centre, site.heading, app, po);
  const double gamma = w.local_frame().meridian_convergence(site.centre);

  SECTION("single rays: a 1x1 pinhole along a pixel's direction sees the same colour") {
    std::mt19937 rng(42);
    std::uniform_int_distribution<int> col(0, po.width - 1), row(20, po.height - 21);
    int same = 0, n = 300;
    for (int i = 0; i < n; ++i) {
      const int u = col(rng), v = row(rng);
      const Eigen::Vector3d d =
          render::panorama_direction(u + 0.5, v + 0.5, po.width, po.height, site.heading, gamma);
      // Camera whose optical axis is d (any roll), focal length = the panorama's px/rad.
      const Eigen::Vector3d z = d;
      const Eigen::Vector3d x = Eigen::Vector3d::UnitZ().cross(z).normalized();
      const Eigen::Vector3d y = z.cross(x);
      Eigen::Matrix3d R_wc;
      R_wc << x, y, z;
      const lie::SE3d T_cw(lie::SO3d(Eigen::Matrix3d(R_wc.transpose())),
                           -(R_wc.transpose() * site.centre));
      map::Camera cam;
      cam.fx = cam.fy = po.width / (2 * M_PI);
      cam.cx = cam.cy = 0;
      cam.width = cam.height = 1;
      render::RenderOptions ro;
      ro.color = true;
      ro.antialias = render::Antialias::kNone;
      const cv::Mat px = render::render_pinhole(w, T_cw, cam, app, ro);
      const cv::Vec3b a = px.at<cv::Vec3b>(0, 0), b = pano.at<cv::Vec3b>(v, u);
      const int diff =
          std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
      if (diff <= 1) ++same;
    }
    CHECK(same >= 0.98 * n);
  }

  SECTION("a view cut from the panorama matches the pinhole view of that direction") {
    // Level camera looking 90 deg right of the heading, with the panorama's angular resolution.
    const double heading = site.heading + M_PI / 2;
    const Eigen::Matrix3d R_wc =
        w.local_frame().level_camera_rotation_from_heading(heading, site.centre);
    const lie::SE3d T_cw(lie::SO3d(Eigen::Matrix3d(R_wc.transpose())),
                         -(R_wc.transpose() * site.centre));
    map::Camera cam;
    cam.fx = cam.fy = po.width / (2 * M_PI);
    cam.width = 60;
    cam.height = 50;
    cam.cx = 29.5;
    cam.cy = 24.5;
    render::RenderOptions ro;
    ro.color = true;
    ro.antialias = render::Antialias::kNone;
    const cv::Mat view = render::render_pinhole(w, T_cw, cam, app, ro);
    std::vector<double> diffs;
    for (int r = 0; r < cam.height; ++r)
      for (int c = 0; c < cam.width; ++c) {
        const Eigen::Vector3d ray((c - cam.cx) / cam.fx, (r - cam.cy) / cam.fy, 1.0);
        const Eigen::Vector2d uv =
            render::panorama_pixel(R_wc * ray, po.width, po.height, site.heading, gamma);
        // Bilinear sample of the panorama (pixel centres at +0.5).
        const double x = uv.x() - 0.5, y = uv.y() - 0.5;
        const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
        const double ax = x - x0, ay = y - y0;
        double s = 0, p = 0;
        for (int ch = 0; ch < 3; ++ch) {
          auto at = [&](int yy, int xx) {
            return static_cast<double>(pano.at<cv::Vec3b>(yy, (xx + po.width) % po.width)[ch]);
          };
          s = (1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x0 + 1)) +
              ay * ((1 - ax) * at(y0 + 1, x0) + ax * at(y0 + 1, x0 + 1));
          p += std::abs(s - view.at<cv::Vec3b>(r, c)[ch]) / 3.0;
        }
        diffs.push_back(p);
      }
    std::sort(diffs.begin(), diffs.end());
    const double median = diffs[diffs.size() / 2], p90 = diffs[diffs.size() * 9 / 10];
    INFO("median |diff| " << median << ", 90th percentile " << p90);
    CHECK(median <= 4.0);
    CHECK(p90 <= 25.0);
  }
}

TEST_CASE("render: ORB finds many well-spread features that match along the ground truth",
          "[render]") {
  const render::World w = world02(880, 940);
  const map::Camera cam = sequence02().camera;
  const render::Appearance app = render::Appearance::video();
  auto orb = cv::ORB::create(3000);
  const int f0 = 900, f1 = 902;
  const cv::Mat i0 = render::render_pinhole(w, w.frame_T_cw(f0), cam, app);
  const cv::Mat i1 = render::render_pinhole(w, w.frame_T_cw(f1), cam, app);
  std::vector<cv::KeyPoint> k0, k1;
  cv::Mat d0, d1;
  orb->detectAndCompute(i0, cv::noArray(), k0, d0);
  orb->detectAndCompute(i1, cv::noArray(), k1, d1);
  INFO("ORB keypoints " << k0.size() << ", " << k1.size());
  CHECK(k0.size() >= 2000);
  // Spread: 8 x 4 grid over the image, at least 24 cells with >= 10 features.
  int cells[4][8] = {};
  for (const auto& k : k0)
    ++cells[std::min(3, static_cast<int>(k.pt.y * 4 / cam.height))]
           [std::min(7, static_cast<int>(k.pt.x * 8 / cam.width))];
  int good = 0;
  for (auto& row : cells)
    for (int c : row) good += c >= 10;
  CHECK(good >= 24);
  // Matches between frames 900 and 902 obey the true epipolar geometry to about a pixel.
  cv::BFMatcher bf(cv::NORM_HAMMING);
  std::vector<std::vector<cv::DMatch>> knn;
  bf.knnMatch(d0, d1, knn, 2);
  const lie::SE3d T_10 = w.frame_T_cw(f1) * w.frame_T_cw(f0).inverse();
  const Eigen::Matrix3d R = T_10.rotation().matrix();
  const Eigen::Vector3d t = T_10.translation();
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  Eigen::Matrix3d K;
  K << cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1;
  const Eigen::Matrix3d F = K.inverse().transpose() * tx * R * K.inverse();
  int n = 0, inl = 0, gross = 0;
  for (const auto& m : knn) {
    if (m.size() < 2 || m[0].distance > 0.8 * m[1].distance) continue;
    const cv::Point2f a = k0[m[0].queryIdx].pt, b = k1[m[0].trainIdx].pt;
    const Eigen::Vector3d l = F * Eigen::Vector3d(a.x, a.y, 1);
    const double e = std::abs(l.dot(Eigen::Vector3d(b.x, b.y, 1))) / l.head<2>().norm();
    // ORB keypoints of pyramid level L are located to about 1.2^L pixels.
    const double scale = std::pow(1.2, k0[m[0].queryIdx].octave);
    ++n;
    inl += e < 1.5 * scale;
    gross += e > 10.0;
  }
  INFO("ratio-test matches " << n << ", within 1.5 px x level scale of the epipolar line " << inl
                             << ", more than 10 px off " << gross);
  CHECK(n >= 800);
  CHECK(inl >= 0.9 * n);
  CHECK(gross <= 0.05 * n);
}

TEST_CASE("render: a dataset folder reads back through the repo's readers", "[render]") {
  test::TempDir t1, t2;
  render::DatasetOptions o;
  o.poses_path = kPoses;
  o.calib_path = kCalib;
  o.times_path = kTimes;
  o.first = 40;
  o.last = 47;
  o.seed = 5;
  o.panorama_spacing_m = 3.0;
  o.panorama_width = 128;
  o.panorama_height = 64;
  const render::DatasetSummary s = render::write_dataset(o, t1.path().string());
  CHECK(s.frames == 8);
  CHECK(s.panoramas >= 2);
  const std::string d = t1.path().string();
  // Ground truth, calibration and times through sim::load_kitti_sequence (io::read_trajectory).
  const sim::KittiSequence back =
      sim::load_kitti_sequence(d + "/poses.txt", d + "/calib.txt", d + "/times.txt");
  REQUIRE(back.num_frames() == 8);
  const sim::KittiSequence& seq = sequence02();
  for (int i = 0; i < 8; ++i) {
    CHECK((back.T_K_c[i].matrix() - seq.T_K_c[40 + i].matrix()).cwiseAbs().maxCoeff() < 1e-9);
    CHECK(back.timestamps[i] == seq.timestamps[40 + i]);
  }
  CHECK(back.camera.fx == seq.camera.fx);
  CHECK(back.camera.cx == seq.camera.cx);
  CHECK(back.camera.cy == seq.camera.cy);
  CHECK(back.baseline_m == Approx(seq.baseline_m).epsilon(1e-12));
  // Frames.
  for (int i = 0; i < 8; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "/image_0/%06d.png", i);
    const cv::Mat img = cv::imread(d + name, cv::IMREAD_UNCHANGED);
    REQUIRE(!img.empty());
    CHECK(img.type() == CV_8UC1);
    CHECK(img.cols == 1241);
    CHECK(img.rows == 376);
  }
  // Geo-tags: header, positions through the assumed KITTI origin, headings, frames, files.
  std::ifstream csv(d + "/geotags.csv");
  std::string line;
  std::getline(csv, line);
  CHECK(line.rfind("# geodrift", 0) == 0);
  std::getline(csv, line);
  CHECK(line == "id,file,latitude,longitude,height,heading_deg,x,y,z,frame");
  const geo::LocalFrame lf = geo::kitti_local_frame();
  const render::World w = render::World::from_kitti(seq.T_K_c, {5, 40, 47, 150.0, 1.65});
  int rows = 0;
  while (std::getline(csv, line)) {
    std::stringstream ss(line);
    std::vector<std::string> f;
    std::string tok;
    while (std::getline(ss, tok, ',')) f.push_back(tok);
    REQUIRE(f.size() == 10);
    CHECK(std::stoi(f[0]) == rows);
    const cv::Mat pano = cv::imread(d + "/" + f[1], cv::IMREAD_UNCHANGED);
    REQUIRE(!pano.empty());
    CHECK(pano.type() == CV_8UC3);
    CHECK(pano.cols == 128);
    const Eigen::Vector3d xyz(std::stod(f[6]), std::stod(f[7]), std::stod(f[8]));
    const Eigen::Vector3d from_ll = lf.to_world(std::stod(f[2]), std::stod(f[3]), std::stod(f[4]));
    CHECK((from_ll - xyz).norm() < 2e-3);
    // 2.5 m above the ground, on the route, 3 m apart, heading = direction of travel.
    CHECK(xyz.z() - w.ground_height(xyz.x(), xyz.y()) == Approx(2.5).margin(0.01));
    const render::RoutePoint rp = w.nearest_route_point(xyz.x(), xyz.y());
    CHECK(std::abs(rp.d) < 0.01);
    CHECK(rp.s == Approx(w.frame_arclength(40) + 3.0 * rows).margin(0.01));
    const double yaw = std::atan2(rp.tangent.y(), rp.tangent.x());
    const double heading = lf.heading_from_grid_yaw(yaw, xyz);
    CHECK(std::abs(std::remainder(heading - std::stod(f[5]) * M_PI / 180, 2 * M_PI)) < 0.03);
    const int frame = std::stoi(f[9]);
    CHECK(frame >= 0);
    CHECK(frame < 8);
    CHECK(std::abs(w.frame_arclength(40 + frame) - rp.s) < 1.5);
    ++rows;
  }
  CHECK(rows == s.panoramas);
  // Deterministic: a second run writes the same bytes.
  render::write_dataset(o, t2.path().string());
  for (const char* f : {"/calib.txt", "/times.txt", "/poses.txt", "/geotags.csv", "/dataset.json",
                        "/image_0/000005.png", "/panoramas/pano_000001.png"})
    CHECK(test::read_text(d + f) == test::read_text(t2.path().string() + f));
}

TEST_CASE("render: bad inputs are rejected with a message naming the problem", "[render]") {
  test::TempDir t;
  render::DatasetOptions o;
  o.poses_path = kPoses;
  o.calib_path = kCalib;
  o.first = 0;
  o.last = 3;
  o.panorama_spacing_m = 0;
  auto fails_with = [&](const render::DatasetOptions& opt, const std::string& what) {
    try {
      render::write_dataset(opt, t.path().string());
      FAIL("no exception; expected one mentioning '" << what << "'");
    } catch (const Error& e) {
      INFO(e.what());
      CHECK(std::string(e.what()).find(what) != std::string::npos);
    }
  };
  {
    render::DatasetOptions b = o;
    b.poses_path = t.file("missing.txt");
    fails_with(b, "missing.txt");
  }
  {
    render::DatasetOptions b = o;
    b.last = 100000;
    fails_with(b, "--last 100000");
  }
  {
    render::DatasetOptions b = o;
    b.first = 5;
    b.last = 2;
    fails_with(b, "--last 2");
  }
  {
    test::write_text(t.file("bad_calib.txt"), "P0: 1 2 3\nP1: 1 0 0 -1 0 1 0 0 0 0 1 0\n");
    render::DatasetOptions b = o;
    b.calib_path = t.file("bad_calib.txt");
    fails_with(b, "expected 12");
  }
  {
    test::write_text(t.file("bad_poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 nan\n");
    render::DatasetOptions b = o;
    b.poses_path = t.file("bad_poses.txt");
    fails_with(b, "bad_poses.txt");
  }
  CHECK_THROWS_AS(render::World(std::vector<Eigen::Isometry3d>(1, Eigen::Isometry3d::Identity()),
                                render::WorldOptions{}),
                  InvalidArgument);
}
