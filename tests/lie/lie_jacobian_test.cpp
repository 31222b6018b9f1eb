// Every analytic Jacobian of SO3 / SE3 / Sim3 against central differences under the same LEFT
// perturbation, over ≥ 1,000 seeded samples per group including the hard regions
// (tests/support/samples.hpp). Tolerance: |J − J_num| ≤ 1e-6·(1 + |J_num|) elementwise plus the
// rounding floor of a central difference of a function of that magnitude
// (test::rounding_floor), so 1e4 m translations are not mistaken for errors while a wrong or
// dropped term (≥ 1e-3 relative) is caught.

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"
#include "support/numeric_jacobian.hpp"
#include "support/samples.hpp"

#include <Eigen/Core>
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <random>

namespace lie = geodrift::lie;
namespace test = geodrift::test;
using lie::SE3d;
using lie::Sim3d;
using lie::SO3d;

namespace {

constexpr int kNumSamples = 1000;
constexpr double kTol = 1e-6;
constexpr double kStep = 1e-6;

template <class Group>
double magnitude(const Group& X) {
  return X.matrix().cwiseAbs().maxCoeff();
}

// Rotation angle of X (θ of its log), to keep the step of a log difference away from θ = π,
// where log jumps to the antipodal branch.
template <class Group>
double angle(const Group& X) {
  return X.log().template head<3>().norm();
}

}  // namespace

TEMPLATE_TEST_CASE("exp Jacobian is the left Jacobian and matches central differences",
                   "[lie][jacobian]", SO3d, SE3d, Sim3d) {
  using Tangent = typename TestType::Tangent;
  std::mt19937 rng(42);
  const auto xis = test::tangent_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xis.size(); ++k) {
    const Tangent& xi = xis[k];
    typename TestType::Jacobian J;
    const TestType E = TestType::exp(xi, &J);
    const auto f = [](const Tangent& x) { return TestType::exp(x); };
    const Eigen::MatrixXd Jn = test::numeric_group_jacobian_vector(f, xi, kStep);
    const double floor =
        test::rounding_floor(std::max(magnitude(E), xi.cwiseAbs().maxCoeff()), kStep);
    INFO("sample " << k << ": xi = " << xi.transpose());
    CHECK(test::near(J, Jn, kTol, floor));
    // left_jacobian() is the same matrix exp() returns.
    CHECK(test::near(TestType::left_jacobian(xi), J, 0.0));
    // ... and left_jacobian_inverse(ξ) is the Jacobian of log at exp(ξ) (left_jacobian
    // consistency: d log/dδ ∘ d exp/dξ = I).
    typename TestType::Jacobian Jlog;
    E.log(&Jlog);
    CHECK(test::near(TestType::left_jacobian_inverse(xi), Jlog, 1e-9,
                     1e-14 * J.cwiseAbs().maxCoeff() * Jlog.cwiseAbs().maxCoeff()));
  }
}

TEMPLATE_TEST_CASE("log Jacobian matches central differences", "[lie][jacobian]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(43);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xs.size(); ++k) {
    const TestType& X = xs[k];
    typename TestType::Jacobian J;
    const typename TestType::Tangent xi = X.log(&J);
    // Stay a few steps inside θ < π so both sides of the difference are on the same branch.
    const double h = std::min(kStep, (M_PI - angle(X)) / 4.0);
    const auto f = [](const TestType& Y) { return Y.log(); };
    const Eigen::MatrixXd Jn = test::numeric_jacobian(f, X, h);
    const double floor = test::rounding_floor(std::max(magnitude(X), xi.cwiseAbs().maxCoeff()), h);
    INFO("sample " << k << ": X = " << X << "\nlog X = " << xi.transpose() << "\nh = " << h);
    CHECK(test::near(J, Jn, kTol, floor));
  }
}

TEMPLATE_TEST_CASE("compose Jacobians match central differences", "[lie][jacobian]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(44);
  const auto as = test::group_samples<TestType>(rng, kNumSamples);
  const auto bs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < as.size(); ++k) {
    const TestType& a = as[k];
    const TestType& b = bs[bs.size() - 1 - k];  // pair hard samples with random ones
    typename TestType::Jacobian Ja, Jb;
    const TestType ab = a.compose(b, &Ja, &Jb);
    const auto fa = [&](const TestType& x) { return x * b; };
    const auto fb = [&](const TestType& x) { return a * x; };
    const double floor =
        test::rounding_floor(std::max({magnitude(a), magnitude(b), magnitude(ab)}), kStep);
    INFO("sample " << k << ": a = " << a << "\nb = " << b);
    CHECK(test::near(Ja, test::numeric_group_jacobian(fa, a, kStep), kTol, floor));
    CHECK(test::near(Jb, test::numeric_group_jacobian(fb, b, kStep), kTol, floor));
  }
}

TEMPLATE_TEST_CASE("inverse Jacobian matches central differences", "[lie][jacobian]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(45);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xs.size(); ++k) {
    const TestType& X = xs[k];
    typename TestType::Jacobian J;
    const TestType Xi = X.inverse(&J);
    const auto f = [](const TestType& Y) { return Y.inverse(); };
    const double floor = test::rounding_floor(std::max(magnitude(X), magnitude(Xi)), kStep);
    INFO("sample " << k << ": X = " << X);
    CHECK(test::near(J, test::numeric_group_jacobian(f, X, kStep), kTol, floor));
  }
}

TEMPLATE_TEST_CASE("act Jacobians match central differences", "[lie][jacobian]", SO3d, SE3d,
                   Sim3d) {
  using Point = typename TestType::Point;
  std::mt19937 rng(46);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xs.size(); ++k) {
    const TestType& X = xs[k];
    const Point p = test::random_translation(rng);
    Eigen::Matrix<double, 3, TestType::kDoF> J_X;
    Eigen::Matrix3d J_p;
    const Point q = X.act(p, &J_X, &J_p);
    Point q_ref;
    if constexpr (TestType::kDoF == 3) {
      q_ref = X.matrix() * p;
    } else {
      q_ref = (X.matrix() * p.homogeneous()).template head<3>();
    }
    CHECK(test::near(q, q_ref, 1e-12, 1e-14 * magnitude(X) * p.norm()));
    const auto fX = [&](const TestType& Y) { return Y.act(p); };
    const auto fp = [&](const Point& y) { return X.act(y); };
    const double floor = test::rounding_floor(
        std::max({magnitude(X), p.cwiseAbs().maxCoeff(), q.cwiseAbs().maxCoeff()}), kStep);
    INFO("sample " << k << ": X = " << X << "\np = " << p.transpose());
    CHECK(test::near(J_X, test::numeric_jacobian(fX, X, kStep), kTol, floor));
    CHECK(test::near(J_p, test::numeric_jacobian_vector(fp, p, kStep), kTol, floor));
  }
}
