// Properties of SO3 / SE3 / Sim3: group axioms, exp/log round trips, adjoint identity,
// Jl·Jl⁻¹ = I, closed forms against Eigen's matrix exponential, conversions, bad input, float.

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <cmath>
#include <complex>
#include <limits>
#include <random>
#include <sstream>
#include <type_traits>
#include <unsupported/Eigen/MatrixFunctions>

#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"
#include "support/numeric_jacobian.hpp"
#include "support/samples.hpp"

// Every member of every group template compiles and is covered (STYLE.md §4).
template class geodrift::lie::SO3<double>;
template class geodrift::lie::SE3<double>;
template class geodrift::lie::Sim3<double>;
template class geodrift::lie::SO3<float>;
template class geodrift::lie::SE3<float>;
template class geodrift::lie::Sim3<float>;
template class geodrift::lie::LieGroupBase<geodrift::lie::Sim3<double>>;

namespace lie = geodrift::lie;
namespace test = geodrift::test;
using lie::SE3d;
using lie::Sim3d;
using lie::SO3d;

namespace {

constexpr int kNumSamples = 1000;

// The Lie-algebra matrix of ξ in the group's 3x3 (SO3) or 4x4 (SE3, Sim3) representation.
template <class Group>
Eigen::MatrixXd hat(const typename Group::Tangent& xi) {
  const Eigen::Vector3d w = xi.template head<3>();
  if constexpr (Group::kDoF == 3) {
    return lie::skew<double>(w);
  } else {
    Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
    m.topLeftCorner<3, 3>() = lie::skew<double>(w);
    m.topRightCorner<3, 1>() = xi.template tail<3>();
    if constexpr (Group::kDoF == 7) m.topLeftCorner<3, 3>().diagonal().array() += xi[3];
    return m;
  }
}

// ad_ξ (kDoF x kDoF) in DESIGN.md's order, from the linearised adjoint:
//   so3: [W];  se3: [[W,0],[[ν]x,W]];  sim3: [[W,0,0],[0,0,0],[[ν]x,−ν,W+σI]].
template <class Group>
Eigen::MatrixXd ad(const typename Group::Tangent& xi) {
  const Eigen::Matrix3d W = lie::skew<double>(Eigen::Vector3d(xi.template head<3>()));
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(Group::kDoF, Group::kDoF);
  A.topLeftCorner<3, 3>() = W;
  if constexpr (Group::kDoF >= 6) {
    const Eigen::Vector3d nu = xi.template tail<3>();
    const int n = Group::kDoF - 3;
    A.block<3, 3>(n, 0) = lie::skew<double>(nu);
    A.block<3, 3>(n, n) = W;
    if constexpr (Group::kDoF == 7) {
      A.block<3, 1>(4, 3) = -nu;
      A.block<3, 3>(4, 4) += xi[3] * Eigen::Matrix3d::Identity();
    }
  }
  return A;
}

template <class Group>
double magnitude(const Group& X) {
  return X.matrix().cwiseAbs().maxCoeff();
}

}  // namespace

TEMPLATE_TEST_CASE("Lie groups satisfy the group axioms", "[lie]", SO3d, SE3d, Sim3d) {
  std::mt19937 rng(42);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  const TestType I;
  for (size_t k = 0; k < xs.size(); ++k) {
    const TestType& a = xs[k];
    const TestType b = test::random_element<TestType>(rng);
    const TestType c = test::random_element<TestType>(rng);
    INFO("sample " << k << ": a = " << a << "\nb = " << b << "\nc = " << c);
    CHECK((a * I).is_approx(a, 1e-12));
    CHECK((I * a).is_approx(a, 1e-12));
    CHECK((a * a.inverse()).is_approx(I, 1e-9));
    CHECK((a.inverse() * a).is_approx(I, 1e-9));
    CHECK(((a * b) * c).is_approx(a * (b * c), 1e-9));
    // The homogeneous matrices multiply the same way (operator* really is the group product).
    CHECK(test::near((a * b).matrix(), a.matrix() * b.matrix(), 1e-12,
                     1e-14 * magnitude(a) * magnitude(b)));
    CHECK(test::near(a.inverse().matrix(), a.matrix().inverse(), 1e-9));
    // compose() with Jacobians returns the same product.
    CHECK(a.compose(b).is_approx(a * b, 1e-14));
  }
}

TEMPLATE_TEST_CASE("exp inverts log on group elements", "[lie]", SO3d, SE3d, Sim3d) {
  std::mt19937 rng(42);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xs.size(); ++k) {
    INFO("sample " << k << ": " << xs[k] << "\nlog = " << xs[k].log().transpose());
    CHECK(TestType::exp(xs[k].log()).is_approx(xs[k], 1e-10));
  }
}

TEMPLATE_TEST_CASE("log inverts exp on tangents with angle below pi", "[lie]", SO3d, SE3d, Sim3d) {
  std::mt19937 rng(7);
  const auto xis = test::tangent_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xis.size(); ++k) {
    const typename TestType::Tangent& xi = xis[k];
    const typename TestType::Tangent back = TestType::exp(xi).log();
    INFO("sample " << k << ": xi = " << xi.transpose() << "\nlog(exp(xi)) = " << back.transpose());
    // Near θ = π the rotation is determined to eps/(π−θ) relative in the ν part (C⁻¹ grows).
    CHECK(test::near(back, xi, 1e-9, 1e-12 * xi.cwiseAbs().maxCoeff()));
  }
}

TEMPLATE_TEST_CASE("exp matches the matrix exponential of the algebra element", "[lie]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(11);
  auto xis = test::hard_tangents<TestType>(rng);
  for (int k = 0; k < 300; ++k) xis.push_back(test::random_tangent<TestType>(rng));
  for (size_t k = 0; k < xis.size(); ++k) {
    typename TestType::Tangent xi = xis[k];
    if constexpr (TestType::kDoF > 3) {  // keep |ν| moderate: expm's error scales with ‖ξ‖
      const double n = xi.template tail<3>().norm();
      if (n > 10.0) xi.template tail<3>() *= 10.0 / n;
    }
    const Eigen::MatrixXd ref = hat<TestType>(xi).exp();
    INFO("sample " << k << ": xi = " << xi.transpose());
    CHECK(test::near(TestType::exp(xi).matrix(), ref, 1e-12, 1e-13 * ref.cwiseAbs().maxCoeff()));
  }
}

TEMPLATE_TEST_CASE("left_jacobian equals the series sum of ad^k/(k+1)! (Van Loan)", "[lie]", SO3d,
                   SE3d, Sim3d) {
  // Jl(ξ) = ∫₀¹ exp(s·ad_ξ) ds = upper-right block of exp([ad_ξ I; 0 0]); an independent
  // reference for the closed forms, including the coupled Sim3 (θ, σ) blocks.
  constexpr int n = TestType::kDoF;
  std::mt19937 rng(13);
  auto xis = test::hard_tangents<TestType>(rng);
  for (int k = 0; k < 300; ++k) xis.push_back(test::random_tangent<TestType>(rng));
  for (size_t k = 0; k < xis.size(); ++k) {
    typename TestType::Tangent xi = xis[k];
    if constexpr (TestType::kDoF > 3) {
      const double nn = xi.template tail<3>().norm();
      if (nn > 10.0) xi.template tail<3>() *= 10.0 / nn;
    }
    Eigen::MatrixXd big = Eigen::MatrixXd::Zero(2 * n, 2 * n);
    big.topLeftCorner(n, n) = ad<TestType>(xi);
    big.topRightCorner(n, n).setIdentity();
    const Eigen::MatrixXd ref = big.exp().topRightCorner(n, n);
    const Eigen::MatrixXd Jl = TestType::left_jacobian(xi);
    INFO("sample " << k << ": xi = " << xi.transpose());
    CHECK(test::near(Jl, ref, 1e-10, 1e-12 * ref.cwiseAbs().maxCoeff()));
  }
}

TEMPLATE_TEST_CASE("left_jacobian times left_jacobian_inverse is the identity", "[lie]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(17);
  const auto xis = test::tangent_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xis.size(); ++k) {
    const typename TestType::Jacobian Jl = TestType::left_jacobian(xis[k]);
    const typename TestType::Jacobian Jli = TestType::left_jacobian_inverse(xis[k]);
    const double floor = 1e-14 * Jl.cwiseAbs().maxCoeff() * Jli.cwiseAbs().maxCoeff();
    INFO("sample " << k << ": xi = " << xis[k].transpose());
    CHECK(test::near(Jl * Jli, TestType::Jacobian::Identity(), 1e-10, floor));
    CHECK(test::near(Jli * Jl, TestType::Jacobian::Identity(), 1e-10, floor));
  }
}

TEMPLATE_TEST_CASE("adjoint moves a left increment across the element", "[lie]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(19);
  const auto xs = test::group_samples<TestType>(rng, kNumSamples);
  for (size_t k = 0; k < xs.size(); ++k) {
    const TestType& X = xs[k];
    const typename TestType::Tangent d = 0.1 * test::random_tangent<TestType>(rng);
    INFO("sample " << k << ": X = " << X << "\nd = " << d.transpose());
    CHECK((X * TestType::exp(d) * X.inverse()).is_approx(TestType::exp(X.adjoint() * d), 1e-9));
    // Ad is a homomorphism: Ad(X⁻¹) = Ad(X)⁻¹.
    CHECK(test::near(X.inverse().adjoint() * X.adjoint(), TestType::Jacobian::Identity(), 1e-9,
                     1e-14 * magnitude(X) * magnitude(X.inverse())));
  }
}

TEMPLATE_TEST_CASE("boxplus, boxminus and between follow the left convention", "[lie]", SO3d, SE3d,
                   Sim3d) {
  std::mt19937 rng(23);
  for (int k = 0; k < 200; ++k) {
    const TestType x = test::random_element<TestType>(rng);
    const TestType y = test::random_element<TestType>(rng);
    const typename TestType::Tangent d = 0.3 * test::random_tangent<TestType>(rng);
    INFO("sample " << k);
    CHECK(x.boxplus(d).is_approx(TestType::exp(d) * x, 1e-14));
    CHECK(y.boxplus(x.boxminus(y)).is_approx(x, 1e-9));
    CHECK(test::near(x.boxplus(d).boxminus(x), d, 1e-9, 1e-12 * d.cwiseAbs().maxCoeff()));
    CHECK((x * x.between(y)).is_approx(y, 1e-9));
  }
  std::ostringstream os;
  os << TestType();
  CHECK(os.str().rfind(TestType::kName, 0) == 0);
}

TEMPLATE_TEST_CASE("non-finite tangents are rejected by exp", "[lie]", SO3d, SE3d, Sim3d) {
  for (int i = 0; i < TestType::kDoF; ++i) {
    typename TestType::Tangent xi = TestType::Tangent::Constant(0.1);
    xi[i] = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_AS(TestType::exp(xi), geodrift::InvalidArgument);
    xi[i] = std::numeric_limits<double>::infinity();
    CHECK_THROWS_AS(TestType::exp(xi), geodrift::InvalidArgument);
  }
}

TEST_CASE("SO3 construction normalises quaternions and re-orthonormalises matrices", "[lie][so3]") {
  const Eigen::Quaterniond q(2.0, 0.4, -0.2, 1.0);
  const SO3d R(q);
  CHECK(R.quaternion().norm() == Approx(1.0).epsilon(1e-15));
  CHECK(R.quaternion().isApprox(q.normalized(), 1e-15));

  std::mt19937 rng(29);
  std::normal_distribution<double> n(0.0, 1e-7);
  for (int k = 0; k < 50; ++k) {
    const SO3d truth = test::random_so3(rng);
    Eigen::Matrix3d M = truth.matrix();
    for (int i = 0; i < 9; ++i) M(i) += n(rng);
    const SO3d Rm(M);
    const Eigen::Matrix3d Rn = Rm.matrix();
    CHECK(test::near(Rn * Rn.transpose(), Eigen::Matrix3d::Identity(), 1e-14));
    CHECK(Rm.is_approx(truth, 1e-6));
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(SO3d(Eigen::Quaterniond(0, 0, 0, 0)), geodrift::InvalidArgument);
  CHECK_THROWS_AS(SO3d(Eigen::Quaterniond(nan, 0, 0, 1)), geodrift::InvalidArgument);
  Eigen::Matrix3d bad = Eigen::Matrix3d::Identity();
  bad(0, 0) = -1.0;  // reflection
  CHECK_THROWS_AS(SO3d(bad), geodrift::InvalidArgument);
  bad(0, 0) = nan;
  CHECK_THROWS_AS(SO3d(bad), geodrift::InvalidArgument);
}

TEST_CASE("SO3 log is accurate near pi", "[lie][so3]") {
  for (double eps : {1e-3, 1e-6, 1e-9, 0.0}) {
    const Eigen::Vector3d axis = Eigen::Vector3d(1.0, -2.0, 0.5).normalized();
    const double angle = M_PI - eps;
    const SO3d R(Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis)));
    const Eigen::Vector3d w = R.log();
    INFO("eps " << eps << " log " << w.transpose());
    CHECK(w.norm() == Approx(angle).epsilon(1e-15));
    CHECK(std::abs(std::abs(w.normalized().dot(axis)) - 1.0) < 1e-14);
    // Through the matrix constructor too (Eigen's matrix→quaternion is Shepperd's method).
    CHECK(SO3d(R.matrix()).log().norm() == Approx(angle).epsilon(1e-14));
  }
}

TEST_CASE("SE3 and Sim3 validate their parts and name the bad value", "[lie][sim3]") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const SO3d R;
  const Eigen::Vector3d t(1, 2, 3);
  CHECK_THROWS_AS(SE3d(R, Eigen::Vector3d(nan, 0, 0)), geodrift::InvalidArgument);
  CHECK_THROWS_AS(Sim3d(R, Eigen::Vector3d(0, inf, 0), 1.0), geodrift::InvalidArgument);
  for (double s : {0.0, -1.0, nan, inf}) {
    INFO("scale " << s);
    CHECK_THROWS_AS(Sim3d(R, t, s), geodrift::InvalidArgument);
  }
  CHECK_THROWS_WITH(Sim3d(R, t, -2.5), Catch::Contains("scale") && Catch::Contains("-2.5"));
  CHECK_NOTHROW(Sim3d(R, t, 1e-12));
}

TEST_CASE("Sim3 converts to and from SE3 as DESIGN.md says", "[lie][sim3]") {
  std::mt19937 rng(31);
  for (int k = 0; k < 100; ++k) {
    const SE3d T = test::random_se3(rng);
    const Sim3d S(T);
    CHECK(S.scale() == 1.0);
    CHECK(test::near(S.matrix(), T.matrix(), 0.0));
    CHECK(S.to_se3().is_approx(T, 1e-15));

    const Sim3d S2 = test::random_sim3(rng);
    const SE3d T2 = S2.to_se3();  // [R | t/s]
    CHECK(T2.rotation().is_approx(S2.rotation(), 1e-15));
    CHECK(test::near(T2.translation(), S2.translation() / S2.scale(), 1e-15));
    // The camera centre c = −(1/s)·Rᵀ·t of S_cw is kept.
    const Eigen::Vector3d c_sim = -(S2.rotation().inverse().act(S2.translation())) / S2.scale();
    const Eigen::Vector3d c_se3 = -(T2.rotation().inverse().act(T2.translation()));
    CHECK(test::near(c_se3, c_sim, 1e-12, 1e-14 * c_sim.norm()));
  }
}

TEST_CASE("Lie groups work in float and cast between scalar types", "[lie]") {
  std::mt19937 rng(37);
  for (int k = 0; k < 100; ++k) {
    const Sim3d S = test::random_sim3(rng);
    const lie::Sim3f Sf = S.cast<float>();
    const Sim3d back = Sf.cast<double>();
    CHECK(back.is_approx(S, 1e-6));
    const lie::SE3f Tf = S.to_se3().cast<float>();
    CHECK(Tf.cast<double>().is_approx(S.to_se3(), 1e-6));

    const Eigen::Matrix<float, 7, 1> xi = test::random_tangent<Sim3d>(rng).cast<float>() * 1e-2f;
    lie::Sim3f::Jacobian J, Ji;
    const lie::Sim3f E = lie::Sim3f::exp(xi, &J);
    const Eigen::Matrix<float, 7, 1> xi_back = E.log(&Ji);
    INFO("xi " << xi.transpose() << "\nback " << xi_back.transpose());
    CHECK(test::near(xi_back, xi, 1e-4, 1e-5f * xi.cwiseAbs().maxCoeff()));
    CHECK(test::near(J * lie::Sim3f::left_jacobian_inverse(xi),
                     Eigen::Matrix<float, 7, 7>::Identity(), 1e-4,
                     1e-4f * J.cwiseAbs().maxCoeff()));
    const lie::SO3f Rf = lie::SO3f::exp(Eigen::Vector3f(0.1f, -0.2f, 0.3f));
    CHECK(Rf.log().isApprox(Eigen::Vector3f(0.1f, -0.2f, 0.3f), 1e-5f));
  }
}

TEST_CASE("Taylor branches agree with the closed forms evaluated in long double", "[lie][taylor]") {
  // The branch coefficients are far too small to move a Jacobian beyond rounding near θ = 0, so
  // a wrong Taylor term would slip through the central-difference tests; compare them here with
  // the exact closed forms, in long double where their cancellation is still harmless.
  using LD = long double;
  namespace detail = geodrift::lie::detail;
  const auto rel = [](double a, LD b) {
    return static_cast<double>(std::abs((static_cast<LD>(a) - b) / b));
  };
  // SE3 / SO3 coefficients below kSmallAngle = 1e-2, against their defining series summed
  // generically in long double to convergence (the closed forms cancel too much there even in
  // long double): c1 = Σ(−1)^m θ^{2m}/(2m+2)!, c2 = Σ(−1)^m θ^{2m}/(2m+3)!, c·t = (dc/dθ)/θ.
  for (double th : {1e-3, 4e-3, 9.99e-3}) {
    const LD t = th;
    LD c1 = 0, c2 = 0, c1t = 0, c2t = 0, p = 1;  // p = (−1)^m θ^{2m}
    LD f2 = 2, f3 = 6;                           // (2m+2)!, (2m+3)!
    for (int m = 0; m < 12; ++m) {
      c1 += p / f2;
      c2 += p / f3;
      if (m >= 1) {
        c1t += 2 * m * p / (t * t) / f2;
        c2t += 2 * m * p / (t * t) / f3;
      }
      p *= -t * t;
      f2 *= (2 * m + 3) * (2 * m + 4);
      f3 *= (2 * m + 4) * (2 * m + 5);
    }
    const detail::VCoeffs<double> k = detail::se3_coeffs<double>(th, true);
    INFO("theta " << th);
    CHECK(rel(k.c1, c1) < 1e-15);
    CHECK(rel(k.c2, c2) < 1e-15);
    CHECK(rel(k.c1t, c1t) < 1e-15);
    CHECK(rel(k.c2t, c2t) < 1e-15);
    const Eigen::Vector3d w = th * Eigen::Vector3d(0.6, 0.0, 0.8);
    const Eigen::Matrix3d W = lie::skew<double>(w);
    const LD d2 = (1 - (t / 2) * std::cos(t / 2) / std::sin(t / 2)) / (t * t);
    const Eigen::Matrix3d Jli =
        Eigen::Matrix3d::Identity() - 0.5 * W + static_cast<double>(d2) * W * W;
    CHECK(test::near(SO3d::left_jacobian_inverse(w), Jli, 1e-15));
    const LD half = std::sin(t / 2) / t;
    const Eigen::Quaterniond q = lie::detail::quaternion_exp<double>(w);
    CHECK(rel(q.w(), std::cos(t / 2)) < 1e-15);
    CHECK(rel(q.x(), half * static_cast<LD>(w.x())) < 1e-15);
  }
  // Sim3 coefficients: series branch (θ < 0.5) against the complex closed forms.
  for (double th : {0.05, 0.2, 0.49}) {
    for (double sg : {-6.0, -1.0, 0.0, 0.7, 3.9, 4.1}) {
      using C = std::complex<LD>;
      const LD t = th, sigma = sg;
      const C z(sigma, t), ez = std::exp(z);
      const C phi = (ez - LD(1)) / z, dphi = (ez * (z - LD(1)) + LD(1)) / (z * z);
      const LD g0 = sg == 0.0 ? LD(1) : std::expm1(sigma) / sigma;
      const LD g1 = sg == 0.0 ? LD(0.5) : (std::exp(sigma) * (sigma - 1) + 1) / (sigma * sigma);
      const LD c1 = phi.imag() / t, c2 = (g0 - phi.real()) / (t * t);
      const LD c1s = dphi.imag() / t, c2s = (g1 - dphi.real()) / (t * t);
      const LD c1t = (dphi.real() - c1) / (t * t), c2t = (c1s - 2 * c2) / (t * t);
      const detail::VCoeffs<double> k = detail::sim3_coeffs<double>(th, sg, true);
      INFO("theta " << th << " sigma " << sg);
      CHECK(rel(k.c0, g0) < 1e-14);
      CHECK(rel(k.c0s, g1) < 1e-13);
      CHECK(rel(k.c1, c1) < 1e-13);
      CHECK(rel(k.c2, c2) < 1e-12);
      CHECK(rel(k.c1s, c1s) < 1e-12);
      CHECK(rel(k.c2s, c2s) < 1e-12);
      CHECK(rel(k.c1t, c1t) < 1e-10);
      CHECK(rel(k.c2t, c2t) < 1e-9);
    }
  }
}

TEST_CASE("Sim3 reduced theta series agree with the full series and the closed forms",
          "[lie][taylor][sim3]") {
  // sim3_coeffs uses M < kSim3ThetaSeriesTerms terms below kSim3ThetaSeriesBound[M]; there the
  // reduced series must equal the full one to rounding, for every coefficient and derivative.
  namespace detail = geodrift::lie::detail;
  const auto rel = [](double a, double b) {
    return std::abs(a - b) / std::max(std::abs(b), 1e-300);
  };
  const auto all = [](const detail::VCoeffs<double>& k) {
    return std::array<double, 8>{k.c0, k.c1, k.c2, k.c0s, k.c1s, k.c2s, k.c1t, k.c2t};
  };
  for (int M = 4; M < lie::kSim3ThetaSeriesTerms; ++M) {
    const double bound = detail::kSim3ThetaSeriesBound[M];
    for (double th : {0.0, 1e-9, 0.5 * bound, 0.999 * bound}) {
      if (detail::sim3_theta_series_terms(th) > M) continue;
      for (double sg : {-6.0, -1.0, -1e-3, 0.0, 0.02, 0.7, 3.9, 4.1}) {
        INFO("M " << M << " theta " << th << " sigma " << sg);
        const auto red = all(detail::sim3_coeffs_series<double>(th, sg, M, true));
        const auto full =
            all(detail::sim3_coeffs_series<double>(th, sg, lie::kSim3ThetaSeriesTerms, true));
        for (int i = 0; i < 8; ++i) {
          INFO("coefficient " << i);
          CHECK(rel(red[i], full[i]) < 4e-16);
        }
      }
    }
  }
  // Dispatch: the chosen M grows with θ and uses the full series from 0.275 to 0.5.
  CHECK(detail::sim3_theta_series_terms(1e-3) == 4);
  CHECK(detail::sim3_theta_series_terms(0.03) == 5);
  CHECK(detail::sim3_theta_series_terms(0.1) == 6);
  CHECK(detail::sim3_theta_series_terms(0.2) == 7);
  CHECK(detail::sim3_theta_series_terms(0.3) == lie::kSim3ThetaSeriesTerms);
  // With 3 terms the series would be visibly wrong at θ = 6e-3 (the test can fail): its c1t
  // misses the θ⁴ term, 2.5e-13 relative.
  const auto three = all(detail::sim3_coeffs_series<double>(6e-3, 0.1, 3, true));
  const auto ref = all(detail::sim3_coeffs_series<double>(6e-3, 0.1, 8, true));
  CHECK(rel(three[6], ref[6]) > 1e-14);
}

TEST_CASE(
    "W-polynomials from W^2 = w w^T - theta^2 I and the written-out 3x3 products equal "
    "the matrix forms",
    "[lie]") {
  // Sim3::log and its Jl^-1 build k0 I + k1 W + k2 W^2 without W*W (w_polynomial) and multiply
  // 3x3 matrices with mul3 (and add k*[v]x with add_skew); all against Eigen's products, seeded,
  // |ω| from 1e-8 to ≈ 5.
  namespace detail = geodrift::lie::detail;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const auto rnd3 = [&] { return Eigen::Vector3d(u(rng), u(rng), u(rng)); };
  for (int trial = 0; trial < 200; ++trial) {
    const double scale = std::pow(10.0, -8.0 + 8.5 * (trial % 17) / 16.0);  // 1e-8 .. ≈ 3
    const Eigen::Vector3d w = scale * rnd3();
    const double k0 = u(rng), k1 = u(rng), k2 = u(rng);
    const Eigen::Matrix3d W = detail::skew<double>(w);
    const Eigen::Matrix3d ref = k0 * Eigen::Matrix3d::Identity() + k1 * W + k2 * (W * W);
    const Eigen::Matrix3d P = detail::w_polynomial(k0, k1, k2, w, w.squaredNorm());
    const Eigen::Vector3d v = rnd3();
    const Eigen::Vector3d Pv = detail::w_polynomial_times(k0, k1, k2, w, w.squaredNorm(), v);
    Eigen::Matrix3d A, B;
    for (int k = 0; k < 9; ++k) {
      A(k % 3, k / 3) = u(rng);
      B(k % 3, k / 3) = u(rng);
    }
    INFO("trial " << trial << " |w| " << w.norm());
    CHECK((P - ref).cwiseAbs().maxCoeff() <= 1e-15 * (1.0 + ref.cwiseAbs().maxCoeff()));
    CHECK((Pv - ref * v).cwiseAbs().maxCoeff() <= 1e-15 * (1.0 + (ref * v).norm()));
    CHECK((detail::mul3(A, B) - A * B).cwiseAbs().maxCoeff() <= 1e-15);
    Eigen::Matrix3d As = A;
    detail::add_skew(&As, k1, v);
    CHECK((As - (A + k1 * detail::skew<double>(v))).cwiseAbs().maxCoeff() <= 1e-15);
  }
}

TEMPLATE_TEST_CASE(
    "times_adjoint, adjoint_times and adjoint_transpose_times equal the products with the "
    "adjoint; log shares its coefficients with left_jacobian_inverse",
    "[lie]", SE3d, Sim3d) {
  using G = TestType;
  std::mt19937 rng(91);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    typename G::Tangent xi, xi_small;
    for (int i = 0; i < G::kDoF; ++i) {
      xi[i] = (k % 2 ? 1.0 : 50.0) * n(rng);
      xi_small[i] = 0.01 * n(rng);
    }
    xi.template head<3>() = xi.template head<3>().normalized() * std::fmod(std::abs(n(rng)), 3.0);
    if constexpr (G::kDoF == 7) xi[3] = 0.5 * n(rng);
    const G X = G::exp(xi);
    typename G::Jacobian M;
    for (int i = 0; i < M.size(); ++i) M.data()[i] = n(rng);
    const typename G::Jacobian ref = M * X.adjoint();
    CHECK((X.times_adjoint(M) - ref).norm() <= 1e-13 * (1.0 + ref.norm()));
    const G Y = G::exp(xi_small) * X;  // a nearby pose: X·Y⁻¹ close to the identity
    const typename G::Matrix XYi = (X * Y.inverse()).matrix(), YXi = (Y * X.inverse()).matrix();
    CHECK((X.times_inverse(Y).matrix() - XYi).norm() <= 1e-13 * (1.0 + X.matrix().norm()));
    CHECK((Y.times_inverse(X).matrix() - YXi).norm() <= 1e-13 * (1.0 + X.matrix().norm()));
#ifdef GEODRIFT_AVX2_KERNELS
    if constexpr (std::is_same_v<G, Sim3d>) {
      // The AVX2 kernel itself (times_adjoint uses it or not, by CPU and GEODRIFT_NO_AVX2).
      if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
        typename G::Jacobian out;
        const Eigen::Matrix3d R = X.rotation().matrix();
        lie::detail::sim3_times_adjoint_avx2(M.data(), R.data(), X.translation().data(), X.scale(),
                                             out.data());
        CHECK((out - ref).norm() <= 1e-13 * (1.0 + ref.norm()));
      }
    }
#endif
    const typename G::Tangent u = M.col(0);
    const typename G::Tangent uref = X.adjoint().transpose() * u;
    CHECK((X.adjoint_transpose_times(u) - uref).norm() <= 1e-13 * (1.0 + uref.norm()));
    const typename G::Tangent dref = X.adjoint() * u;
    CHECK((X.adjoint_times(u) - dref).norm() <= 1e-13 * (1.0 + dref.norm()));
    for (const G& Y : {X, G::exp(xi_small)}) {
      typename G::Jacobian J;
      const typename G::Tangent l = Y.log(&J);
      const typename G::Jacobian Jref = G::left_jacobian_inverse(l);
      CHECK((J - Jref).norm() <= 1e-14 * (1.0 + Jref.norm()));
      CHECK((l - Y.log()).norm() <= 1e-15 * (1.0 + l.norm()));
    }
  }
}
