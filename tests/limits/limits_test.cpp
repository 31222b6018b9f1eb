// Limits of `geodrift correct` on places and values at the edge of what it handles (issue 25
// item 5): a path across a UTM zone border, across the equator and in the southern hemisphere
// is corrected in W's one zone; a latitude beyond UTM, a coordinate of 1e300 and a 100 MB line
// are refused with a message naming the problem, a non-zero exit and no output.

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "support/cli_run.hpp"
#include "support/test_files.hpp"

namespace geo = geodrift::geo;
using geodrift::test::run_cli;
using geodrift::test::TempDir;

namespace {

// A drift-free monocular path in W: 300 m east, a 90° bend, 300 m north, a pose per metre,
// written as a KITTI trajectory in map units of 0.5 per metre (camera x right, y down, z
// forward; map frame = east, -up, north) with anchors x,y,z every 20 poses.
struct Path {
  std::vector<Eigen::Vector3d> truth;  // camera centres in W
};

Path write_path(const TempDir& dir, double translation_override = 0.0) {
  Path p;
  std::ostringstream traj, anchors;
  traj.precision(10);
  anchors.precision(10);
  anchors << "frame,x,y,z,sigma_m\n";
  const double scale = 0.5;
  Eigen::Vector3d c(0, 0, 0);
  for (int i = 0; i < 620; ++i) {
    // Heading: east for 300 poses, a bend over 20, then north.
    const double h = i < 300 ? 0.0 : (i < 320 ? (i - 300) / 20.0 * M_PI / 2 : M_PI / 2);
    if (i > 0) c += Eigen::Vector3d(std::cos(h), std::sin(h), 0.0);
    p.truth.push_back(c);
    const double ch = std::cos(h), sh = std::sin(h);
    const Eigen::Vector3d t = scale * Eigen::Vector3d(c.x(), -c.z(), c.y());
    traj << sh << " 0 " << ch << " "
         << (i == 400 && translation_override != 0.0 ? translation_override : t.x()) << " 0 1 0 "
         << t.y() << " " << -ch << " 0 " << sh << " " << t.z() << "\n";
    if (i % 20 == 10) anchors << i << "," << c.x() << "," << c.y() << "," << c.z() << ",0.1\n";
  }
  geodrift::test::write_text(dir.file("traj.txt"), traj.str());
  geodrift::test::write_text(dir.file("anchors.csv"), anchors.str());
  return p;
}

struct Row {
  Eigen::Vector3d x;
  std::string zone;
  double lat = 0, lon = 0, easting = 0, northing = 0;
};

// trajectory.csv: frame,timestamp,kind,x,y,z,easting,northing,zone,latitude,longitude,...
std::vector<Row> read_rows(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<Row> rows;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("frame,", 0) == 0) continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string t; std::getline(ss, t, ',');) f.push_back(t);
    REQUIRE(f.size() >= 11);
    Row r;
    r.x = Eigen::Vector3d(std::stod(f[3]), std::stod(f[4]), std::stod(f[5]));
    r.easting = std::stod(f[6]);
    r.northing = std::stod(f[7]);
    r.zone = f[8];
    r.lat = std::stod(f[9]);
    r.lon = std::stod(f[10]);
    rows.push_back(r);
  }
  return rows;
}

// Runs correct at `origin`; checks the corrected path against the truth and the lat/lon
// columns against W through a frame of the reported zone. Returns the rows.
std::vector<Row> correct_at(const std::string& origin, int zone, bool northp) {
  TempDir dir;
  const Path p = write_path(dir);
  const auto r = run_cli(GEODRIFT_CLI_EXE, "correct --trajectory " + dir.file("traj.txt") +
                                               " --anchors " + dir.file("anchors.csv") +
                                               " --origin " + origin + " --out " + dir.file("out"));
  INFO(r.output);
  REQUIRE(r.code == 0);
  const auto rows = read_rows(dir.file("out/trajectory.csv"));
  REQUIRE(rows.size() == p.truth.size());
  double max_err = 0;
  for (std::size_t i = 0; i < rows.size(); ++i)
    max_err = std::max(max_err, (rows[i].x - p.truth[i]).head<2>().norm());
  CHECK(max_err < 0.05);  // drift-free input, exact anchors: the path comes back to the mm level
  // W is one zone: every row's UTM is that zone's grid (northings of points north of the
  // equator in a southern-hemisphere W carry the northern convention: the letter says which).
  const geo::LocalFrame W =
      geo::LocalFrame::from_geodetic(std::stod(origin.substr(0, origin.find(','))),
                                     std::stod(origin.substr(origin.find(',') + 1)), 0.0);
  CHECK(W.zone() == zone);
  CHECK(W.northp() == northp);
  for (const Row& row : rows) {
    CHECK(row.zone.substr(0, row.zone.size() - 1) == std::to_string(zone));
    const geo::Geodetic g = W.to_geodetic(row.x);
    CHECK(std::abs(g.latitude_deg - row.lat) < 1e-9);
    CHECK(std::abs(g.longitude_deg - row.lon) < 1e-9);
  }
  return rows;
}

}  // namespace

TEST_CASE("A path across a UTM zone border stays in W's zone", "[limits]") {
  // 11.997°E at 47°N is ~230 m west of the 12°E border of zones 32 and 33.
  const auto rows = correct_at("47.0,11.997,500", 32, true);
  int east_of_border = 0;
  for (const Row& r : rows) east_of_border += r.lon > 12.0;
  CHECK(east_of_border > 300);
  // Its easting keeps growing across the border (zone 32's grid, not a jump to zone 33's).
  CHECK(rows.back().easting > rows.front().easting + 290);
}

TEST_CASE("Southern hemisphere and a path across the equator", "[limits]") {
  const auto sydney = correct_at("-33.9,151.2,10", 56, false);
  for (const Row& r : sydney) CHECK(r.zone == "56S");
  // From 0.002°S (about 220 m south of the equator) north across it.
  const auto eq = correct_at("-0.002,9.0,0", 32, false);
  int north = 0;
  for (const Row& r : eq) {
    CHECK(r.zone == (r.lat >= 0 ? "32N" : "32S"));
    north += r.lat > 0;
  }
  CHECK(north > 50);
}

TEST_CASE("Places and values geodrift cannot represent are refused, nothing written", "[limits]") {
  TempDir dir;
  write_path(dir);
  const std::string base =
      "correct --trajectory " + dir.file("traj.txt") + " --anchors " + dir.file("anchors.csv");
  // Polar: UTM ends at 84°N / 80°S and geodrift has no UPS.
  for (const std::string origin : {"89.9,0,0", "-89.9,0,0"}) {
    const auto r =
        run_cli(GEODRIFT_CLI_EXE, base + " --origin " + origin + " --out " + dir.file("polar"));
    INFO(r.output);
    CHECK(r.code != 0);
    CHECK(r.output.find("cannot be projected to UTM") != std::string::npos);
    CHECK(geodrift::test::no_outputs(dir.path(), "polar"));
  }
  // A translation of 1e300 (finite, parses) on line 401.
  TempDir big;
  write_path(big, 1e300);
  auto r = run_cli(GEODRIFT_CLI_EXE, "correct --trajectory " + big.file("traj.txt") +
                                         " --anchors " + big.file("anchors.csv") +
                                         " --origin 47,11,0 --out " + big.file("out"));
  INFO(r.output);
  CHECK(r.code != 0);
  CHECK(r.output.find("keyframe 400 translation") != std::string::npos);
  CHECK(r.output.find("exceeds 1e+12 map units") != std::string::npos);
  CHECK(geodrift::test::no_outputs(big.path(), "out"));
  // A 100 MB line (no newline inside): refused by line number before it is split into fields.
  {
    std::ofstream out(dir.file("long.txt"), std::ios::binary);
    const std::string chunk(1 << 20, '7');
    for (int i = 0; i < 100; ++i) out << chunk;
    out << "\n";
  }
  r = run_cli(GEODRIFT_CLI_EXE, "correct --trajectory " + dir.file("long.txt") + " --anchors " +
                                    dir.file("anchors.csv") + " --origin 47,11,0 --out " +
                                    dir.file("long_out"));
  INFO(r.output);
  CHECK(r.code != 0);
  CHECK(r.output.find("long.txt:1: line of 104857600 bytes, longer than the 64 MiB limit") !=
        std::string::npos);
  CHECK(r.output.size() < 1000);
  CHECK(geodrift::test::no_outputs(dir.path(), "long_out"));
}

TEST_CASE("A COLMAP point seen by every image: the long-track path of the Corrector", "[limits]") {
  // 1,200 images 1 m apart, weaving 5 m sideways (identity rotations; the layout of
  // bench/support/colmap_long_track.py, where 100,000 images are measured: BENCHMARKS.md),
  // 4 short-track points per image, one far landmark seen by all 1,200 (past the Corrector's
  // covisibility_max_track of 1,000 and the 256 rays of the exact parallax test), listed twice
  // by image 1,100 (a point is observed once per keyframe). Exact anchors every 100 images.
  TempDir dir;
  const int n = 1200;
  const double f = 500, cx = 500, cy = 250;
  const auto cam_x = [](int i) { return 5.0 * std::sin(i / 200.0); };
  struct Point {
    Eigen::Vector3d p;
    int first, last;
  };
  std::vector<Point> pts{{Eigen::Vector3d(0, -20, n + 1000.0), 0, n - 1}};
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 4; ++k)
      pts.push_back(
          {Eigen::Vector3d(cam_x(i) + (k - 1.5) * 5.0, k % 2 ? -2.0 : 0.5, i + 15.0 + 2.5 * k), i,
           std::min(i + 3, n - 1)});
  std::vector<std::ostringstream> obs(n);
  std::vector<int> nobs(n, 0);
  std::ostringstream points;
  points.precision(10);
  for (std::size_t q = 0; q < pts.size(); ++q) {
    points << q + 1 << " " << pts[q].p.x() << " " << pts[q].p.y() << " " << pts[q].p.z()
           << " 128 128 128 0.5";
    for (int j = pts[q].first; j <= pts[q].last; ++j) {
      const int copies = (q == 0 && j == 1100) ? 2 : 1;
      for (int c = 0; c < copies; ++c) {
        const double d = pts[q].p.z() - j;
        obs[j] << (nobs[j] ? " " : "") << cx + f * (pts[q].p.x() - cam_x(j)) / d << " "
               << cy + f * pts[q].p.y() / d << " " << q + 1;
        points << " " << j + 1 << " " << nobs[j]++;
      }
    }
    points << "\n";
  }
  std::ostringstream images, traj, anchors;
  images.precision(10);
  traj.precision(10);
  anchors << "frame,x,y,z,sigma_m\n";
  for (int i = 0; i < n; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d.png", i);
    images << i + 1 << " 1 0 0 0 " << -cam_x(i) << " 0 " << -i << " 1 " << name << "\n"
           << obs[i].str() << "\n";
    traj << "1 0 0 " << cam_x(i) << " 0 1 0 0 0 0 1 " << i << "\n";
    if (i % 100 == 0) anchors << i << "," << cam_x(i) << "," << i << ",0,0.5\n";
  }
  std::filesystem::create_directories(dir.file("model"));
  geodrift::test::write_text(dir.file("model/cameras.txt"), "1 PINHOLE 1000 500 500 500 500 250\n");
  geodrift::test::write_text(dir.file("model/images.txt"), images.str());
  geodrift::test::write_text(dir.file("model/points3D.txt"), points.str());
  geodrift::test::write_text(dir.file("traj.txt"), traj.str());
  geodrift::test::write_text(dir.file("anchors.csv"), anchors.str());
  const auto r =
      run_cli(GEODRIFT_CLI_EXE, "correct --trajectory " + dir.file("traj.txt") + " --map " +
                                    dir.file("model") + " --anchors " + dir.file("anchors.csv") +
                                    " --origin 55,13,0 --out " + dir.file("out"));
  INFO(r.output);
  REQUIRE(r.code == 0);
  const auto rows = read_rows(dir.file("out/trajectory.csv"));
  REQUIRE(rows.size() == static_cast<std::size_t>(n));
  double max_err = 0;
  for (int i = 0; i < n; ++i)
    max_err = std::max(max_err, (rows[i].x.head<2>() - Eigen::Vector2d(cam_x(i), i)).norm());
  CHECK(max_err < 0.02);  // exact map and anchors: 3.6 mm here (0.02 m mean at 100,000 images)
}
