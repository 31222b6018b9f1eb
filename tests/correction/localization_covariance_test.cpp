// Covariance of a PnP + LM pose (correction::pnp_pose_covariance) against a Monte-Carlo
// estimate, the centre covariance's Jacobian against central differences, and the geo-term
// weighting by localization uncertainty in the Corrector.
#include "geodrift/correction/localization_covariance.hpp"

#include <catch2/catch.hpp>
#include <random>

#include "geodrift/correction/corrector.hpp"
#include "geodrift/correction/pose_refinement.hpp"
#include "support/numeric_jacobian.hpp"

using namespace geodrift;

namespace {
const map::Camera kCam{0, 718.856, 718.856, 607.19, 185.22, 1241, 376};

/// A street-like PnP: n points on two facades and the ground 6-40 m ahead of a camera at
/// T_cw, all inside the image.
std::vector<Eigen::Vector3d> street_points(const lie::SE3d& T_cw, int n, std::mt19937* rng) {
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Eigen::Vector3d> X;
  const lie::SE3d T_wc = T_cw.inverse();
  while (static_cast<int>(X.size()) < n) {
    const double z = 6 + 34 * u(*rng);
    const int kind = static_cast<int>(X.size()) % 3;
    const double x = kind == 0 ? -7.0 : kind == 1 ? 7.0 : -5 + 10 * u(*rng);
    const double y = kind == 2 ? 1.6 : -6 + 7 * u(*rng);  // camera y down: ground at +1.6
    const Eigen::Vector3d p(x, y, z);
    if (!kCam.in_image(kCam.project(p))) continue;
    X.push_back(T_wc.act(p));
  }
  return X;
}

Eigen::Matrix<double, 6, 6> sample_covariance(const std::vector<Eigen::Matrix<double, 6, 1>>& d) {
  Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
  for (const auto& x : d) mean += x;
  mean /= static_cast<double>(d.size());
  Eigen::Matrix<double, 6, 6> C = Eigen::Matrix<double, 6, 6>::Zero();
  for (const auto& x : d) C += (x - mean) * (x - mean).transpose();
  return C / static_cast<double>(d.size() - 1);
}
}  // namespace

TEST_CASE("PnP pose covariance matches a Monte-Carlo estimate", "[correction][covariance]") {
  const lie::SE3d T_true(lie::SO3d::exp(Eigen::Vector3d(0.05, -0.3, 0.02)),
                         Eigen::Vector3d(1.5, -0.4, 3.0));
  std::mt19937 rng(2024);
  const std::vector<Eigen::Vector3d> X = street_points(T_true, 40, &rng);
  std::vector<Eigen::Vector2d> u_true;
  for (const auto& x : X) u_true.push_back(kCam.project(T_true.act(x)));

  for (double noise_px : {1.0, 3.0}) {
    INFO("pixel noise " << noise_px << " px");
    std::normal_distribution<double> n01(0, 1);
    const int trials = 1500;
    std::vector<Eigen::Matrix<double, 6, 1>> deltas;
    Eigen::Matrix<double, 6, 6> predicted = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix3d predicted_centre = Eigen::Matrix3d::Zero();
    std::vector<Eigen::Vector3d> centre_err;
    double sigma_sum = 0;
    for (int t = 0; t < trials; ++t) {
      std::vector<Eigen::Vector2d> u = u_true;
      for (auto& p : u) p += noise_px * Eigen::Vector2d(n01(rng), n01(rng));
      const correction::PnpResult r = correction::refine_pose_lm(X, u, kCam, T_true, 50);
      REQUIRE(r.converged);
      REQUIRE(r.covariance.ok);
      deltas.push_back((r.T_cw * T_true.inverse()).log());  // T_est = exp(δ)·T_true
      predicted += r.covariance.pose;
      predicted_centre += r.covariance.center;
      centre_err.push_back(r.T_cw.inverse().translation() - T_true.inverse().translation());
      sigma_sum += r.covariance.sigma_px;
    }
    predicted /= trials;
    predicted_centre /= trials;
    const Eigen::Matrix<double, 6, 6> mc = sample_covariance(deltas);
    // σ̂ is the residual SD, unbiased in σ² with the 2n − 6 degrees of freedom.
    CHECK(sigma_sum / trials == Approx(noise_px).epsilon(0.03));
    // Each variance within 12 % (the sampling SD of a variance from 1,500 draws is 3.7 %).
    for (int i = 0; i < 6; ++i) {
      INFO("tangent component " << i << ": predicted " << predicted(i, i) << ", Monte Carlo "
                                << mc(i, i));
      CHECK(predicted(i, i) == Approx(mc(i, i)).epsilon(0.12));
    }
    // The whole matrix (correlations too): relative Frobenius difference in whitened form.
    const Eigen::Matrix<double, 6, 6> W =
        predicted.llt().matrixL().solve(Eigen::Matrix<double, 6, 6>::Identity());  // L⁻¹
    const Eigen::Matrix<double, 6, 6> whitened = W * mc * W.transpose();
    INFO("whitened Monte-Carlo covariance\n" << whitened);
    CHECK((whitened - Eigen::Matrix<double, 6, 6>::Identity()).norm() < 0.25);
    // Camera centre: Monte-Carlo covariance of the solved centres vs the predicted one.
    Eigen::Matrix3d mc_c = Eigen::Matrix3d::Zero();
    Eigen::Vector3d mean_c = Eigen::Vector3d::Zero();
    for (const auto& e : centre_err) mean_c += e;
    mean_c /= trials;
    for (const auto& e : centre_err) mc_c += (e - mean_c) * (e - mean_c).transpose();
    mc_c /= trials - 1;
    INFO("centre covariance predicted\n" << predicted_centre << "\nMonte Carlo\n" << mc_c);
    CHECK(predicted_centre.trace() == Approx(mc_c.trace()).epsilon(0.10));
    CHECK((predicted_centre - mc_c).norm() < 0.15 * mc_c.norm());
    // The localization SD in metres at map scale s (M units per metre).
    CHECK(correction::localization_sd_m(predicted, 2.0) ==
          Approx(std::sqrt(predicted_centre.trace() / 3.0) / 2.0).epsilon(1e-9));
  }
}

TEST_CASE("Centre covariance uses the centre's Jacobian under the left perturbation",
          "[correction][covariance]") {
  const lie::SE3d T(lie::SO3d::exp(Eigen::Vector3d(0.4, -0.7, 1.1)), Eigen::Vector3d(2, -1, 5));
  const Eigen::MatrixXd J = test::numeric_jacobian<lie::SE3d>(
      [](const lie::SE3d& X) -> Eigen::VectorXd { return X.inverse().translation(); }, T);
  // Any covariance: compare J Σ Jᵀ with center_covariance().
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Random();
  const Eigen::Matrix<double, 6, 6> S = A * A.transpose();
  const Eigen::Matrix3d expected = J * S * J.transpose();
  CHECK(test::near(correction::center_covariance(S, T), expected, 1e-6));
}

TEST_CASE("PnP pose covariance refuses too few points and a size mismatch",
          "[correction][covariance]") {
  const lie::SE3d T;
  std::vector<Eigen::Vector3d> X = {{0, 0, 10}, {1, 0, 10}, {0, 1, 10}};
  std::vector<Eigen::Vector2d> u;
  for (const auto& x : X) u.push_back(kCam.project(x));
  const correction::PnpCovariance c = correction::pnp_pose_covariance(X, u, kCam, T);
  CHECK_FALSE(c.ok);
  CHECK_THAT(c.why, Catch::Contains("need at least 4"));
  u.pop_back();
  CHECK_THROWS_WITH(correction::pnp_pose_covariance(X, u, kCam, T),
                    Catch::Contains("3 points but 2 pixels"));
  // Points all on one ray from the camera centre: JᵀJ is singular.
  std::vector<Eigen::Vector3d> ray;
  std::vector<Eigen::Vector2d> ur;
  for (int i = 1; i <= 6; ++i) {
    ray.push_back(Eigen::Vector3d(0.1, 0.1, 1.0) * (4.0 * i));
    ur.push_back(kCam.project(ray.back()));
  }
  const correction::PnpCovariance d = correction::pnp_pose_covariance(ray, ur, kCam, T);
  CHECK_FALSE(d.ok);
  CHECK_THAT(d.why, Catch::Contains("singular"));
}

TEST_CASE("Effective geo-term SD combines geo-tag and localization SDs", "[correction]") {
  CHECK(correction::effective_geo_sd_m(0.05, 0.0) == Approx(0.05));
  CHECK(correction::effective_geo_sd_m(0.3, 0.4) == Approx(0.5));
  Eigen::Matrix<double, 6, 6> P = Eigen::Matrix<double, 6, 6>::Zero();
  CHECK(correction::localization_sd_m(P, 1.0) == 0.0);
  P.block<3, 3>(3, 3) = Eigen::Vector3d(0.01, 0.04, 0.07).asDiagonal();  // tr = 0.12 M units²
  // √(0.12 / 3) = 0.2 M units, at 0.5 M units per metre: 0.4 m.
  CHECK(correction::localization_sd_m(P, 0.5) == Approx(0.4));
}
