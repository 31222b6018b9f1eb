// Two-view initialisation on the real Balbianello photos against their Bundler reconstruction,
// and its clean failure on pure rotation.

#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <string>
#include <vector>

#include "geodrift/vo/features.hpp"
#include "geodrift/vo/two_view.hpp"

using namespace geodrift;

namespace {

struct BundlerCamera {
  double f = 0, k1 = 0, k2 = 0;
  Eigen::Matrix3d R;  // OpenCV convention (x right, y down, z forward), world -> camera
  Eigen::Vector3d t;
};

/// Bundler v0.3: per camera "f k1 k2", R (3 rows), t; Bundler cameras look down -z with y up,
/// so OpenCV's camera is diag(1, -1, -1) times Bundler's.
std::vector<BundlerCamera> read_bundler(const std::string& path) {
  std::ifstream in(path);
  std::string header;
  std::getline(in, header);
  int nc = 0, np = 0;
  in >> nc >> np;
  std::vector<BundlerCamera> cams(static_cast<std::size_t>(nc));
  const Eigen::Matrix3d F = Eigen::Vector3d(1, -1, -1).asDiagonal();
  for (auto& c : cams) {
    in >> c.f >> c.k1 >> c.k2;
    for (int r = 0; r < 3; ++r) in >> c.R(r, 0) >> c.R(r, 1) >> c.R(r, 2);
    in >> c.t.x() >> c.t.y() >> c.t.z();
    c.R = F * c.R;
    c.t = F * c.t;
  }
  return cams;
}

struct View {
  vo::Features feats;
  std::vector<Eigen::Vector2d> uv;  // pixels in the common camera (focal f0)
};

/// Undistorts with the Bundler intrinsics (principal point at the centre) and rescales pixels
/// to the common focal length f0, so both views share one pinhole camera.
View load_view(const std::string& file, const BundlerCamera& c, double f0,
               const vo::OrbExtractor& orb) {
  const cv::Mat gray = cv::imread(file, cv::IMREAD_GRAYSCALE);
  REQUIRE(!gray.empty());
  const double cx = gray.cols / 2.0, cy = gray.rows / 2.0;
  const cv::Matx33d K(c.f, 0, cx, 0, c.f, cy, 0, 0, 1);
  cv::Mat und;
  cv::undistort(gray, und, K, std::vector<double>{c.k1, c.k2, 0, 0});
  View v;
  v.feats = orb.extract(und);
  for (const auto& kp : v.feats.keypoints)
    v.uv.emplace_back((kp.pt.x - cx) * f0 / c.f + cx, (kp.pt.y - cy) * f0 / c.f + cy);
  return v;
}

/// Nearest-neighbour matches with Lowe's ratio test and a mutual check.
std::vector<std::pair<int, int>> match(const vo::Features& a, const vo::Features& b) {
  const auto nn = [](const cv::Mat& da, const cv::Mat& db, int i, int* second) {
    int best = 256, bk = -1;
    *second = 256;
    for (int k = 0; k < db.rows; ++k) {
      const int d = vo::hamming(da.ptr<std::uint8_t>(i), db.ptr<std::uint8_t>(k));
      if (d < best) {
        *second = best;
        best = d;
        bk = k;
      } else if (d < *second) {
        *second = d;
      }
    }
    return std::make_pair(bk, best);
  };
  std::vector<std::pair<int, int>> m;
  for (int i = 0; i < a.descriptors.rows; ++i) {
    int s1, s2;
    const auto [j, d] = nn(a.descriptors, b.descriptors, i, &s1);
    if (j < 0 || d > 64 || d > 0.8 * s1) continue;
    if (nn(b.descriptors, a.descriptors, j, &s2).first != i) continue;
    m.emplace_back(i, j);
  }
  return m;
}

double angle_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / M_PI;
}

}  // namespace

TEST_CASE("Two-view initialisation on real Balbianello pairs agrees with Bundler", "[vo][data]") {
  const std::string dir = std::string(GEODRIFT_DATA_DIR) + "/gtsam_examples_data/";
  if (!GEODRIFT_HAVE_DATA) {
    WARN("no test data at " << dir);
    return;
  }
  const auto cams = read_bundler(dir + "Balbianello.out");
  REQUIRE(cams.size() == 5);
  vo::OrbOptions oo;
  oo.num_features = 5000;
  oo.fast_threshold = 8;
  const vo::OrbExtractor orb(oo);
  const double f0 = cams[0].f;
  std::vector<View> views;
  for (int i = 0; i < 5; ++i)
    views.push_back(
        load_view(dir + "Balbianello/BalbianelloMedium-" + std::to_string(i + 1) + ".jpg",
                  cams[static_cast<std::size_t>(i)], f0, orb));
  map::Camera cam;
  cam.fx = cam.fy = f0;
  cam.cx = 320;
  cam.cy = 213.5;
  cam.width = 640;
  cam.height = 427;
  int tested = 0;
  for (int i = 0; i + 1 < 5; ++i) {
    const int j = i + 1;
    const auto m = match(views[i].feats, views[j].feats);
    std::vector<Eigen::Vector2d> x1, x2;
    for (const auto& [a, b] : m) {
      x1.push_back(views[i].uv[a]);
      x2.push_back(views[j].uv[b]);
    }
    const vo::TwoViewResult r = vo::initialize_two_view(x1, x2, cam);
    const BundlerCamera &ci = cams[i], &cj = cams[j];
    const Eigen::Matrix3d R21 = cj.R * ci.R.transpose();
    const Eigen::Vector3d t21 = cj.t - R21 * ci.t;
    const Eigen::Matrix3d dR = r.T_21.rotation().matrix() * R21.transpose();
    const double rot_err = Eigen::AngleAxisd(dR).angle() * 180.0 / M_PI;
    const double dir_err = angle_deg(r.T_21.translation(), t21);
    INFO("pair " << i + 1 << "-" << j + 1 << ": " << m.size() << " matches, ok " << r.ok << " ("
                 << r.reason << "), model "
                 << (r.model == vo::TwoViewResult::Model::kHomography ? "H" : "E") << ", "
                 << r.num_good << " points, parallax " << r.parallax_deg << " deg; rotation error "
                 << rot_err << " deg, translation direction error " << dir_err
                 << " deg; true rotation " << Eigen::AngleAxisd(R21).angle() * 180 / M_PI
                 << " deg");
    REQUIRE(r.ok);
    CHECK(rot_err < 2.0);
    CHECK(dir_err < 5.0);
    ++tested;
  }
  CHECK(tested == 4);
}

TEST_CASE("Two-view initialisation refuses pure rotation with a reason", "[vo][data]") {
  const std::string file =
      std::string(GEODRIFT_DATA_DIR) + "/gtsam_examples_data/Balbianello/BalbianelloMedium-1.jpg";
  if (!GEODRIFT_HAVE_DATA) {
    WARN("no test data at " << file);
    return;
  }
  const cv::Mat gray = cv::imread(file, cv::IMREAD_GRAYSCALE);
  REQUIRE(!gray.empty());
  map::Camera cam;
  cam.fx = cam.fy = 520;
  cam.cx = 320;
  cam.cy = 213.5;
  cam.width = gray.cols;
  cam.height = gray.rows;
  const Eigen::Matrix3d K = (Eigen::Matrix3d() << 520, 0, 320, 0, 520, 213.5, 0, 0, 1).finished();
  // The second view rotates 4 degrees about the y axis and 1 about x: H = K R K^-1.
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(4 * M_PI / 180, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(1 * M_PI / 180, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  const Eigen::Matrix3d H = K * R * K.inverse();
  cv::Matx33d Hcv;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) Hcv(r, c) = H(r, c);
  cv::Mat rotated;
  cv::warpPerspective(gray, rotated, Hcv, gray.size());
  const vo::OrbExtractor orb;
  const vo::Features a = orb.extract(gray), b = orb.extract(rotated);
  const auto m = match(a, b);
  std::vector<Eigen::Vector2d> x1, x2;
  for (const auto& [i, j] : m) {
    x1.emplace_back(a.keypoints[i].pt.x, a.keypoints[i].pt.y);
    x2.emplace_back(b.keypoints[j].pt.x, b.keypoints[j].pt.y);
  }
  REQUIRE(x1.size() >= 200);
  const vo::TwoViewResult r = vo::initialize_two_view(x1, x2, cam);
  INFO(r.reason << "; parallax " << r.parallax_deg);
  CHECK_FALSE(r.ok);
  CHECK(r.model == vo::TwoViewResult::Model::kHomography);
  CHECK((r.reason.find("parallax") != std::string::npos ||
         r.reason.find("pure rotation") != std::string::npos));
}

TEST_CASE("ORB Hamming distance counts differing bits", "[vo]") {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < 1000; ++trial) {
    std::uint8_t a[32], b[32];
    int expected = 0;
    for (int i = 0; i < 32; ++i) {
      a[i] = static_cast<std::uint8_t>(rng());
      b[i] = static_cast<std::uint8_t>(rng());
      for (int bit = 0; bit < 8; ++bit) expected += ((a[i] ^ b[i]) >> bit) & 1;
    }
    REQUIRE(vo::hamming(a, b) == expected);
  }
  std::uint8_t z[32] = {}, o[32];
  std::memset(o, 0xff, sizeof o);
  CHECK(vo::hamming(z, o) == 256);
  CHECK(vo::hamming(o, o) == 0);
}
