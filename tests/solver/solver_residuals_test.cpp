// Every solver residual's analytic Jacobian against central differences under the solver's
// LEFT perturbation (STYLE.md §9), ≥ 200 seeded samples each, plain and loss-weighted.

#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"
#include "support/numeric_jacobian.hpp"
#include "support/samples.hpp"

using namespace geodrift;

namespace {

constexpr int kSamples = 200;

/// A tangent with rotation angle ≤ 3 rad (away from the log's π singularity), σ ∈ [−2, 2],
/// translation up to ~1e3 m; every 10th sample is tiny (|ξ| ≈ 1e-9, Taylor branches).
template <class Group>
typename Group::Tangent moderate_tangent(std::mt19937& rng, int trial) {
  std::uniform_real_distribution<double> ang(0.0, 3.0), sig(-2.0, 2.0), len(-2.0, 3.0);
  std::normal_distribution<double> n(0.0, 1.0);
  typename Group::Tangent xi;
  const double scale = trial % 10 == 0 ? 1e-9 : 1.0;
  const Eigen::Vector3d omega = ang(rng) * test::random_unit(rng) * scale;
  const Eigen::Vector3d nu = std::pow(10.0, len(rng)) * test::random_unit(rng) * scale;
  if constexpr (Group::kDoF == 6) {
    xi << omega, nu;
  } else {
    xi << omega, sig(rng) * scale, nu;
  }
  return xi;
}

/// |f| for the rounding floor of a central difference.
double fscale(const Eigen::VectorXd& v) { return v.lpNorm<Eigen::Infinity>(); }

}  // namespace

TEMPLATE_TEST_CASE("Relative pose residual Jacobians match central differences",
                   "[solver][jacobian]", lie::SE3d, lie::Sim3d) {
  using G = TestType;
  using Res = solver::RelativePoseResidual<G>;
  std::mt19937 rng(42);
  for (int trial = 0; trial < kSamples; ++trial) {
    const G S_i = test::random_element<G>(rng);
    const G dS = test::random_element<G>(rng);
    // S_j chosen so that E = dS·S_i·S_j⁻¹ = exp(ξ) with a controlled ξ.
    const G S_j = G::exp(-moderate_tangent<G>(rng, trial)) * dS * S_i;
    const Res res{dS};
    typename Res::Vec r;
    typename Res::Mat J_i, J_j;
    REQUIRE(res(S_i, S_j, &r, &J_i, &J_j));
    const auto r_of_i = [&](const G& S) {
      typename Res::Vec v;
      res(S, S_j, &v);
      return Eigen::VectorXd(v);
    };
    const auto r_of_j = [&](const G& S) {
      typename Res::Vec v;
      res(S_i, S, &v);
      return Eigen::VectorXd(v);
    };
    const Eigen::MatrixXd Ni = test::numeric_jacobian(r_of_i, S_i);
    const Eigen::MatrixXd Nj = test::numeric_jacobian(r_of_j, S_j);
    INFO("trial " << trial << " r = " << r.transpose());
    CHECK(test::near(J_i, Ni, 1e-6, test::rounding_floor(fscale(r) + 1e4, 1e-6)));
    CHECK(test::near(J_j, Nj, 1e-6, test::rounding_floor(fscale(r) + 1e4, 1e-6)));
  }
}

TEMPLATE_TEST_CASE("Relative pose residual: linked() Jacobian link matches central differences",
                   "[solver][jacobian]", lie::SE3d, lie::Sim3d) {
  // linked() returns operator()'s r and J_r_Si and the link G: J_r_Sj = −J_r_Si·Ad(G) must be
  // the central-difference Jacobian in S_j (what ResidualBlock's linked accumulation assumes).
  using G = TestType;
  using Res = solver::RelativePoseResidual<G>;
  std::mt19937 rng(142);
  for (int trial = 0; trial < kSamples; ++trial) {
    const G S_i = test::random_element<G>(rng);
    const G dS = test::random_element<G>(rng);
    const G S_j = G::exp(-moderate_tangent<G>(rng, trial)) * dS * S_i;
    const Res res{dS};
    typename Res::Vec r, r_link;
    typename Res::Mat J_i, J_j, J_i_link;
    G link;
    REQUIRE(res(S_i, S_j, &r, &J_i, &J_j));
    REQUIRE(res.linked(S_i, S_j, &r_link, &J_i_link, &link));
    CHECK(r_link == r);
    CHECK(J_i_link == J_i);
    const typename Res::Mat J_j_link = -link.times_adjoint(J_i_link);
    const auto r_of_j = [&](const G& S) {
      typename Res::Vec v;
      res(S_i, S, &v);
      return Eigen::VectorXd(v);
    };
    const Eigen::MatrixXd Nj = test::numeric_jacobian(r_of_j, S_j);
    INFO("trial " << trial << " r = " << r.transpose());
    CHECK(test::near(J_j_link, Nj, 1e-6, test::rounding_floor(fscale(r) + 1e4, 1e-6)));
    // and the same matrix as operator()'s J_r_Sj up to rounding
    CHECK((J_j_link - J_j).norm() <= 1e-9 * (1.0 + J_j.norm()));
  }
}

TEMPLATE_TEST_CASE("Pose prior and camera-centre prior Jacobians match central differences",
                   "[solver][jacobian]", lie::SE3d, lie::Sim3d) {
  using G = TestType;
  std::mt19937 rng(43);
  for (int trial = 0; trial < kSamples; ++trial) {
    const G S_prior = test::random_element<G>(rng);
    const G S = G::exp(moderate_tangent<G>(rng, trial)) * S_prior;
    const solver::PosePriorResidual<G> prior{S_prior};
    typename solver::PosePriorResidual<G>::Vec r;
    typename solver::PosePriorResidual<G>::Mat J;
    REQUIRE(prior(S, &r, &J));
    const auto f = [&](const G& X) {
      typename solver::PosePriorResidual<G>::Vec v;
      prior(X, &v);
      return Eigen::VectorXd(v);
    };
    INFO("trial " << trial);
    CHECK(test::near(J, test::numeric_jacobian(f, S), 1e-6,
                     test::rounding_floor(fscale(r) + 1e4, 1e-6)));

    const solver::CameraCentrePriorResidual<G> cp{test::random_translation(rng)};
    Eigen::Vector3d rc = Eigen::Vector3d::Zero();
    typename solver::CameraCentrePriorResidual<G>::Mat Jc;
    REQUIRE(cp(S, &rc, &Jc));
    const auto fc = [&](const G& X) {
      Eigen::Vector3d v;
      cp(X, &v);
      return Eigen::VectorXd(v);
    };
    // camera centre magnitude up to |t|/s with s down to e^-3: scale the floor with it
    const double cmag = S.inverse().translation().norm();
    CHECK(test::near(Jc, test::numeric_jacobian(fc, S), 1e-6,
                     test::rounding_floor(cmag + fscale(rc), 1e-6)));
  }
}

TEST_CASE("Local-scale Sim3 edge and its Gauss-Markov links match central differences",
          "[solver][jacobian]") {
  using G = lie::Sim3d;
  using Res = solver::RelativeSim3LocalScaleResidual;
  std::mt19937 rng(45);
  std::normal_distribution<double> n(0.0, 0.3);
  std::uniform_real_distribution<double> rho(0.0, 0.999);
  for (int trial = 0; trial < kSamples; ++trial) {
    const G S_i = test::random_element<G>(rng);
    const G dS = test::random_element<G>(rng);
    const G S_j = G::exp(-moderate_tangent<G>(rng, trial)) * dS * S_i;
    const Eigen::Matrix<double, 1, 1> u_i(n(rng)), u_j(n(rng));
    const Res res{dS};
    Res::Vec r;
    Res::Mat J_i, J_j;
    Res::MatU J_ui, J_uj;
    REQUIRE(res(S_i, S_j, u_i, u_j, &r, &J_i, &J_j, &J_ui, &J_uj));
    // The pose part is RelativePoseResidual's; the offsets only move the log-scale.
    solver::RelativePoseResidual<G>::Vec r0;
    solver::RelativePoseResidual<G>{dS}(S_i, S_j, &r0);
    CHECK(std::abs(r[3] - (r0[3] - (u_i[0] - u_j[0]))) <= 1e-12 * (1.0 + std::abs(r0[3])));
    const auto r_of_i = [&](const G& S) {
      Res::Vec v;
      res(S, S_j, u_i, u_j, &v);
      return Eigen::VectorXd(v);
    };
    const auto r_of_j = [&](const G& S) {
      Res::Vec v;
      res(S_i, S, u_i, u_j, &v);
      return Eigen::VectorXd(v);
    };
    const auto r_of_ui = [&](const Eigen::Matrix<double, 1, 1>& u) {
      Res::Vec v;
      res(S_i, S_j, u, u_j, &v);
      return Eigen::VectorXd(v);
    };
    const auto r_of_uj = [&](const Eigen::Matrix<double, 1, 1>& u) {
      Res::Vec v;
      res(S_i, S_j, u_i, u, &v);
      return Eigen::VectorXd(v);
    };
    INFO("trial " << trial << " r = " << r.transpose());
    const double floor = test::rounding_floor(fscale(r) + 1e4, 1e-6);
    CHECK(test::near(J_i, test::numeric_jacobian(r_of_i, S_i), 1e-6, floor));
    CHECK(test::near(J_j, test::numeric_jacobian(r_of_j, S_j), 1e-6, floor));
    CHECK(test::near(J_ui, test::numeric_jacobian_vector(r_of_ui, u_i), 1e-6, floor));
    CHECK(test::near(J_uj, test::numeric_jacobian_vector(r_of_uj, u_j), 1e-6, floor));

    const solver::LocalScaleLinkResidual link{rho(rng)};
    solver::LocalScaleLinkResidual::Vec l;
    solver::LocalScaleLinkResidual::Mat J_prev, J_u;
    REQUIRE(link(u_i, u_j, &l, &J_prev, &J_u));
    CHECK(std::abs(l[0] - (u_j[0] - link.rho * u_i[0])) <= 1e-15);
    const auto l_of_prev = [&](const Eigen::Matrix<double, 1, 1>& u) {
      solver::LocalScaleLinkResidual::Vec v;
      link(u, u_j, &v);
      return Eigen::VectorXd(v);
    };
    const auto l_of_u = [&](const Eigen::Matrix<double, 1, 1>& u) {
      solver::LocalScaleLinkResidual::Vec v;
      link(u_i, u, &v);
      return Eigen::VectorXd(v);
    };
    CHECK(test::near(J_prev, test::numeric_jacobian_vector(l_of_prev, u_i), 1e-8, 1e-9));
    CHECK(test::near(J_u, test::numeric_jacobian_vector(l_of_u, u_j), 1e-8, 1e-9));
    solver::LocalScalePriorResidual::Vec p;
    solver::LocalScalePriorResidual::Mat J_p;
    REQUIRE(solver::LocalScalePriorResidual{}(u_i, &p, &J_p));
    CHECK(p[0] == u_i[0]);
    const auto p_of_u = [&](const Eigen::Matrix<double, 1, 1>& u) {
      solver::LocalScalePriorResidual::Vec v;
      solver::LocalScalePriorResidual{}(u, &v);
      return Eigen::VectorXd(v);
    };
    CHECK(test::near(J_p, test::numeric_jacobian_vector(p_of_u, u_i), 1e-8, 1e-9));
  }
}

TEST_CASE("Reprojection residual Jacobians match central differences", "[solver][jacobian]") {
  std::mt19937 rng(44);
  std::uniform_real_distribution<double> u(-1.0, 1.0), depth(0.5, 80.0), px(0.0, 1000.0);
  for (int trial = 0; trial < kSamples; ++trial) {
    const lie::SE3d T_cw = test::random_se3(rng);
    const double z = depth(rng);
    const Eigen::Vector3d p_c(u(rng) * z, u(rng) * z * 0.7, z);
    const Eigen::Vector3d X = T_cw.inverse().act(p_c);
    solver::ReprojectionResidual res;
    res.fx = 700.0 + 10 * u(rng);
    res.fy = 710.0 + 10 * u(rng);
    res.cx = 600.0;
    res.cy = 180.0;
    res.uv = Eigen::Vector2d(px(rng), px(rng) * 0.4);
    Eigen::Vector2d r = Eigen::Vector2d::Zero();
    solver::ReprojectionResidual::MatT J_T;
    solver::ReprojectionResidual::MatX J_X;
    REQUIRE(res(T_cw, X, &r, &J_T, &J_X));
    const auto f_T = [&](const lie::SE3d& T) {
      Eigen::Vector2d v;
      res(T, X, &v);
      return Eigen::VectorXd(v);
    };
    const auto f_X = [&](const Eigen::Vector3d& Y) {
      Eigen::Vector2d v;
      res(T_cw, Y, &v);
      return Eigen::VectorXd(v);
    };
    INFO("trial " << trial);
    // pixel values ~1e3 and world coordinates ~1e4 m: rounding floor from both
    const double floor = test::rounding_floor(1e3 + 1e3 * X.norm() / z, 1e-6);
    CHECK(test::near(J_T, test::numeric_jacobian(f_T, T_cw), 1e-6, floor));
    CHECK(test::near(J_X, test::numeric_jacobian_vector(f_X, X), 1e-6, floor));
  }
  // Behind the camera: unevaluable.
  solver::ReprojectionResidual res;
  Eigen::Vector2d r;
  CHECK_FALSE(res(lie::SE3d(), Eigen::Vector3d(0.0, 0.0, -1.0), &r));
  CHECK_FALSE(res(lie::SE3d(), Eigen::Vector3d(0.0, 0.0, 0.0), &r));
}

TEMPLATE_TEST_CASE("Loss-weighted relative pose blocks give the exact cost gradient",
                   "[solver][jacobian]", lie::SE3d, lie::Sim3d) {
  // Through the Problem: information matrix weight + Huber/Cauchy. The assembled J̃ᵀr̃ must be
  // the gradient of ½ρ(|W·r|²) under left perturbations (numeric), and with the trivial loss
  // J̃ = W·J exactly.
  using G = TestType;
  constexpr int D = G::kDoF;
  std::mt19937 rng(45);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < kSamples; ++trial) {
    // Poses within ~10 m of the origin: the robust cost's third derivative grows with |t|³,
    // which the central difference (not the analytic gradient) cannot follow at 1e4 m.
    G S_i = G::exp(0.01 * moderate_tangent<G>(rng, trial + 1));
    const G dS = G::exp(0.01 * moderate_tangent<G>(rng, trial + 1));
    typename G::Tangent xi = moderate_tangent<G>(rng, trial);
    xi *= 1e-2;  // residuals near the robust threshold
    G S_j = G::exp(-xi) * dS * S_i;
    Eigen::Matrix<double, D, D> A;
    for (int k = 0; k < D * D; ++k) A.data()[k] = n(rng);
    const Eigen::Matrix<double, D, D> info =
        A * A.transpose() + Eigen::Matrix<double, D, D>::Identity();
    const solver::RobustLoss loss = trial % 3 == 0   ? solver::RobustLoss()
                                    : trial % 3 == 1 ? solver::RobustLoss::huber(0.05)
                                                     : solver::RobustLoss::cauchy(0.05);
    solver::Problem p;
    p.add_residual_block(solver::RelativePoseResidual<G>{dS}, loss, info, &S_i, &S_j);
    p.finalize();
    Eigen::SparseMatrix<double> J;
    Eigen::VectorXd r;
    REQUIRE(p.evaluate_jacobian(&J, &r));
    const Eigen::VectorXd g = J.transpose() * r;
    Eigen::VectorXd gnum(2 * D);
    const double h = 1e-6;
    for (int c = 0; c < 2 * D; ++c) {
      G& X = c < D ? S_i : S_j;
      const G X0 = X;
      typename G::Tangent d = G::Tangent::Zero();
      d[c % D] = h;
      double cp, cm;
      X = G::exp(d) * X0;
      REQUIRE(p.evaluate_cost(&cp));
      X = G::exp(-d) * X0;
      REQUIRE(p.evaluate_cost(&cm));
      X = X0;
      gnum[c] = (cp - cm) / (2 * h);
    }
    INFO("trial " << trial << " loss " << int(loss.type()));
    CHECK(test::near(g, gnum, 1e-6, test::rounding_floor(1e2 * info.norm(), h)));
    if (loss.is_trivial()) {
      solver::RelativePoseResidual<G> res{dS};
      typename solver::RelativePoseResidual<G>::Vec r0;
      typename solver::RelativePoseResidual<G>::Mat Ji, Jj;
      res(S_i, S_j, &r0, &Ji, &Jj);
      const Eigen::Matrix<double, D, D> W = info.llt().matrixU();
      const Eigen::MatrixXd Jd(J);
      CHECK(test::near(Jd.leftCols(D), W * Ji, 1e-12));
      CHECK(test::near(Jd.rightCols(D), W * Jj, 1e-12));
      CHECK((r.transpose() * r)(0) == Approx(r0.transpose() * info * r0).epsilon(1e-10));
    }
  }
}
