// Readers for the solver's reference data: g2o 3D pose graphs, BAL problems, GTSAM's KITTI VO
// format. Inline strings test the parsing rules and every error path; the [data] cases check
// the real files' counts and a few known values.
#include <Eigen/Geometry>
#include <catch2/catch.hpp>
#include <sstream>
#include <string>

#include "geodrift/io/bal.hpp"
#include "geodrift/io/g2o.hpp"
#include "geodrift/io/vo_stereo.hpp"

using namespace geodrift;

namespace {

io::G2oPoseGraph3D parse_g2o(const std::string& s) {
  std::istringstream in(s);
  return io::parse_g2o_se3(in, "graph.g2o");
}
io::BalProblem parse_bal(const std::string& s) {
  std::istringstream in(s);
  return io::parse_bal(in, "problem.txt");
}

const char* kInfoZero = " 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0";
const char* kInfoIndefinite = " 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21";

// A valid upper triangle (row-major): diagonally dominant, so positive definite.
const char* kInfoPd = " 100 1 2 3 4 5 110 6 7 8 9 120 10 11 12 400 13 14 410 15 420";

std::string edge(const std::string& ids, const char* info = kInfoPd) {
  return "EDGE_SE3:QUAT " + ids + " 1 2 3 0 0 0.7071067811865476 0.7071067811865476" + info + "\n";
}

}  // namespace

TEST_CASE("g2o reader parses vertices, edges, information order and FIX", "[io][g2o]") {
  const std::string text =
      "# comment\n\nVERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n"
      "VERTEX_SE3:QUAT 5 1 -2 3.5 0 0 0.6 0.8\n" +
      edge("0 5") + "VERTEX_SE2 7 0 0 0\nEDGE_SE2 0 1 0 0 0 1 0 0 1 0 1\nFIX 0\n";
  const io::G2oPoseGraph3D g = parse_g2o(text);
  REQUIRE(g.vertices.size() == 2);
  REQUIRE(g.edges.size() == 1);
  CHECK(g.vertices[1].id == 5);
  CHECK(g.index(5) == 1);
  CHECK(g.vertices[1].t_wi.isApprox(Eigen::Vector3d(1, -2, 3.5)));
  CHECK(g.vertices[1].q_wi.z() == Approx(0.6));
  CHECK(g.vertices[1].q_wi.w() == Approx(0.8));
  CHECK(g.vertices[1].line == 4);
  const io::G2oEdgeSE3& e = g.edges[0];
  CHECK(e.i == 0);
  CHECK(e.j == 5);
  CHECK(e.line == 5);
  CHECK(e.t_ij.isApprox(Eigen::Vector3d(1, 2, 3)));
  // 90 deg about z.
  CHECK((e.q_ij.toRotationMatrix() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY()));
  // Upper triangle row-major, mirrored.
  CHECK(e.information_g2o(0, 0) == 100);
  CHECK(e.information_g2o(0, 5) == 5);
  CHECK(e.information_g2o(5, 0) == 5);
  CHECK(e.information_g2o(3, 4) == 13);
  CHECK(e.information_g2o(5, 5) == 420);
  // (x y z rx ry rz) -> (rx ry rz x y z): the rotation block moves to the top-left.
  const Eigen::Matrix<double, 6, 6> I = e.information_omega_nu();
  CHECK(I(0, 0) == 400);
  CHECK(I(2, 2) == 420);
  CHECK(I(3, 3) == 100);
  CHECK(I(5, 5) == 120);
  CHECK(I(0, 3) == e.information_g2o(3, 0));  // rx-x coupling
  CHECK(I(0, 3) == 3);
  CHECK(I(3, 4) == 1);   // x-y
  CHECK(I(1, 2) == 15);  // ry-rz
  const Eigen::Matrix<double, 6, 6> L = e.sqrt_information_omega_nu();
  CHECK((L.transpose() * L - I).norm() < 1e-9 * I.norm());
  CHECK(L.isUpperTriangular());
  REQUIRE(g.fixed_ids.size() == 1);
  CHECK(g.fixed_ids[0] == 0);
  CHECK(g.skipped_tags.at("VERTEX_SE2") == 1);
  CHECK(g.skipped_tags.at("EDGE_SE2") == 1);
  CHECK(g.num_skipped_lines() == 2);
  CHECK_THROWS_AS(g.index(3), InvalidArgument);
}

TEST_CASE("g2o indefinite information is used through its nearest PSD matrix", "[io][g2o]") {
  const auto g = parse_g2o("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n" +
                           edge("0 1", kInfoIndefinite) + edge("1 0"));
  CHECK(g.num_indefinite_information == 1);
  CHECK_FALSE(g.edges[0].information_is_positive_definite());
  CHECK(g.edges[1].information_is_positive_definite());
  const Eigen::Matrix<double, 6, 6> I = g.edges[0].information_omega_nu();
  const Eigen::Matrix<double, 6, 6> L = g.edges[0].sqrt_information_omega_nu();
  const Eigen::Matrix<double, 6, 6> P = L.transpose() * L;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> es(I);
  REQUIRE(es.eigenvalues()(0) < 0);
  // Same eigenvectors, negative eigenvalues clamped to zero.
  const Eigen::Matrix<double, 6, 6> expected = es.eigenvectors() *
                                               es.eigenvalues().cwiseMax(0.0).asDiagonal() *
                                               es.eigenvectors().transpose();
  CHECK((P - expected).norm() < 1e-10 * I.norm());
  CHECK(Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>>(P).eigenvalues()(0) >
        -1e-10 * I.norm());
}

TEST_CASE("g2o reader normalises nearly-unit quaternions", "[io][g2o]") {
  const auto g = parse_g2o("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1.0004\n");
  CHECK(g.vertices[0].q_wi.norm() == Approx(1.0).epsilon(1e-15));
}

TEST_CASE("g2o reader reports malformed lines with path and line number", "[io][g2o]") {
  const std::string v0 = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n";
  const std::string v1 = "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n";
  struct Case {
    std::string text, expect;
  };
  const Case cases[] = {
      {v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 1\n", "graph.g2o:2: VERTEX_SE3:QUAT needs 8 fields"},
      {v0 + "VERTEX_SE3:QUAT 1 0 0 abc 0 0 0 1\n", "graph.g2o:2: VERTEX_SE3:QUAT field 4 (z)"},
      {v0 + "VERTEX_SE3:QUAT 1 0 0 nan 0 0 0 1\n", "not a finite number"},
      {v0 + "VERTEX_SE3:QUAT -1 0 0 0 0 0 0 1\n", "graph.g2o:2: VERTEX_SE3:QUAT field 1 (id)"},
      {v0 + "VERTEX_SE3:QUAT 1 0 0 0 0 0 0 2\n", "graph.g2o:2: VERTEX_SE3:QUAT: quaternion norm"},
      {v0 + v0, "graph.g2o:2: duplicate vertex id 0 (first defined on line 1)"},
      {v0 + v1 + "EDGE_SE3:QUAT 0 1 0 0 0 0 0 0 1 1 0 0\n", "graph.g2o:3: EDGE_SE3:QUAT needs 30"},
      {v0 + v1 + edge("0 1", kInfoZero), "graph.g2o:3: EDGE_SE3:QUAT information matrix has no"},
      {v0 + v1 + edge("0 0"), "graph.g2o:3: edge connects vertex 0 to itself"},
      {v0 + edge("0 9") + v1, "graph.g2o:2: EDGE_SE3:QUAT references vertex id 9"},
      {v0 + "FIX\n", "graph.g2o:2: FIX needs at least one vertex id"},
      {v0 + "\nFIX 4\n", "graph.g2o:3: FIX references vertex id 4"},
      {"EDGE_SE2 0 1 0 0 0 1 0 0 1 0 1\n", "graph.g2o: no VERTEX_SE3:QUAT line"},
  };
  for (const Case& c : cases) {
    INFO(c.text);
    CHECK_THROWS_WITH(parse_g2o(c.text), Catch::Contains(c.expect));
    CHECK_THROWS_AS(parse_g2o(c.text), InvalidArgument);
  }
  CHECK_THROWS_WITH(io::read_g2o_se3("/nonexistent/x.g2o"), Catch::Contains("/nonexistent/x.g2o"));
}

TEST_CASE("g2o edge measurement convention matches Z_ij = T_wi^-1 T_wj on sphere2500",
          "[io][g2o][data]") {
  const io::G2oPoseGraph3D g =
      io::read_g2o_se3(GEODRIFT_DATA_DIR "/pose_graphs_g2o/sphere2500.g2o");
  REQUIRE(g.vertices.size() == 2500);
  REQUIRE(g.edges.size() == 4949);
  CHECK(g.skipped_tags.empty());
  // In sphere2500 the initial vertices are the odometry chain: the first edges equal
  // T_wi^-1·T_wj exactly (to file precision), which fixes the direction of the convention.
  for (int k = 0; k < 20; ++k) {
    const io::G2oEdgeSE3& e = g.edges[static_cast<std::size_t>(k)];
    REQUIRE(e.j == e.i + 1);
    const Eigen::Matrix4d Z =
        g.vertices[static_cast<std::size_t>(g.index(e.i))].matrix().inverse() *
        g.vertices[static_cast<std::size_t>(g.index(e.j))].matrix();
    INFO("edge " << k);
    CHECK((Z - e.matrix()).cwiseAbs().maxCoeff() < 1e-4);
  }
  const Eigen::Matrix<double, 6, 6> I = g.edges[0].information_omega_nu();
  CHECK(I(0, 0) == Approx(400.021));  // rotation block first
  CHECK(I(3, 3) == Approx(10));
}

TEST_CASE("g2o reader loads the four benchmark graphs", "[io][g2o][data]") {
  struct Expect {
    const char* file;
    std::size_t vertices, edges;
  };
  for (const Expect& x : {Expect{"parking-garage", 1661, 6275}, Expect{"torus3D", 5000, 9048},
                          Expect{"cubicle", 5750, 16869}}) {
    const auto g =
        io::read_g2o_se3(std::string(GEODRIFT_DATA_DIR "/pose_graphs_g2o/") + x.file + ".g2o");
    INFO(x.file);
    CHECK(g.vertices.size() == x.vertices);
    CHECK(g.edges.size() == x.edges);
    CHECK(g.fixed_ids.empty());
    CHECK(g.num_indefinite_information == (std::string(x.file) == "cubicle" ? 5021 : 0));
  }
}

TEST_CASE("BAL reader parses the layout and models the camera", "[io][bal]") {
  // 2 cameras, 2 points, 3 observations. Camera 1 rotates 180 deg about y (angle-axis (0, pi, 0)).
  const double pi = 3.14159265358979323846;
  std::ostringstream s;
  s.precision(17);
  s << "2 2 3\n0 0 10.5 -3\n1 0 1 2\n1 1 -4 5e-1\n"
    << "0 0 0\n0 0 -5\n500 0.1 -0.01\n"
    << "0\n"
    << pi << "\n0\n1\n2\n3\n800\n0\n0\n"
    << "1 2 3\n-1 -2 -3\n";
  const io::BalProblem p = parse_bal(s.str());
  REQUIRE(p.cameras.size() == 2);
  REQUIRE(p.points.size() == 2);
  REQUIRE(p.observations.size() == 3);
  CHECK(p.observations[2].camera == 1);
  CHECK(p.observations[2].point == 1);
  CHECK(p.observations[2].pixel.isApprox(Eigen::Vector2d(-4, 0.5)));
  CHECK(p.cameras[0].t.isApprox(Eigen::Vector3d(0, 0, -5)));
  CHECK(p.cameras[0].f == 500);
  CHECK(p.cameras[0].k1 == 0.1);
  CHECK(p.cameras[0].k2 == -0.01);
  CHECK(p.points[1].isApprox(Eigen::Vector3d(-1, -2, -3)));

  // Camera 0: identity rotation, t = (0,0,-5). X = (1,2,3) -> P = (1,2,-2), p = (0.5, 1),
  // r = 1 + 0.1·1.25 - 0.01·1.5625.
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
  REQUIRE(io::bal_project(p.cameras[0], p.points[0], &px));
  const double r = 1 + 0.1 * 1.25 - 0.01 * 1.5625;
  CHECK(px.isApprox(500 * r * Eigen::Vector2d(0.5, 1)));
  // Undistortion inverts the radial polynomial exactly.
  CHECK(io::undistort_bal_pixel(p.cameras[0], px).isApprox(Eigen::Vector2d(250, 500), 1e-12));
  // A point behind the BAL camera (P.z >= 0) does not project.
  CHECK_FALSE(io::bal_project(p.cameras[0], Eigen::Vector3d(0, 0, 6), &px));

  // OpenCV frame: z forward, y down. The point is in front (z > 0) and the pixel is (u, -v).
  const Eigen::Vector3d Pcv = p.cameras[0].R_cw_opencv() * p.points[0] + p.cameras[0].t_cw_opencv();
  CHECK(Pcv.isApprox(Eigen::Vector3d(1, -2, 2)));
  CHECK(500 * Pcv.x() / Pcv.z() == Approx(250));
  CHECK(500 * Pcv.y() / Pcv.z() == Approx(-500));  // BAL v = +500, y up
  // Camera 1: R = rot_y(pi): (x, y, z) -> (-x, y, -z).
  CHECK(p.cameras[1].R_bal().isApprox(Eigen::Vector3d(-1, 1, -1).asDiagonal().toDenseMatrix(),
                                      1e-12));
}

TEST_CASE("BAL reader reports malformed content with path and line number", "[io][bal]") {
  const std::string cams = "0 0 0 0 0 -5 500 0 0\n";
  struct Case {
    std::string text, expect;
  };
  const Case cases[] = {
      {"1 1\n", "problem.txt:1: unexpected end of file, expected number of observations"},
      {"1 0 1\n", "problem.txt:1: header counts"},
      {"1 1 x\n", "problem.txt:1: number of observations: 'x' is not an integer"},
      {"1 1 1\n0 3 1 2\n" + cams + "1 2 3\n", "problem.txt:2: observation 0: point index 3"},
      {"1 1 1\n2 0 1 2\n" + cams + "1 2 3\n", "problem.txt:2: observation 0: camera index 2"},
      {"1 1 1\n0 0 1 inf\n" + cams + "1 2 3\n", "problem.txt:2: observation 0 y"},
      {"1 1 1\n0 0 1 2\n0 0 0\n0 0 -5\n-1 0 0\n1 2 3\n", "problem.txt:5: camera 0: focal"},
      {"1 1 1\n0 0 1 2\n0 0 0 0 q 0 1 0 0\n1 2 3\n", "problem.txt:3: camera 0 parameter t2"},
      {"1 1 1\n0 0 1 2\n" + cams + "1 2\n",
       "unexpected end of file, expected point 0 coordinate 2"},
      {"1 1 1\n0 0 1 2\n" + cams + "1 2 3\n\n7\n", "problem.txt:6: trailing content"},
  };
  for (const Case& c : cases) {
    INFO(c.text);
    CHECK_THROWS_WITH(parse_bal(c.text), Catch::Contains(c.expect));
    CHECK_THROWS_AS(parse_bal(c.text), InvalidArgument);
  }
  CHECK_THROWS_WITH(io::read_bal("/nonexistent/p.txt"), Catch::Contains("/nonexistent/p.txt"));
}

TEST_CASE("BAL reader loads the Dubrovnik subsets and their observations reproject",
          "[io][bal][data]") {
  struct Expect {
    const char* file;
    std::size_t cams, points, obs;
  };
  for (const Expect& x :
       {Expect{"dubrovnik-1-1-pre.txt", 1, 1, 1}, Expect{"dubrovnik-3-7-pre.txt", 3, 7, 19},
        Expect{"dubrovnik-3-7-18-pre.txt", 3, 7, 18}}) {
    const io::BalProblem p =
        io::read_bal(std::string(GEODRIFT_DATA_DIR "/gtsam_examples_data/") + x.file);
    INFO(x.file);
    CHECK(p.cameras.size() == x.cams);
    CHECK(p.points.size() == x.points);
    CHECK(p.observations.size() == x.obs);
    // Every observation reprojects near its pixel under BAL's model, which pins the
    // -z / y-up convention.
    // A flipped y or z convention gives errors of hundreds of pixels; the subsets' own
    // residuals are a few percent of the radius (RMS 11-20 px).
    double sum2 = 0.0;
    for (const io::BalObservation& o : p.observations) {
      Eigen::Vector2d px = Eigen::Vector2d::Zero();
      REQUIRE(io::bal_project(p.cameras[static_cast<std::size_t>(o.camera)],
                              p.points[static_cast<std::size_t>(o.point)], &px));
      CHECK((px - o.pixel).norm() < 0.06 * o.pixel.norm() + 2.0);
      sum2 += (px - o.pixel).squaredNorm();
    }
    CHECK(std::sqrt(sum2 / static_cast<double>(p.observations.size())) < 25.0);
  }
}

TEST_CASE("VO readers parse calibration, poses and stereo factors", "[io][vo]") {
  {
    std::istringstream in(
        "718.856 718.856 0.0 607.1928 185.2157 0.53716571890  1  0  0  0  0  1 "
        " 0  0 -0  0  1  0  0  0  0  1");
    const io::VoCalibration c = io::parse_vo_calibration(in, "calib.txt");
    CHECK(c.fx == 718.856);
    CHECK(c.cy == 185.2157);
    CHECK(c.baseline == 0.5371657189);
  }
  {
    std::istringstream in("3 0 -1 0 1  1 0 0 2  0 0 1 3  0 0 0 1\n");
    const auto poses = io::parse_vo_camera_poses(in, "poses.txt");
    REQUIRE(poses.size() == 1);
    CHECK(poses[0].id == 3);
    const Eigen::Matrix4d T = poses[0].T_cw() * poses[0].T_wc;
    CHECK(T.isApprox(Eigen::Matrix4d::Identity()));
    CHECK(poses[0].T_cw().topRightCorner<3, 1>().isApprox(Eigen::Vector3d(-2, 1, -3)));
  }
  {
    std::istringstream in("0 7 322.5 299.5 11.6 -6.6 -4.0 16.7\n\n2 9 1 2 3 4 5 6\n");
    const auto f = io::parse_vo_stereo_factors(in, "factors.txt");
    REQUIRE(f.size() == 2);
    CHECK(f[1].camera == 2);
    CHECK(f[1].landmark == 9);
    CHECK(f[0].u_right == 299.5);
    CHECK(f[0].point_camera.isApprox(Eigen::Vector3d(-6.6, -4.0, 16.7)));
  }
  struct Case {
    int kind;
    std::string text, expect;
  };
  const Case cases[] = {
      {0, "718 718 0 607 185", "calib.txt:1: calibration needs 6 numbers"},
      {0, "\n718 -718 0 607 185 0.5", "calib.txt:2: fx, fy and baseline must be > 0"},
      {0, "", "calib.txt:0: no calibration line"},
      {1, "1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n", "poses.txt:1: pose line needs 17 numbers"},
      {1, "1.5 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "poses.txt:1: pose id 1.5"},
      {1, "1 2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "poses.txt:1: the 3x3 block is not a rotation"},
      {1, "1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 1 1\n", "poses.txt:1: the last row"},
      {1, "1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n",
       "poses.txt:2: duplicate pose id 1 (first on line 1)"},
      {2, "0 7 1 2 3 4 5\n", "factors.txt:1: stereo factor needs 8 numbers"},
      {2, "0 7 1 2 3 4 5 6\n0 7 1 2 3 4 5 -6\n", "factors.txt:2: landmark depth Z = -6"},
      {2, "0 7 1 2 3 4 x 6\n", "factors.txt:1: field 7: 'x' is not a finite number"},
      {2, "-1 7 1 2 3 4 5 6\n", "factors.txt:1: camera id -1"},
  };
  for (const Case& c : cases) {
    INFO(c.text);
    std::istringstream in(c.text);
    if (c.kind == 0) {
      CHECK_THROWS_WITH(io::parse_vo_calibration(in, "calib.txt"), Catch::Contains(c.expect));
    } else if (c.kind == 1) {
      CHECK_THROWS_WITH(io::parse_vo_camera_poses(in, "poses.txt"), Catch::Contains(c.expect));
    } else {
      CHECK_THROWS_WITH(io::parse_vo_stereo_factors(in, "factors.txt"), Catch::Contains(c.expect));
    }
  }
  CHECK_THROWS_WITH(io::read_vo_calibration("/nonexistent/c.txt"),
                    Catch::Contains("/nonexistent/c.txt"));
}

TEST_CASE("VO readers load the KITTI 00 tracks consistently", "[io][vo][data]") {
  const std::string dir = GEODRIFT_DATA_DIR "/gtsam_examples_data/";
  const io::VoCalibration K = io::read_vo_calibration(dir + "VO_calibration00s.txt");
  const auto poses = io::read_vo_camera_poses(dir + "VO_camera_poses00s.txt");
  const auto obs = io::read_vo_stereo_factors(dir + "VO_stereo_factors00s.txt");
  CHECK(K.fx == 718.856);
  CHECK(K.cx == 607.1928);
  REQUIRE(poses.size() == 77);
  CHECK(poses.front().id == 0);
  CHECK(poses.back().id == 76);
  REQUIRE(obs.size() == 52544);
  // The landmark's camera-frame point reprojects to the left observation, and stereo
  // disparity matches depth: uL - uR = fx·b/Z (both to sub-pixel accuracy).
  int bad = 0;
  for (const io::VoStereoObservation& o : obs) {
    const Eigen::Vector3d& P = o.point_camera;
    const double u = K.fx * P.x() / P.z() + K.cx, v = K.fy * P.y() / P.z() + K.cy;
    const double disparity = K.fx * K.baseline / P.z();
    if (std::abs(u - o.u_left) > 0.5 || std::abs(v - o.v) > 0.5 ||
        std::abs(disparity - (o.u_left - o.u_right)) > 0.5) {
      ++bad;
    }
  }
  CHECK(bad == 0);
  // Poses are camera -> world with the camera moving forward along +z (KITTI 00 start).
  CHECK(poses[76].T_wc(2, 3) > 30.0);
}
