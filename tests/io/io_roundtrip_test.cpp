// Round trips of every io/ format, plus known-answer checks of each format's conventions.

#include <sys/resource.h>

#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "geodrift/geo/kitti.hpp"
#include "geodrift/geo/local_frame.hpp"
#include "geodrift/io/anchors.hpp"
#include "geodrift/io/colmap_text.hpp"
#include "geodrift/io/csv.hpp"
#include "geodrift/io/geojson.hpp"
#include "geodrift/io/kml.hpp"
#include "geodrift/io/ply.hpp"
#include "geodrift/io/svg.hpp"
#include "geodrift/io/trajectory.hpp"
#include "geodrift/io/trajectory_jumps.hpp"
#include "geodrift/version.hpp"
#include "support/test_files.hpp"

namespace io = geodrift::io;
namespace geo = geodrift::geo;
namespace lie = geodrift::lie;
using geodrift::test::pose_distance;
using geodrift::test::random_pose;
using geodrift::test::read_text;
using geodrift::test::TempDir;
using geodrift::test::write_text;

namespace {

constexpr double kPi = 3.14159265358979323846;

const std::string kVersionTag = std::string("geodrift ") + geodrift::kVersion;

// All numbers in a string, in order (a hand scanner: GCC 12's std::regex trips
// -Wmaybe-uninitialized under the sanitizer build).
std::vector<double> numbers_in(const std::string& s) {
  std::vector<double> out;
  const char* p = s.c_str();
  while (*p) {
    const bool starts =
        std::isdigit(static_cast<unsigned char>(*p)) ||
        ((*p == '-' || *p == '+' || *p == '.') && std::isdigit(static_cast<unsigned char>(p[1])));
    if (!starts) {
      ++p;
      continue;
    }
    char* end = nullptr;
    out.push_back(std::strtod(p, &end));
    p = end;
  }
  return out;
}

int count_of(const std::string& s, const std::string& what) {
  int n = 0;
  for (std::size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + 1)) ++n;
  return n;
}

io::Trajectory random_trajectory(std::mt19937& rng, int n, bool timestamps) {
  io::Trajectory t;
  double time = 1305031102.175304;
  for (int i = 0; i < n; ++i) {
    io::TrajectoryPose p;
    p.frame = 3 * i + 7;
    if (timestamps) p.timestamp = (time += 0.0333);
    p.T_cw = random_pose(rng, 1000.0);
    t.poses.push_back(p);
  }
  return t;
}

}  // namespace

TEST_CASE("KITTI trajectories round trip, with and without frame index", "[io][trajectory]") {
  TempDir dir;
  std::mt19937 rng(42);
  const io::Trajectory t = random_trajectory(rng, 50, false);
  for (const bool with_index : {false, true}) {
    const std::string path = dir.file(with_index ? "k13.txt" : "k12.txt");
    io::write_trajectory_kitti(path, t, "test frame", with_index);
    const std::string text = read_text(path);
    CHECK(text.rfind("# " + kVersionTag + " KITTI trajectory: camera-to-world", 0) == 0);
    CHECK(text.find("test frame") != std::string::npos);
    CHECK(text.find("metres") != std::string::npos);
    for (const io::TrajectoryFormat f :
         {io::TrajectoryFormat::kAuto, io::TrajectoryFormat::kKitti}) {
      const io::Trajectory r = io::read_trajectory(path, f);
      CHECK(r.format == io::TrajectoryFormat::kKitti);
      CHECK(r.has_frame_index == with_index);
      CHECK_FALSE(r.has_timestamps);
      REQUIRE(r.poses.size() == t.poses.size());
      for (std::size_t i = 0; i < t.poses.size(); ++i) {
        INFO("pose " << i);
        CHECK(pose_distance(r.poses[i].T_cw, t.poses[i].T_cw) < 1e-9);
        CHECK(r.poses[i].frame == (with_index ? t.poses[i].frame : static_cast<int>(i)));
        CHECK(r.poses[i].line == static_cast<int>(i) + 2);  // after the header line
        CHECK(std::isnan(r.poses[i].timestamp));
      }
    }
  }
}

TEST_CASE("KITTI lines are camera-to-world and become T_cw", "[io][trajectory]") {
  TempDir dir;
  const std::string path = dir.file("kitti.txt");
  // Camera 0 at the origin; camera 1 at (1, 2, 3) rotated 90° about y (optical axis -> +x).
  write_text(path,
             "1 0 0 0 0 1 0 0 0 0 1 0\n"
             "\n"
             "0 0 1 1 0 1 0 2 -1 0 0 3\n");
  const io::Trajectory t = io::read_trajectory(path);
  REQUIRE(t.poses.size() == 2);
  CHECK(t.poses[1].line == 3);
  const lie::SE3d T_wc = t.poses[1].T_cw.inverse();
  CHECK((T_wc.translation() - Eigen::Vector3d(1, 2, 3)).norm() < 1e-15);
  // T_cw maps the camera centre to the camera origin.
  CHECK(t.poses[1].T_cw.act(Eigen::Vector3d(1, 2, 3)).norm() < 1e-15);
  // The camera's optical axis (0,0,1) in the world is +x.
  CHECK((T_wc.rotation().act(Eigen::Vector3d::UnitZ()) - Eigen::Vector3d::UnitX()).norm() < 1e-15);
}

TEST_CASE("TUM trajectories round trip and use qx qy qz qw order", "[io][trajectory]") {
  TempDir dir;
  std::mt19937 rng(42);
  const io::Trajectory t = random_trajectory(rng, 40, true);
  const std::string path = dir.file("tum.txt");
  io::write_trajectory_tum(path, t, "W test");
  CHECK(read_text(path).rfind("# " + kVersionTag + " TUM trajectory", 0) == 0);
  for (const io::TrajectoryFormat f : {io::TrajectoryFormat::kAuto, io::TrajectoryFormat::kTum}) {
    const io::Trajectory r = io::read_trajectory(path, f);
    CHECK(r.format == io::TrajectoryFormat::kTum);
    CHECK(r.has_timestamps);
    REQUIRE(r.poses.size() == t.poses.size());
    for (std::size_t i = 0; i < t.poses.size(); ++i) {
      INFO("pose " << i);
      CHECK(pose_distance(r.poses[i].T_cw, t.poses[i].T_cw) < 1e-9);
      CHECK(r.poses[i].timestamp == t.poses[i].timestamp);  // shortest round trip: exact
      CHECK(r.poses[i].frame == static_cast<int>(i));
    }
  }

  // Known answer: 90° about z is (qx qy qz qw) = (0 0 sin45 cos45).
  const std::string known = dir.file("known_tum.txt");
  const double s = std::sqrt(0.5);
  write_text(known,
             "# comment\n0.5 1 2 3 0 0 " + std::to_string(s) + " " + std::to_string(s) + "\n");
  const io::Trajectory k = io::read_trajectory(known);
  const Eigen::Matrix3d R_wc = k.poses[0].T_cw.inverse().rotation().matrix();
  CHECK((R_wc * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm() < 1e-6);
  CHECK(k.poses[0].timestamp == 0.5);
  CHECK(k.poses[0].line == 2);

  // Without timestamps (KITTI source) the frame indices are written as timestamps.
  const io::Trajectory no_time = random_trajectory(rng, 5, false);
  const std::string p2 = dir.file("tum_from_kitti.txt");
  io::write_trajectory_tum(p2, no_time, "W");
  CHECK(read_text(p2).find("timestamps are frame indices") != std::string::npos);
  const io::Trajectory r2 = io::read_trajectory(p2);
  for (std::size_t i = 0; i < no_time.poses.size(); ++i)
    CHECK(r2.poses[i].timestamp == no_time.poses[i].frame);
}

TEST_CASE("Trajectory formats parse from their --format names", "[io][trajectory]") {
  CHECK(io::parse_trajectory_format("kitti") == io::TrajectoryFormat::kKitti);
  CHECK(io::parse_trajectory_format("tum") == io::TrajectoryFormat::kTum);
  CHECK(io::parse_trajectory_format("auto") == io::TrajectoryFormat::kAuto);
  CHECK_THROWS_AS(io::parse_trajectory_format("euroc"), geodrift::InvalidArgument);
}

TEST_CASE("Anchors CSV round trips and every position form lands on the same W point",
          "[io][anchors]") {
  TempDir dir;
  const geo::LocalFrame frame = geo::kitti_local_frame();
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-3000.0, 3000.0);
  std::vector<io::Anchor> anchors;
  for (int i = 0; i < 20; ++i) {
    io::Anchor a;
    a.frame = 50 * (i + 1);
    a.timestamp = 0.1 * a.frame;
    a.y_w = Eigen::Vector3d(u(rng), u(rng), 0.01 * u(rng));
    a.sigma_m = i % 3 == 0 ? std::nan("") : 0.05 * (i + 1);
    a.heading = i % 4 == 0 ? std::nan("") : 0.3 * i;
    anchors.push_back(a);
  }
  const std::string path = dir.file("anchors.csv");
  io::write_anchors_csv(path, anchors, frame);
  CHECK(read_text(path).rfind("# " + kVersionTag + " anchors", 0) == 0);
  const io::AnchorTable table = io::read_anchors_csv(path);
  CHECK(table.kind == io::AnchorPositionKind::kGeodetic);
  CHECK(table.has_frame);
  CHECK(table.has_timestamp);
  const std::vector<io::Anchor> back = io::anchors_in_world(table, frame);
  REQUIRE(back.size() == anchors.size());
  for (std::size_t i = 0; i < anchors.size(); ++i) {
    INFO("anchor " << i);
    CHECK((back[i].y_w - anchors[i].y_w).norm() < 1e-6);
    CHECK(back[i].frame == anchors[i].frame);
    CHECK(back[i].timestamp == anchors[i].timestamp);
    CHECK(back[i].line == static_cast<int>(i) + 3);
    CHECK(std::isnan(back[i].sigma_m) == std::isnan(anchors[i].sigma_m));
    if (!std::isnan(anchors[i].sigma_m)) CHECK(back[i].sigma_m == Approx(anchors[i].sigma_m));
    CHECK(std::isnan(back[i].heading) == std::isnan(anchors[i].heading));
    if (!std::isnan(anchors[i].heading))
      CHECK(back[i].heading == Approx(anchors[i].heading).margin(1e-12));
  }

  // The same first anchor written as UTM (its own standard zone: 32N here), UTM of the
  // neighbouring zone 33N, and W x,y,z.
  const geo::Geodetic g = frame.to_geodetic(anchors[0].y_w);
  const geo::UtmCoordinate u32 = geo::geodetic_to_utm(g);
  const geo::UtmCoordinate u33 = geo::geodetic_to_utm(g, 33);
  const std::string utm_path = dir.file("utm.csv");
  write_text(utm_path, "timestamp, easting, northing, zone, height, heading_deg\n" +
                           io::detail::fmt(5.0) + "," + io::detail::fmt(u32.easting) + "," +
                           io::detail::fmt(u32.northing) + ",32N," + io::detail::fmt(g.height) +
                           ",90\n" + "6," + io::detail::fmt(u33.easting) + "," +
                           io::detail::fmt(u33.northing) + ",33n," + io::detail::fmt(g.height) +
                           ",\n");
  const io::AnchorTable ut = io::read_anchors_csv(utm_path);
  CHECK(ut.kind == io::AnchorPositionKind::kUtm);
  CHECK_FALSE(ut.has_frame);
  const std::vector<io::Anchor> ua = io::anchors_in_world(ut, frame);
  CHECK((ua[0].y_w - anchors[0].y_w).norm() < 1e-3);
  CHECK((ua[1].y_w - anchors[0].y_w).norm() < 1e-3);
  CHECK(ua[0].frame == -1);
  CHECK(ua[0].heading == Approx(kPi / 2));
  CHECK(std::isnan(ua[1].heading));
  // A frame at the first anchor has it at W's origin.
  const geo::LocalFrame f0 = io::local_frame_at_first_anchor(ut);
  CHECK(f0.zone_string() == "32N");
  CHECK(io::anchors_in_world(ut, f0)[0].y_w.norm() < 1e-9);

  const std::string xyz_path = dir.file("xyz.csv");
  write_text(xyz_path, "# W anchors\nframe,x,y,z,sigma_m\n10,1.5,-2.5,3,0.2\n");
  const std::vector<io::Anchor> xa = io::read_anchors(xyz_path, frame);
  REQUIRE(xa.size() == 1);
  CHECK(xa[0].y_w == Eigen::Vector3d(1.5, -2.5, 3.0));
  CHECK(xa[0].frame == 10);
  CHECK(xa[0].sigma_m == 0.2);
  CHECK(xa[0].line == 3);
  CHECK_THROWS_AS(io::local_frame_at_first_anchor(io::read_anchors_csv(xyz_path)),
                  geodrift::InvalidArgument);

  // A spreadsheet export: UTF-8 byte-order mark and CRLF line ends read as the same anchors.
  const std::string bom_path = dir.file("bom.csv");
  write_text(bom_path,
             "\xEF\xBB\xBF"
             "frame,x,y,z,sigma_m\r\n10,1.5,-2.5,3,0.2\r\n");
  const std::vector<io::Anchor> ba = io::read_anchors(bom_path, frame);
  REQUIRE(ba.size() == 1);
  CHECK(ba[0].y_w == Eigen::Vector3d(1.5, -2.5, 3.0));
  CHECK(ba[0].frame == 10);
  CHECK(ba[0].sigma_m == 0.2);
}

TEST_CASE("COLMAP text models round trip through map::Map", "[io][colmap]") {
  TempDir dir;
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> px(0.0, 1200.0);
  geodrift::map::Map m;
  m.cameras.push_back({1, 718.856, 718.856, 607.1928, 185.2157, 1241, 376});
  m.cameras.push_back({7, 500.0, 510.0, 320.5, 240.25, 640, 480});
  for (int i = 0; i < 6; ++i) {
    geodrift::map::Keyframe k;
    k.id = 100 + i;
    k.frame_index = 3 * i;
    k.T_cw = random_pose(rng, 50.0);
    k.camera_id = i % 2 ? 7 : 1;
    m.keyframes.push_back(k);
  }
  for (int j = 0; j < 30; ++j) {
    geodrift::map::MapPoint p;
    p.id = 1000 + j;
    p.position = random_pose(rng, 20.0).translation();
    // Seen by keyframes j%6 .. j%6+2 (clipped): reference = the earliest.
    const int first = j % 4;
    p.reference_keyframe = 100 + first;
    m.points.push_back(p);
    for (int k = first; k < first + 3; ++k)
      m.observations.push_back({100 + k, 1000 + j, Eigen::Vector2d(px(rng), px(rng) * 0.3)});
  }
  io::write_colmap_text(dir.path().string(), m, "M (test)");
  for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"})
    CHECK(read_text(dir.file(f)).rfind("# " + kVersionTag + " COLMAP text model", 0) == 0);
  const io::ColmapModel r = io::read_colmap_text(dir.path().string());
  REQUIRE(r.map.cameras.size() == 2);
  CHECK(r.map.cameras[1].id == 7);
  CHECK(r.map.cameras[1].fy == 510.0);
  CHECK(r.map.cameras[1].cy == 240.25);
  CHECK(r.map.cameras[0].width == 1241);
  REQUIRE(r.map.keyframes.size() == m.keyframes.size());
  for (std::size_t i = 0; i < m.keyframes.size(); ++i) {
    INFO("keyframe " << i);
    CHECK(r.map.keyframes[i].id == m.keyframes[i].id);
    CHECK(r.map.keyframes[i].frame_index == m.keyframes[i].frame_index);  // from "%06d.png"
    CHECK(r.map.keyframes[i].camera_id == m.keyframes[i].camera_id);
    CHECK(pose_distance(r.map.keyframes[i].T_cw, m.keyframes[i].T_cw) < 1e-12);
  }
  REQUIRE(r.map.points.size() == m.points.size());
  for (std::size_t j = 0; j < m.points.size(); ++j) {
    CHECK(r.map.points[j].id == m.points[j].id);
    CHECK(r.map.points[j].position == m.points[j].position);
    CHECK(r.map.points[j].reference_keyframe == m.points[j].reference_keyframe);
  }
  REQUIRE(r.map.observations.size() == m.observations.size());
  std::set<std::tuple<int, int, double, double>> a, b;
  for (const auto& o : m.observations) a.insert({o.keyframe, o.point, o.pixel.x(), o.pixel.y()});
  for (const auto& o : r.map.observations)
    b.insert({o.keyframe, o.point, o.pixel.x(), o.pixel.y()});
  CHECK(a == b);
  CHECK_NOTHROW(r.map.validate());
}

TEST_CASE("COLMAP reader takes distortion-free OPENCV/SIMPLE_PINHOLE cameras and names",
          "[io][colmap]") {
  TempDir dir;
  write_text(dir.file("cameras.txt"),
             "# Camera list\n1 SIMPLE_PINHOLE 640 480 500 320 240\n"
             "2 OPENCV 640 480 500 501 320 240 0 0 0 0\n");
  // Image 5 has no points (empty POINTS2D line); TUM-style names give timestamps.
  write_text(dir.file("images.txt"),
             "# Image list\n"
             "5 1 0 0 0 0 0 0 1 rgb/1305031102.275304.png\n"
             "\n"
             "3 1 0 0 0 1 2 3 2 rgb/1305031102.175304.png\n"
             "10 20 42 30.5 40.5 -1\n");
  write_text(dir.file("points3D.txt"), "42 1 2 3 255 0 10 0.5 3 0\n");
  const io::ColmapModel r = io::read_colmap_text(dir.path().string());
  REQUIRE(r.map.cameras.size() == 2);
  CHECK(r.map.cameras[0].fx == 500.0);
  CHECK(r.map.cameras[0].fy == 500.0);
  CHECK(r.map.cameras[0].cx == 320.0);
  CHECK(r.map.cameras[1].fy == 501.0);
  REQUIRE(r.map.keyframes.size() == 2);
  // Sorted by time: image 3 first.
  CHECK(r.map.keyframes[0].id == 3);
  CHECK(r.map.keyframes[0].timestamp == Approx(1305031102.175304));
  CHECK(r.map.keyframes[0].frame_index == 0);
  CHECK(r.map.keyframes[1].frame_index == 1);
  CHECK(r.image_names[0] == "rgb/1305031102.175304.png");
  CHECK((r.map.keyframes[0].T_cw.translation() - Eigen::Vector3d(1, 2, 3)).norm() == 0.0);
  REQUIRE(r.map.observations.size() == 1);
  CHECK(r.map.observations[0].keyframe == 3);
  CHECK(r.map.observations[0].pixel == Eigen::Vector2d(10, 20));
  CHECK(r.map.points[0].reference_keyframe == 3);
  CHECK(r.point_colors[0][0] == 255);
  CHECK(r.point_colors[0][2] == 10);
  CHECK(r.point_errors[0] == 0.5);

  long long frame = 0;
  double t = 0;
  io::detail::frame_from_image_name("seq/frame_000123.png", &frame, &t);
  CHECK(frame == 123);
  CHECK(std::isnan(t));
  io::detail::frame_from_image_name("cam.jpg", &frame, &t);
  CHECK(frame == -1);
}

TEST_CASE("trajectory.csv round trips with UTM, latitude/longitude and heading", "[io][csv]") {
  TempDir dir;
  const geo::LocalFrame frame = geo::kitti_local_frame();
  std::vector<io::TrajectoryCsvRow> rows;
  for (int i = 0; i < 30; ++i) {
    io::TrajectoryCsvRow r;
    r.frame = i;
    r.timestamp = i % 5 == 4 ? std::nan("") : 0.1 * i;
    r.keyframe = i % 3 == 0;
    r.after_last_anchor = i > 25;
    const Eigen::Vector3d c(10.0 * i, 50.0 * i - 400.0, 0.5 * i);
    const double heading = 0.2 * i;  // true heading of a level camera
    const Eigen::Matrix3d R_wc = frame.level_camera_rotation_from_heading(heading, c);
    r.T_cw = lie::SE3d(lie::SO3d(Eigen::Matrix3d(R_wc)), c).inverse();
    if (i % 4 != 3)  // some rows without an uncertainty estimate
      r.cov_en << 0.04 * (i + 1), 0.01 * i, 0.01 * i, 0.09 * (i + 1);
    rows.push_back(r);
  }
  const std::string path = dir.file("trajectory.csv");
  io::write_trajectory_csv(path, rows, frame, geo::kKittiGeoOriginNote);
  const std::string text = read_text(path);
  CHECK(text.rfind("# " + kVersionTag + " trajectory: x,y,z camera centre in W = UTM 32N", 0) == 0);
  CHECK(text.find("ASSUMPTION") != std::string::npos);
  const std::vector<io::TrajectoryCsvRecord> back = io::read_trajectory_csv(path);
  REQUIRE(back.size() == rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    INFO("row " << i);
    const Eigen::Vector3d c = rows[i].T_cw.inverse().translation();
    CHECK((back[i].p_w - c).norm() < 1e-5);
    const geo::UtmCoordinate u = frame.utm_of(c);
    CHECK(back[i].easting == Approx(u.easting).margin(1e-5));
    CHECK(back[i].northing == Approx(u.northing).margin(1e-5));
    CHECK(back[i].zone == "32N");
    const geo::Geodetic g = frame.to_geodetic(c);
    CHECK(back[i].latitude_deg == Approx(g.latitude_deg).margin(1e-9));
    CHECK(back[i].longitude_deg == Approx(g.longitude_deg).margin(1e-9));
    CHECK(back[i].height == Approx(160.0 + c.z()).margin(1e-5));
    CHECK(back[i].heading_deg == Approx(0.2 * static_cast<double>(i) * 180.0 / kPi).margin(1e-5));
    CHECK(back[i].keyframe == rows[i].keyframe);
    CHECK(back[i].after_last_anchor == rows[i].after_last_anchor);
    if (i % 4 != 3) {
      CHECK(back[i].sd_east == Approx(0.2 * std::sqrt(i + 1.0)).margin(1e-4));
      CHECK(back[i].sd_north == Approx(0.3 * std::sqrt(i + 1.0)).margin(1e-4));
      CHECK(back[i].cov_en == Approx(0.01 * static_cast<double>(i)).epsilon(1e-3));
    } else {
      CHECK(std::isnan(back[i].sd_east));
      CHECK(std::isnan(back[i].cov_en));
    }
    CHECK(std::isnan(back[i].timestamp) == std::isnan(rows[i].timestamp));
    CHECK(back[i].line == static_cast<int>(i) + 3);
  }
}

TEST_CASE("GeoJSON and KML carry lon,lat order, the anchors and the metadata",
          "[io][geojson][kml]") {
  TempDir dir;
  const geo::LocalFrame frame = geo::kitti_local_frame();
  std::vector<Eigen::Vector3d> track;
  for (int i = 0; i < 25; ++i) track.emplace_back(3.0 * i, 40.0 * i, 0.1 * i);
  std::vector<io::Anchor> anchors(2);
  anchors[0].frame = 5, anchors[0].y_w = track[5], anchors[0].sigma_m = 0.05;
  anchors[1].timestamp = 2.5, anchors[1].y_w = track[20];

  const std::string gj = dir.file("track.geojson");
  io::write_geojson(gj, track, anchors, frame, geo::kKittiGeoOriginNote);
  const std::string j = read_text(gj);
  CHECK(j.find("\"type\": \"FeatureCollection\"") != std::string::npos);
  CHECK(j.find("\"version\": \"" + std::string(geodrift::kVersion) + "\"") != std::string::npos);
  CHECK(j.find("ASSUMPTION") != std::string::npos);
  CHECK(count_of(j, "\"LineString\"") == 1);
  CHECK(count_of(j, "\"Point\"") == 2);
  CHECK(count_of(j, "{") == count_of(j, "}"));
  CHECK(count_of(j, "[") == count_of(j, "]"));
  // The LineString coordinates: [lon, lat, h] triples equal to the W track's geodetic positions.
  const std::size_t b = j.find("\"coordinates\": [", j.find("LineString"));
  const std::size_t e = j.find("]}}", b);
  const std::vector<double> nums = numbers_in(j.substr(b, e - b));
  REQUIRE(nums.size() == 3 * track.size());
  for (std::size_t i = 0; i < track.size(); ++i) {
    const geo::Geodetic g = frame.to_geodetic(track[i]);
    CHECK(nums[3 * i] == Approx(g.longitude_deg).margin(1e-9));
    CHECK(nums[3 * i + 1] == Approx(g.latitude_deg).margin(1e-9));
    CHECK(nums[3 * i + 2] == Approx(g.height).margin(1e-4));
  }
  // Karlsruhe: longitude ~8.4 comes first, latitude ~49.0 second.
  CHECK(nums[0] == Approx(8.417).margin(1e-6));
  CHECK(nums[1] == Approx(49.011).margin(1e-6));

  const std::string km = dir.file("track.kml");
  io::write_kml(km, track, anchors, frame, geo::kKittiGeoOriginNote);
  const std::string k = read_text(km);
  CHECK(k.find("<kml xmlns=\"http://www.opengis.net/kml/2.2\">") != std::string::npos);
  CHECK(k.find(kVersionTag) != std::string::npos);
  CHECK(count_of(k, "<Placemark>") == 3);
  CHECK(count_of(k, "<Placemark>") == count_of(k, "</Placemark>"));
  const std::size_t kb = k.find("<coordinates>") + 13;
  const std::vector<double> kn = numbers_in(k.substr(kb, k.find("</coordinates>") - kb));
  REQUIRE(kn.size() == 3 * track.size());
  for (std::size_t i = 0; i < track.size(); ++i) {
    const geo::Geodetic g = frame.to_geodetic(track[i]);
    CHECK(kn[3 * i] == Approx(g.longitude_deg).margin(1e-9));
    CHECK(kn[3 * i + 1] == Approx(g.latitude_deg).margin(1e-9));
  }
}

TEST_CASE("PLY point clouds round trip with and without colour", "[io][ply]") {
  TempDir dir;
  std::mt19937 rng(42);
  io::PointCloud cloud;
  for (int i = 0; i < 100; ++i) cloud.points.push_back(random_pose(rng, 5000.0).translation());
  for (const bool rgb : {false, true}) {
    if (rgb)
      for (int i = 0; i < 100; ++i)
        cloud.colors.push_back(
            {static_cast<std::uint8_t>(i), 7, static_cast<std::uint8_t>(255 - i)});
    const std::string path = dir.file(rgb ? "rgb.ply" : "xyz.ply");
    io::write_ply(path, cloud, "W = UTM 32N shifted");
    const io::PointCloud r = io::read_ply(path);
    REQUIRE(r.points.size() == cloud.points.size());
    for (std::size_t i = 0; i < cloud.points.size(); ++i) CHECK(r.points[i] == cloud.points[i]);
    CHECK(r.colors == cloud.colors);
    REQUIRE(r.comments.size() == 3);
    CHECK(r.comments[0] == kVersionTag + " map points");
    CHECK(r.comments[1] == "frame: W = UTM 32N shifted");
    CHECK(r.comments[2] == "units: metres");
  }
  // A monocular map frame says its coordinates are not metres.
  io::write_ply(dir.file("m.ply"), cloud, "M (VO)", io::kMapUnits);
  CHECK(io::read_ply(dir.file("m.ply")).comments.at(2) == std::string("units: ") + io::kMapUnits);
}

TEST_CASE("SVG plots keep equal aspect, north up, and state version and frame", "[io][svg]") {
  TempDir dir;
  io::SvgSeries square{"square", "#123456", 2.0, {{0, 0}, {100, 0}, {100, 100}, {0, 100}}};
  io::SvgSeries wide{"wide", "red", 1.0, {{-50, 20}, {250, 20}}};
  const std::vector<io::SvgMarker> markers = {{"a0", {0, 0}}, {"a1", {100, 100}}};
  const std::string path = dir.file("topview.svg");
  io::write_svg_topview(path, {square, wide}, markers, "Top view", "W = UTM 32N");
  const std::string s = read_text(path);
  CHECK(s.find("<svg xmlns=\"http://www.w3.org/2000/svg\"") != std::string::npos);
  CHECK(s.find(kVersionTag + "; frame: W = UTM 32N; axes: x east, y north, metres") !=
        std::string::npos);
  CHECK(count_of(s, "<polyline") == 2);
  CHECK(count_of(s, "<circle") == 3);  // two markers + the legend entry
  // The square's pixel coordinates: equal sides (equal aspect) and y flipped (north up).
  const std::size_t b = s.find("points=\"", s.find("data-label=\"square\"")) + 8;
  const std::vector<double> p = numbers_in(s.substr(b, s.find('"', b) - b));
  REQUIRE(p.size() == 8);
  const double side_x = p[2] - p[0], side_y = p[3] - p[5];
  CHECK(side_x > 100.0);
  CHECK(side_y == Approx(side_x).epsilon(1e-6));  // (100, 100) is ABOVE (100, 0) on screen

  const std::string sp = dir.file("scale.svg");
  io::SvgSeries scale{"scale factor", "blue", 1.5, {{0, 0.9}, {100, 1.1}, {200, 1.0}}};
  io::write_svg_line_plot(sp, {scale}, "Scale factor", "distance [m]", "scale", "W", 1.0);
  const std::string t = read_text(sp);
  CHECK(count_of(t, "<polyline") == 1);
  CHECK(count_of(t, "stroke-dasharray=\"4 4\"") == 1);  // the reference line
  CHECK(t.find(kVersionTag) != std::string::npos);
  CHECK(io::detail::nice_step(97.0) == 20.0);
  CHECK(io::detail::nice_step(0.3) == 0.05);
}

TEST_CASE("Writers replace files atomically and never leave partial files", "[io][atomic]") {
  TempDir dir;
  const std::string path = dir.file("out.txt");
  write_text(path, "old content\n");
  // A writer that fails half way leaves the old file and no temporary file.
  CHECK_THROWS_AS(io::detail::write_atomically(path,
                                               [](std::ostream& os) {
                                                 os << "partial";
                                                 throw geodrift::InvalidArgument("boom");
                                               }),
                  geodrift::InvalidArgument);
  CHECK(read_text(path) == "old content\n");
  CHECK(dir.num_entries() == 1);
  // A writer whose input is bad throws before touching the target.
  std::vector<io::TrajectoryCsvRow> rows(2);
  rows[1].T_cw = lie::SE3d(lie::SO3d(), Eigen::Vector3d(-2.0e6, 0.0, 0.0));  // centre 2000 km east
  CHECK_THROWS_AS(io::write_trajectory_csv(path, rows, geo::kitti_local_frame()),
                  geodrift::InvalidArgument);
  CHECK(read_text(path) == "old content\n");
  CHECK(dir.num_entries() == 1);
  // Success replaces the content.
  io::detail::write_atomically(path, [](std::ostream& os) { os << "new\n"; });
  CHECK(read_text(path) == "new\n");
  CHECK(dir.num_entries() == 1);
  // A missing directory is an I/O Error naming the path.
  const std::string bad = dir.file("no/such/dir/out.txt");
  geodrift::test::require_io_error(
      [&] { io::detail::write_atomically(bad, [](std::ostream& os) { os << "x"; }); }, bad);

  // A write that fails half way (here past RLIMIT_FSIZE, EFBIG, as a full disk would give
  // ENOSPC) names the cause, keeps the old file and leaves no temporary file.
  struct rlimit old_limit {};
  REQUIRE(::getrlimit(RLIMIT_FSIZE, &old_limit) == 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  struct rlimit small = old_limit;
  small.rlim_cur = 4096;
  REQUIRE(::setrlimit(RLIMIT_FSIZE, &small) == 0);
  std::string what;
  try {
    io::detail::write_atomically(
        path, [](std::ostream& os) { os << std::string(std::size_t{1} << 20, 'x'); });
  } catch (const geodrift::Error& e) {
    what = e.what();
  }
  ::setrlimit(RLIMIT_FSIZE, &old_limit);
  std::signal(SIGXFSZ, old_handler);
  CHECK(what == "cannot write '" + path + "': I/O error: " + std::strerror(EFBIG));
  CHECK(read_text(path) == "new\n");
  CHECK(dir.num_entries() == 1);
}

TEST_CASE("KITTI files with a leading time column read as timestamps", "[io][trajectory]") {
  TempDir dir;
  const std::string p = dir.file("with_times.txt");
  write_text(p, "0 1 0 0 0 0 1 0 0 0 0 1 0\n0.1036117 1 0 0 0 0 1 0 0 0 0 1 1.5\n");
  const io::Trajectory t = io::read_trajectory(p);
  CHECK(t.format == io::TrajectoryFormat::kKitti);
  CHECK(t.has_timestamps);
  CHECK_FALSE(t.has_frame_index);
  REQUIRE(t.poses.size() == 2);
  CHECK(t.poses[1].timestamp == 0.1036117);
  CHECK(t.poses[1].frame == 1);
  CHECK(t.poses[1].T_cw.inverse().translation().z() == 1.5);
}

TEST_CASE("Anchors are located on the trajectory by frame or by time", "[io][anchors]") {
  io::Trajectory traj;
  traj.has_timestamps = true;
  for (int i = 0; i < 5; ++i) {
    io::TrajectoryPose p;
    p.frame = 10 * i;
    p.timestamp = 100.0 + 2.0 * i;
    traj.poses.push_back(p);
  }
  std::vector<io::Anchor> a(4);
  a[0].frame = 0;
  a[1].frame = 25;
  a[2].timestamp = 107.0;
  a[3].frame = 40;
  const std::vector<io::AnchorLocation> loc = io::locate_anchors(a, traj, "anchors.csv");
  CHECK(loc[0].index == 0);
  CHECK(loc[0].fraction == 0.0);
  CHECK(loc[1].index == 2);
  CHECK(loc[1].fraction == Approx(0.5));
  CHECK(loc[2].index == 3);
  CHECK(loc[2].fraction == Approx(0.5));
  CHECK(loc[3].index == 4);
  CHECK(loc[3].fraction == 0.0);

  std::vector<io::Anchor> late(1);
  late[0].frame = 41;
  late[0].line = 7;
  geodrift::test::require_parse_error([&] { io::locate_anchors(late, traj, "anchors.csv"); },
                                      "anchors.csv", 7, "frame 41 is outside");
  std::vector<io::Anchor> early(1);
  early[0].timestamp = 99.0;
  early[0].line = 3;
  geodrift::test::require_parse_error([&] { io::locate_anchors(early, traj, "anchors.csv"); },
                                      "anchors.csv", 3, "timestamp 99 is outside");
  traj.has_timestamps = false;
  geodrift::test::require_parse_error([&] { io::locate_anchors(early, traj, "anchors.csv"); },
                                      "anchors.csv", 3, "no timestamps");
}

TEST_CASE("An anchor between two poses sits on a cubic through them, not on their chord",
          "[io][anchors]") {
  // KITTI 02's ground truth (shipped), thinned to poses every 3-12 frames as an ORB-SLAM
  // keyframe trajectory is: each dropped frame, located by frame and by time, against the
  // chord between its two neighbouring poses.
  const std::string dir = std::string(GEODRIFT_SOURCE_DIR) + "/data/kitti";
  const io::Trajectory gt = io::read_trajectory(dir + "/poses/02.txt");
  std::ifstream tf(dir + "/times/02.txt");
  std::vector<double> times;
  for (double t; tf >> t;) times.push_back(t);
  REQUIRE(times.size() == gt.poses.size());
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> gap(3, 12);
  io::Trajectory thin;
  thin.has_timestamps = true;
  std::vector<std::size_t> kept;
  for (std::size_t k = 0; k < gt.poses.size(); k += gap(rng)) kept.push_back(k);
  for (std::size_t k : kept) {
    io::TrajectoryPose p = gt.poses[k];
    p.frame = static_cast<int>(k);
    p.timestamp = times[k];
    thin.poses.push_back(p);
  }
  std::vector<io::Anchor> by_frame, by_time;
  std::vector<Eigen::Vector3d> truth;
  for (std::size_t j = 0; j + 1 < kept.size(); ++j)
    for (std::size_t k = kept[j] + 1; k < kept[j + 1]; ++k) {
      io::Anchor a;
      a.frame = static_cast<int>(k);
      by_frame.push_back(a);
      a.frame = -1;
      a.timestamp = times[k];
      by_time.push_back(a);
      truth.push_back(gt.poses[k].T_cw.inverse().translation());
    }
  for (const auto* anchors : {&by_frame, &by_time}) {
    const std::vector<io::AnchorLocation> loc = io::locate_anchors(*anchors, thin, "a.csv");
    double cubic = 0, chord = 0, worst_cubic = 0, worst_chord = 0;
    for (std::size_t j = 0; j < loc.size(); ++j) {
      const Eigen::Vector3d c = io::anchor_pose_cw(thin, loc[j]).inverse().translation();
      const Eigen::Vector3d a = thin.poses[loc[j].index].T_cw.inverse().translation();
      const Eigen::Vector3d b = thin.poses[loc[j].index + 1].T_cw.inverse().translation();
      const Eigen::Vector3d lin = a + loc[j].fraction * (b - a);
      cubic += (c - truth[j]).norm();
      chord += (lin - truth[j]).norm();
      worst_cubic = std::max(worst_cubic, (c - truth[j]).norm());
      worst_chord = std::max(worst_chord, (lin - truth[j]).norm());
    }
    cubic /= static_cast<double>(loc.size());
    chord /= static_cast<double>(loc.size());
    INFO((anchors == &by_frame ? "by frame" : "by time")
         << ": mean distance to the true centre, cubic " << cubic << " m, chord " << chord
         << " m; worst " << worst_cubic << " / " << worst_chord << " m over " << loc.size());
    CHECK(chord > 0.08);  // measured 0.096 m (by frame)
    CHECK(cubic < 0.5 * chord);
    CHECK(worst_cubic < 0.7 * worst_chord);
  }

  // At a pose: that pose. The rotation along the geodesic between the two.
  io::AnchorLocation at;
  at.index = 5;
  CHECK((io::anchor_pose_cw(thin, at).matrix() - thin.poses[5].T_cw.matrix()).norm() == 0.0);
  at.fraction = 0.5;
  const lie::SO3d Ra = thin.poses[5].T_cw.rotation().inverse();
  const lie::SO3d Rb = thin.poses[6].T_cw.rotation().inverse();
  const lie::SO3d Rm = io::anchor_pose_cw(thin, at).rotation().inverse();
  CHECK((Ra.inverse() * Rm).log().norm() ==
        Approx(0.5 * (Ra.inverse() * Rb).log().norm()).margin(1e-12));

  // A jump next to the anchor's interval (50 m from one pose to the next): the tangent it
  // would pull is not used, the centre stays on the chord's side of the jump.
  io::Trajectory line;
  for (int k = 0; k < 6; ++k) {
    io::TrajectoryPose p;
    p.frame = k;
    const double x = k + (k >= 4 ? 50.0 : 0.0);  // 1 m per frame, a 50 m leap from 3 to 4
    p.T_cw = lie::SE3d(lie::SO3d(), Eigen::Vector3d(-x, 0, 0));
    line.poses.push_back(p);
  }
  io::AnchorLocation mid;
  mid.index = 2;
  mid.fraction = 0.5;
  CHECK(io::anchor_pose_cw(line, mid).inverse().translation().x() == Approx(2.5).margin(1e-12));
}

TEST_CASE("Anchors in another clock than the trajectory's are named: unit or GPS epoch",
          "[io][anchors]") {
  // 100 poses over 99 s, in a given unit and epoch; four anchors at 10, 40, 70 and 95 s.
  const auto trajectory = [](double scale, double epoch) {
    io::Trajectory t;
    t.has_timestamps = true;
    for (int i = 0; i < 100; ++i) {
      io::TrajectoryPose p;
      p.frame = i;
      p.timestamp = epoch + scale * i;
      t.poses.push_back(p);
    }
    return t;
  };
  const auto anchors = [](double scale, double epoch) {
    std::vector<io::Anchor> a(4);
    const double at[4] = {10, 40, 70, 95};
    for (int i = 0; i < 4; ++i) {
      a[i].timestamp = epoch + scale * at[i];
      a[i].line = 2 + i;
    }
    return a;
  };
  // Same clock: located, no complaint.
  const std::vector<io::AnchorLocation> ok =
      io::locate_anchors(anchors(1, 1.6e9), trajectory(1, 1.6e9), "a.csv");
  CHECK(ok[1].index == 40);
  // Seconds against a trajectory in nanoseconds: inside its range, bunched at its start.
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1, 0), trajectory(1e9, 0), "a.csv"); }, "a.csv", 2,
      "look like seconds and the trajectory's like nanoseconds");
  // Nanoseconds against seconds, milliseconds against seconds: outside, with the unit named.
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1e9, 1.6e18), trajectory(1, 1.6e9), "a.csv"); }, "a.csv", 2,
      "look like nanoseconds and the trajectory's like seconds");
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1e3, 1.6e12), trajectory(1, 1.6e9), "a.csv"); }, "a.csv", 2,
      "look like milliseconds");
  // GPS time (18 leap seconds) against Unix time, both ways, with the offset to pass.
  const double gps = 1.6e9 - 315964782.0;
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1, gps), trajectory(1, 1.6e9), "a.csv"); }, "a.csv", 2,
      "less 18 leap seconds: one is GPS time, the other Unix (UTC) time (--anchor-time-offset "
      "315964782)");
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1, 1.6e9), trajectory(1, gps), "a.csv"); }, "a.csv", 2,
      "(--anchor-time-offset -315964782)");
  // Seconds of the GPS week against an absolute time.
  geodrift::test::require_parse_error(
      [&] { io::locate_anchors(anchors(1, 3e5), trajectory(1, 1.6e9), "a.csv"); }, "a.csv", 2,
      "seconds of the GPS week");
  // Simply outside, no unit fits: the plain message.
  std::vector<io::Anchor> far = anchors(1, 2e9);
  try {
    io::locate_anchors(far, trajectory(1, 1.6e9), "a.csv");
    FAIL("no error");
  } catch (const geodrift::InvalidArgument& e) {
    const std::string msg = e.what();
    CHECK(msg.find("is outside the trajectory's timestamp range") != std::string::npos);
    CHECK(msg.find("look like") == std::string::npos);
    CHECK(msg.find("GPS") == std::string::npos);
  }
}

TEST_CASE("The shipped KITTI ground truth reads as 4661 poses, with and without times",
          "[io][trajectory][data]") {
  const std::string dir = std::string(GEODRIFT_DATA_DIR) + "/kitti_odometry_gt";
  const io::Trajectory plain = io::read_trajectory(dir + "/poses/02.txt");
  const io::Trajectory timed = io::read_trajectory(dir + "/egusa_poses_with_times/02.txt");
  REQUIRE(plain.poses.size() == 4661);
  REQUIRE(timed.poses.size() == 4661);
  CHECK(timed.has_timestamps);
  CHECK(timed.poses.back().timestamp == Approx(483.28).margin(0.01));
  double length = 0.0, max_diff = 0.0;
  for (std::size_t i = 0; i < plain.poses.size(); ++i) {
    max_diff = std::max(max_diff, pose_distance(plain.poses[i].T_cw, timed.poses[i].T_cw));
    if (i > 0)
      length += (plain.poses[i].T_cw.inverse().translation() -
                 plain.poses[i - 1].T_cw.inverse().translation())
                    .norm();
  }
  CHECK(max_diff < 1e-5);                       // same poses, printed with different digits
  CHECK(length == Approx(5067.2).margin(0.1));  // the README's path length
  CHECK(pose_distance(plain.poses[0].T_cw, lie::SE3d()) < 1e-6);
}

TEST_CASE("Numbers are written in the shortest form that reads back exactly", "[io][format]") {
  CHECK(io::detail::fmt(0.1) == "0.1");
  CHECK(io::detail::fmt(-2.5e-7) == "-2.5e-07");
  CHECK(io::detail::fmt(std::nan("")) == "nan");
  CHECK(io::detail::fmt(1.0 / 3.0, 4) == "0.3333");
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1e7, 1e7);
  for (int i = 0; i < 1000; ++i) {
    const double v = u(rng) * std::pow(10.0, static_cast<int>(rng() % 21) - 10);
    INFO(v);
    CHECK(std::strtod(io::detail::fmt(v).c_str(), nullptr) == v);
  }
}

TEST_CASE("Jumps in a trajectory: a new map mid-path is one, a gap in time is not",
          "[io][trajectory][data]") {
  const std::string dir = std::string(GEODRIFT_DATA_DIR) + "/kitti_odometry_gt";
  for (const char* seq : {"02", "08"}) {
    INFO("sequence " << seq);
    const io::Trajectory gt = io::read_trajectory(dir + "/egusa_poses_with_times/" + seq + ".txt");
    REQUIRE(gt.has_timestamps);
    CHECK(std::string(io::trajectory_time_unit(gt)) == "s");
    // Real driving (stops, turns, 10 Hz): no jump, in seconds, in frames, and in poses.
    CHECK(io::find_trajectory_jumps(gt).empty());
    io::Trajectory frames = gt;
    frames.has_timestamps = false;
    CHECK(std::string(io::trajectory_time_unit(frames)) == "frames");
    CHECK(io::find_trajectory_jumps(frames).empty());

    // A new SLAM map from pose 2000 on: its own origin there and a unit 0.3 of the old one.
    const std::size_t cut = 2000;
    io::Trajectory reset = gt;
    const lie::SE3d T_new_old = gt.poses[cut].T_cw;  // the new map's frame = that camera
    for (std::size_t i = cut; i < reset.poses.size(); ++i) {
      const lie::SE3d T_wc = T_new_old * gt.poses[i].T_cw.inverse();
      reset.poses[i].T_cw = lie::SE3d(T_wc.rotation(), 0.3 * T_wc.translation()).inverse();
    }
    std::vector<io::TrajectoryJump> j = io::find_trajectory_jumps(reset);
    REQUIRE(j.size() == 1);
    CHECK(j[0].index == cut - 1);
    CHECK(j[0].ratio > 10.0);
    // Unit-free: the same jump at any scale of the whole file.
    io::Trajectory small = reset;
    for (auto& p : small.poses) {
      const lie::SE3d T_wc = p.T_cw.inverse();
      p.T_cw = lie::SE3d(T_wc.rotation(), 1e-3 * T_wc.translation()).inverse();
    }
    const std::vector<io::TrajectoryJump> js = io::find_trajectory_jumps(small);
    REQUIRE(js.size() == 1);
    CHECK(js[0].index == cut - 1);
    CHECK(js[0].ratio == Approx(j[0].ratio).epsilon(1e-9));

    // A 6 m leap with the same frame and unit: suspect (a warning), not a jump.
    io::Trajectory leap = gt;
    for (std::size_t i = cut; i < leap.poses.size(); ++i) {
      const lie::SE3d T_wc = gt.poses[i].T_cw.inverse();
      leap.poses[i].T_cw =
          lie::SE3d(T_wc.rotation(), T_wc.translation() + Eigen::Vector3d(6, 0, 0)).inverse();
    }
    CHECK(io::find_trajectory_jumps(leap).empty());
    io::TrajectoryJumpOptions suspect;
    suspect.max_ratio = io::kSuspectJumpRatio;
    j = io::find_trajectory_jumps(leap, suspect);
    REQUIRE(j.size() == 1);
    CHECK(j[0].index == cut - 1);
    CHECK(j[0].ratio > io::kSuspectJumpRatio);
    CHECK(j[0].ratio < 10.0);
    CHECK(io::find_trajectory_jumps(gt, suspect).empty());

    // 300 poses lost (tracking lost, relocalized in the same map): a long step over a long
    // time, not a jump; the same file without times or frame numbers has one.
    io::Trajectory gap = gt;
    gap.poses.erase(gap.poses.begin() + 1500, gap.poses.begin() + 1800);
    CHECK(io::find_trajectory_jumps(gap).empty());
    io::Trajectory gap_frames = gap;
    gap_frames.has_timestamps = false;
    CHECK(io::find_trajectory_jumps(gap_frames).empty());
    io::Trajectory gap_poses = gap_frames;
    for (std::size_t i = 0; i < gap_poses.poses.size(); ++i)
      gap_poses.poses[i].frame = static_cast<int>(i);
    CHECK(std::string(io::trajectory_time_unit(gap_poses)) == "frames");
    j = io::find_trajectory_jumps(gap_poses);
    REQUIRE(j.size() == 1);
    CHECK(j[0].index == 1499);
    CHECK(io::describe_jump(gap_poses, j[0]).find("in 1 frame(s)") != std::string::npos);
  }
}
