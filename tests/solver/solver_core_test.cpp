// Solver building blocks: block structure layout, losses and the Triggs correction, Euclidean
// problems, LM behaviour (rejected steps, NaN, options), linear solvers on the same matrix.

#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/block_structure.hpp"
#include "geodrift/solver/cholmod_solver.hpp"
#include "geodrift/solver/dense_solver.hpp"
#include "geodrift/solver/large_array_allocator.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/loss.hpp"
#include "geodrift/solver/manifold.hpp"
#include "geodrift/solver/problem.hpp"
#include "support/numeric_jacobian.hpp"

using namespace geodrift;
using solver::LevenbergMarquardt;
using solver::LinearSolverType;
using solver::Options;
using solver::Problem;
using solver::RobustLoss;
using solver::Termination;

namespace {

/// r = A·x − b for x ∈ R^3 (linear, for exact known answers).
struct LinearResidual3 {
  static constexpr int kNumResiduals = 2;
  Eigen::Matrix<double, 2, 3> A;
  Eigen::Vector2d b;
  template <typename X>
  bool operator()(const X& x, Eigen::Vector2d* r, Eigen::Matrix<double, 2, 3>* J = nullptr) const {
    *r = A * Eigen::Vector3d(x) - b;
    if (J) *J = A;
    return true;
  }
};

/// r = x_j − x_i − d (2 parameters, R^3 each).
struct DifferenceResidual {
  static constexpr int kNumResiduals = 3;
  Eigen::Vector3d d;
  template <typename X, typename Y>
  bool operator()(const X& xi, const Y& xj, Eigen::Vector3d* r, Eigen::Matrix3d* Ji = nullptr,
                  Eigen::Matrix3d* Jj = nullptr) const {
    *r = Eigen::Vector3d(xj) - Eigen::Vector3d(xi) - d;
    if (Ji) *Ji = -Eigen::Matrix3d::Identity();
    if (Jj) *Jj = Eigen::Matrix3d::Identity();
    return true;
  }
};

/// Rosenbrock as a least-squares problem: r = (10·(y − x²), 1 − x). LM from (−1.2, 1) is the
/// textbook case where a full Gauss-Newton step overshoots.
struct Rosenbrock {
  static constexpr int kNumResiduals = 2;
  bool operator()(const Eigen::Vector2d& p, Eigen::Vector2d* r,
                  Eigen::Matrix2d* J = nullptr) const {
    (*r)[0] = 10.0 * (p[1] - p[0] * p[0]);
    (*r)[1] = 1.0 - p[0];
    if (J) *J << -20.0 * p[0], 10.0, -1.0, 0.0;
    return true;
  }
};

/// r = x − c, but NaN when lo < x < hi (to test unevaluable residuals).
struct NanInside {
  static constexpr int kNumResiduals = 1;
  double c = 0.0, lo = 1e300, hi = 1e301;
  bool operator()(const Eigen::Matrix<double, 1, 1>& x, Eigen::Matrix<double, 1, 1>* r,
                  Eigen::Matrix<double, 1, 1>* J = nullptr) const {
    (*r)[0] = (x[0] > lo && x[0] < hi) ? std::numeric_limits<double>::quiet_NaN() : x[0] - c;
    if (J) (*J)(0, 0) = 1.0;
    return true;
  }
};

/// Rosenbrock with a deliberately wrong ∂r0/∂x (for Options::check_jacobians).
struct WrongRosenbrock {
  static constexpr int kNumResiduals = 2;
  bool operator()(const Eigen::Vector2d& p, Eigen::Vector2d* r,
                  Eigen::Matrix2d* J = nullptr) const {
    Rosenbrock{}(p, r, J);
    if (J) (*J)(0, 0) *= 1.01;
    return true;
  }
};

/// Tiny local test manifold: planar rotation angle group (kDoF = 1), left retraction.
struct Rot2 {
  static constexpr int kDoF = 1;
  using Tangent = Eigen::Matrix<double, 1, 1>;
  double theta = 0.0;
  static Rot2 exp(const Tangent& t) { return Rot2{t[0]}; }
  Rot2 operator*(const Rot2& o) const { return Rot2{std::remainder(theta + o.theta, 2 * M_PI)}; }
};

/// r = wrap(θ − θ_target)
struct Rot2Residual {
  static constexpr int kNumResiduals = 1;
  double target = 0.0;
  bool operator()(const Rot2& R, Eigen::Matrix<double, 1, 1>* r,
                  Eigen::Matrix<double, 1, 1>* J = nullptr) const {
    (*r)[0] = std::remainder(R.theta - target, 2 * M_PI);
    if (J) (*J)(0, 0) = 1.0;
    return true;
  }
};

}  // namespace

TEST_CASE("Block structure matches the documented worked example", "[solver]") {
  solver::BlockStructure s;
  s.build({2, 3, 2}, {{1, 0}, {0, 2}, {0, 1}});
  CHECK(s.num_cols() == 7);
  CHECK(s.num_values() == 27);
  const std::vector<int> col_ptr{0, 2, 4, 9, 14, 19, 23, 27};
  CHECK(s.col_ptr() == col_ptr);
  CHECK(s.column_height(0) == 2);
  CHECK(s.column_height(1) == 5);
  CHECK(s.column_height(2) == 4);
  CHECK(s.block_offset(0, 1) == 4);
  CHECK(s.block_offset(1, 1) == 6);
  CHECK(s.block_offset(0, 2) == 19);
  CHECK(s.block_offset(2, 2) == 21);
  CHECK(s.block_offset(1, 2) == -1);
  // Rows of column 5 (first column of block 2): 0 1 5 6.
  const std::vector<int> rows = s.row_idx();
  CHECK(rows.size() == 27u);
  const std::vector<int> rows5(rows.begin() + 19, rows.begin() + 23);
  CHECK(rows5 == std::vector<int>{0, 1, 5, 6});
  // H_01(1, 2) lives at values[15].
  solver::BlockSparseMatrix H(&s);
  H.block(0, 1)(1, 2) = 42.0;
  CHECK(H.values()[15] == 42.0);
  CHECK(H.to_dense()(1, 4) == 42.0);
  CHECK(H.to_dense()(4, 1) == 42.0);
  CHECK(s.diagonal_positions()[6] == 21 + 1 * 4 + 1);
}

TEST_CASE("Robust losses have the documented derivatives", "[solver][jacobian]") {
  const std::vector<RobustLoss> losses{RobustLoss::trivial(), RobustLoss::huber(0.7),
                                       RobustLoss::cauchy(1.3)};
  for (const auto& loss : losses) {
    for (double s : {1e-3, 0.2, 0.45, 0.6, 2.0, 30.0}) {
      double rho[3], rp[3], rm[3];
      const double h = 1e-6 * (1.0 + s);
      loss.evaluate(s, rho);
      loss.evaluate(s + h, rp);
      loss.evaluate(s - h, rm);
      INFO("loss type " << int(loss.type()) << " s " << s);
      CHECK(rho[1] == Approx((rp[0] - rm[0]) / (2 * h)).epsilon(1e-6));
      CHECK(rho[2] == Approx((rp[1] - rm[1]) / (2 * h)).epsilon(1e-5).margin(1e-9));
    }
  }
  double rho[3];
  RobustLoss::huber(1.0).evaluate(4.0, rho);  // |r| = 2 > δ = 1: 2·1·2 − 1
  CHECK(rho[0] == Approx(3.0));
  RobustLoss::cauchy(2.0).evaluate(4.0, rho);  // 4·log(2)
  CHECK(rho[0] == Approx(4.0 * std::log(2.0)));
  CHECK_THROWS_AS(RobustLoss::huber(-1.0), InvalidArgument);
  CHECK_THROWS_AS(RobustLoss::cauchy(std::nan("")), InvalidArgument);
}

TEST_CASE("Triggs correction matches the robustified cost to second order", "[solver]") {
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    Eigen::Vector3d r(n(rng), n(rng), n(rng));
    Eigen::Matrix<double, 3, 4> J;
    for (int i = 0; i < 12; ++i) J.data()[i] = n(rng);
    const double s = r.squaredNorm();
    // A loss with ρ'' > 0 exercises α ≠ 0; Huber/Cauchy (ρ'' ≤ 0) take the α = 0 branch.
    for (const double rho2 : {0.05, -0.2}) {
      const double rho[3] = {s, 0.8, rho2};
      solver::TriggsCorrector corr(s, rho);
      Eigen::Vector3d rt = r;
      Eigen::Matrix<double, 3, 4> Jt = J;
      corr.correct_jacobian(rt, Jt);
      corr.correct_residual(rt);
      INFO("trial " << trial << " rho2 " << rho2);
      // gradient of ½ρ(|r + Jδ|²) at 0 is ρ'·Jᵀr
      CHECK(test::near(Jt.transpose() * rt, rho[1] * J.transpose() * r, 1e-12));
      if (rho2 > 0) {
        // Hessian (without r's second derivatives): ρ'JᵀJ + 2ρ''Jᵀr rᵀJ
        const Eigen::Matrix4d Hexp =
            rho[1] * J.transpose() * J + 2 * rho2 * J.transpose() * r * r.transpose() * J;
        CHECK(test::near(Jt.transpose() * Jt, Hexp, 1e-12));
      } else {
        CHECK(test::near(Jt.transpose() * Jt, rho[1] * J.transpose() * J, 1e-12));
      }
    }
  }
}

TEST_CASE("Loss-weighted residual blocks give the exact cost gradient", "[solver][jacobian]") {
  // Gradient of the total cost (numeric) = J̃ᵀr̃ (assembled), for every loss and weight form.
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  int checked = 0;
  for (int trial = 0; trial < 210; ++trial) {
    Eigen::Vector3d x(n(rng), n(rng), n(rng));
    Eigen::Vector3d y(n(rng), n(rng), n(rng));
    LinearResidual3 f;
    for (int i = 0; i < 6; ++i) f.A.data()[i] = n(rng);
    f.b = Eigen::Vector2d(n(rng), n(rng)) * 3.0;
    const DifferenceResidual d{Eigen::Vector3d(n(rng), n(rng), n(rng))};
    const RobustLoss loss = trial % 3 == 0   ? RobustLoss::trivial()
                            : trial % 3 == 1 ? RobustLoss::huber(0.5)
                                             : RobustLoss::cauchy(0.8);
    Eigen::Matrix2d info;
    info << 2.0, 0.3, 0.3, 0.5;
    Problem p;
    p.add_residual_block(f, loss, info, &x);
    p.add_residual_block(d, loss, 3.0, &x, solver::euclidean<3>(y.data()));
    p.finalize();
    Eigen::SparseMatrix<double> J;
    Eigen::VectorXd r;
    REQUIRE(p.evaluate_jacobian(&J, &r));
    const Eigen::VectorXd g = J.transpose() * r;
    // numeric gradient of the cost
    Eigen::VectorXd gnum(6);
    const double h = 1e-6;
    for (int c = 0; c < 6; ++c) {
      double* v = c < 3 ? &x[c] : &y[c - 3];
      const double v0 = *v;
      double cp, cm;
      *v = v0 + h;
      REQUIRE(p.evaluate_cost(&cp));
      *v = v0 - h;
      REQUIRE(p.evaluate_cost(&cm));
      *v = v0;
      gnum[c] = (cp - cm) / (2 * h);
    }
    INFO("trial " << trial);
    CHECK(test::near(g, gnum, 1e-6));
    ++checked;
  }
  CHECK(checked == 210);
}

TEST_CASE("Linear least squares: LM reaches the normal-equation solution", "[solver]") {
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  // Chain x0 - x1 - ... - x9 with differences, and absolute measurements on each.
  std::vector<Eigen::Vector3d> x(10, Eigen::Vector3d::Zero());
  for (const auto type : {LinearSolverType::kCholmod, LinearSolverType::kDense}) {
    std::mt19937 rng2(7);
    Problem p;
    std::vector<LinearResidual3> abs_res;
    for (int i = 0; i < 10; ++i) {
      LinearResidual3 f;
      for (int k = 0; k < 6; ++k) f.A.data()[k] = n(rng2);
      f.b = Eigen::Vector2d(n(rng2), n(rng2));
      p.add_residual_block(f, RobustLoss(), 1.0, &x[i]);
      if (i > 0)
        p.add_residual_block(DifferenceResidual{Eigen::Vector3d(n(rng2), n(rng2), n(rng2))},
                             RobustLoss(), 2.0, &x[i - 1], &x[i]);
    }
    Options o;
    o.linear_solver = type;
    o.function_tolerance = 1e-14;
    o.parameter_tolerance = 1e-12;
    o.gradient_tolerance = 1e-12;
    LevenbergMarquardt lm(o);
    const solver::Summary s = lm.solve(&p);
    INFO(s.brief_report());
    CHECK(s.converged());
    // Exact solution from the dense normal equations.
    Eigen::SparseMatrix<double> J;
    Eigen::VectorXd r;
    for (auto& xi : x) xi.setZero();
    REQUIRE(p.evaluate_jacobian(&J, &r));
    const Eigen::MatrixXd Jd(J);
    const Eigen::VectorXd sol = (Jd.transpose() * Jd).ldlt().solve(-Jd.transpose() * r);
    for (auto& xi : x) xi.setZero();
    const solver::Summary s2 = lm.solve(&p);  // reuses the symbolic analysis
    CHECK(s2.time_analyze == 0.0);
    for (int i = 0; i < 10; ++i) CHECK(test::near(x[i], sol.segment<3>(3 * i), 1e-9));
  }
}

TEST_CASE("A step that would raise the cost is rejected", "[solver]") {
  // Rosenbrock from (-1.2, 1): with a tiny initial λ the first Gauss-Newton step overshoots
  // (cost 12.1 -> 10.5k); LM must reject it, raise λ, and still converge to (1, 1).
  Eigen::Vector2d xy(-1.2, 1.0);
  Problem p;
  p.add_residual_block(Rosenbrock{}, RobustLoss(), 1.0, &xy);
  {
    // confirm the undamped first step overshoots
    Eigen::Vector2d r;
    Eigen::Matrix2d J;
    Rosenbrock{}(xy, &r, &J);
    const Eigen::Vector2d gn = -J.colPivHouseholderQr().solve(r);
    Eigen::Vector2d x1 = xy + gn, r1;
    Rosenbrock{}(x1, &r1);
    REQUIRE(r1.squaredNorm() > r.squaredNorm());
  }
  Options o;
  o.initial_lambda = 1e-12;
  o.max_iterations = 200;
  o.function_tolerance = 0.0;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 0.0;
  std::vector<double> costs;
  LevenbergMarquardt lm(o);
  const solver::Summary s = lm.solve(&p);
  INFO(s.brief_report());
  CHECK(s.unsuccessful_steps >= 1);
  CHECK(s.final_cost < s.initial_cost);
  CHECK(s.converged());
  CHECK(xy[0] == Approx(1.0).epsilon(1e-8));
  CHECK(xy[1] == Approx(1.0).epsilon(1e-8));

  // Max one iteration with a huge overshoot: the state must be unchanged, cost not raised.
  Eigen::Vector2d xy2(-1.2, 1.0);
  Problem p2;
  p2.add_residual_block(Rosenbrock{}, RobustLoss(), 1.0, &xy2);
  o.max_iterations = 1;
  LevenbergMarquardt lm2(o);
  const solver::Summary s2 = lm2.solve(&p2);
  CHECK(s2.unsuccessful_steps == 1);
  CHECK(s2.final_cost == s2.initial_cost);
  CHECK(xy2 == Eigen::Vector2d(-1.2, 1.0));
  CHECK(s2.termination == Termination::kMaxIterations);
}

TEST_CASE("A NaN residual stops the solve with a clear reason", "[solver]") {
  Eigen::Matrix<double, 1, 1> a, b;
  a << 5.0;
  b << 1.0;
  Problem p;
  p.add_residual_block(NanInside{0.0}, RobustLoss(), 1.0, &b);
  p.add_residual_block(NanInside{0.0, 4.0, 1e300}, RobustLoss(), 1.0, &a);  // NaN at a = 5
  LevenbergMarquardt lm;
  const solver::Summary s = lm.solve(&p);
  CHECK(s.termination == Termination::kNonFiniteResidual);
  CHECK_THAT(s.message, Catch::Contains("residual block 1"));
  CHECK_THAT(s.message, Catch::Contains("initial point"));
  CHECK(std::isnan(s.final_cost));
  CHECK(a[0] == 5.0);

  // A trial point inside the NaN window is a rejected step, not the end: target 3, start 0,
  // λ0 = 1 makes the first step land at 1.5 (damping D = 1 here), inside (1.4, 1.6).
  Eigen::Matrix<double, 1, 1> c;
  c << 0.0;
  Problem p2;
  p2.add_residual_block(NanInside{3.0, 1.4, 1.6}, RobustLoss(), 1.0, &c);
  Options o;
  o.initial_lambda = 1.0;
  LevenbergMarquardt lm2(o);
  const solver::Summary s2 = lm2.solve(&p2);
  INFO(s2.brief_report());
  CHECK(s2.unsuccessful_steps >= 1);
  CHECK(s2.converged());
  CHECK(c[0] == Approx(3.0).epsilon(1e-6));
}

TEST_CASE("Invalid options are rejected by validate with a message", "[solver]") {
  std::string why;
  CHECK(Options{}.validate(&why));
  CHECK(why.empty());
  Options o;
  o.max_iterations = -1;
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("max_iterations"));
  o = Options{};
  o.function_tolerance = -1e-3;
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("function_tolerance"));
  o = Options{};
  o.initial_lambda = 0.0;
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("initial_lambda"));
  o = Options{};
  o.num_threads = 3;
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("num_threads"));
  o = Options{};
  o.gradient_tolerance = std::nan("");
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("gradient_tolerance"));
  o = Options{};
  o.min_lambda = 1.0;  // above initial_lambda
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("min_lambda"));
  for (const double f : {0.0, 1.0, std::numeric_limits<double>::quiet_NaN()}) {
    o = Options{};
    o.lambda_decrease_limit = f;
    CHECK_FALSE(o.validate(&why));
    CHECK_THAT(why, Catch::Contains("lambda_decrease_limit"));
  }
  o = Options{};
  o.min_diagonal = 10.0;
  o.max_diagonal = 1.0;
  CHECK_FALSE(o.validate(&why));
  // solve() refuses too, touching nothing.
  Eigen::Vector2d xy(-1.2, 1.0);
  Problem p;
  p.add_residual_block(Rosenbrock{}, RobustLoss(), 1.0, &xy);
  LevenbergMarquardt lm(o);
  const solver::Summary s = lm.solve(&p);
  CHECK(s.termination == Termination::kInvalidOptions);
  CHECK_THAT(s.message, Catch::Contains("diagonal"));
  CHECK(xy == Eigen::Vector2d(-1.2, 1.0));
}

TEST_CASE("Problem rejects bad input", "[solver]") {
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  Problem p;
  const DifferenceResidual d{Eigen::Vector3d::Ones()};
  CHECK_THROWS_AS(p.add_residual_block(d, RobustLoss(), 1.0, &x, &x), InvalidArgument);
  CHECK_THROWS_AS(p.add_residual_block(d, RobustLoss(), -1.0, &x, solver::euclidean<3>(x.data())),
                  InvalidArgument);
  Eigen::Vector3d y = Eigen::Vector3d::Zero();
  Eigen::Matrix3d bad = Eigen::Matrix3d::Identity();
  bad(2, 2) = -1.0;
  CHECK_THROWS_AS(p.add_residual_block(d, RobustLoss(), bad, &x, &y), InvalidArgument);
  CHECK_THROWS_AS(p.set_constant(&bad), InvalidArgument);
}

TEST_CASE("Constant blocks get no columns; a local test manifold is retracted on the left",
          "[solver]") {
  Rot2 a{3.0}, b{-3.0};
  Problem p;
  p.add_residual_block(Rot2Residual{0.5}, RobustLoss(), 1.0, &a);
  p.add_residual_block(Rot2Residual{-2.9}, RobustLoss(), 1.0, &b);  // constant: cost stays
  p.set_constant(&b);
  p.finalize();
  CHECK(p.num_effective_parameters() == 1);
  CHECK(p.parameter_block(&b).col == -1);
  CHECK(p.parameter_block(&a).col == 0);
  Options o;
  o.parameter_tolerance = 1e-14;
  o.function_tolerance = 1e-14;
  LevenbergMarquardt lm(o);
  const solver::Summary s = lm.solve(&p);
  CHECK(s.converged());
  // b's constant residual (0.1) leaves cost 0.005, so a is resolved to ~sqrt(eps·0.005)
  CHECK(a.theta == Approx(0.5).epsilon(1e-9));
  CHECK(b.theta == -3.0);
  CHECK(s.final_cost == Approx(0.005).epsilon(1e-12));
}

TEST_CASE("CHOLMOD and dense solvers agree; not positive definite is a status", "[solver]") {
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  solver::BlockStructure s;
  s.build({3, 2, 4, 3}, {{0, 1}, {1, 2}, {0, 3}, {2, 3}});
  solver::BlockSparseMatrix H(&s);
  // Random SPD values on the pattern: H = Σ JᵀJ over pairs + diagonal.
  const std::vector<std::pair<int, int>> pairs{{0, 1}, {1, 2}, {0, 3}, {2, 3}};
  for (const auto& [a, b] : pairs) {
    Eigen::MatrixXd Ja(5, s.block_size(a)), Jb(5, s.block_size(b));
    for (int i = 0; i < Ja.size(); ++i) Ja.data()[i] = n(rng);
    for (int i = 0; i < Jb.size(); ++i) Jb.data()[i] = n(rng);
    H.block(a, a) += Ja.transpose() * Ja;
    H.block(b, b) += Jb.transpose() * Jb;
    H.block(a, b) += Ja.transpose() * Jb;
  }
  for (int c = 0; c < s.num_cols(); ++c) H.values()[s.diagonal_positions()[c]] += 0.1;
  Eigen::VectorXd b(s.num_cols()), x1(s.num_cols()), x2(s.num_cols());
  for (int i = 0; i < b.size(); ++i) b[i] = n(rng);
  // Both orderings: block AMD (CholmodSolver gathers P·H·Pᵀ itself) and CHOLMOD's scalar AMD.
  // Both factor kinds: supernodal and simplicial (Factorization::kAuto picks one of them).
  using Factorization = solver::CholmodSolver::Factorization;
  for (const auto ordering :
       {solver::CholmodSolver::Ordering::kBlockAmd, solver::CholmodSolver::Ordering::kAmd})
    for (const auto kind : {Factorization::kSupernodal, Factorization::kSimplicial}) {
      INFO("ordering " << static_cast<int>(ordering) << ", factorization "
                       << static_cast<int>(kind));
      solver::BlockSparseMatrix Hk = H;
      solver::CholmodSolver chol(ordering, kind);
      solver::DenseSolver dense;
      REQUIRE(chol.analyze(s) == solver::LinearSolverStatus::kSuccess);
      REQUIRE(dense.analyze(s) == solver::LinearSolverStatus::kSuccess);
      REQUIRE(chol.factorize(Hk) == solver::LinearSolverStatus::kSuccess);
      REQUIRE(dense.factorize(Hk) == solver::LinearSolverStatus::kSuccess);
      CHECK(chol.is_supernodal() == (kind == Factorization::kSupernodal));
      REQUIRE(chol.solve(b.data(), x1.data()) == solver::LinearSolverStatus::kSuccess);
      REQUIRE(dense.solve(b.data(), x2.data()) == solver::LinearSolverStatus::kSuccess);
      CHECK(test::near(x1, x2, 1e-10));
      CHECK(test::near(Hk.to_dense() * x1, b, 1e-10));
      // Break positive definiteness: both report it, no exception; the message names H's column.
      Hk.values()[s.diagonal_positions()[4]] = -100.0;
      CHECK(chol.factorize(Hk) == solver::LinearSolverStatus::kNotPositiveDefinite);
      CHECK_THAT(chol.message(), Catch::Contains("not positive definite (column 4)"));
      CHECK(dense.factorize(Hk) == solver::LinearSolverStatus::kNotPositiveDefinite);
      // And recover on the next values.
      Hk.values()[s.diagonal_positions()[4]] = 1e3;
      CHECK(chol.factorize(Hk) == solver::LinearSolverStatus::kSuccess);
    }
}

TEST_CASE("Options::check_jacobians catches a wrong analytic Jacobian", "[solver][jacobian]") {
  Eigen::Vector2d good(-1.2, 1.0), bad(0.5, 0.3);
  Problem p;
  p.add_residual_block(Rosenbrock{}, RobustLoss(), 1.0, &good);
  Options o;
  o.check_jacobians = true;
  LevenbergMarquardt lm(o);
  CHECK(lm.solve(&p).converged());
  p.add_residual_block(WrongRosenbrock{}, RobustLoss::huber(1.0), 1.0, &bad);
  const Eigen::Vector2d before = bad;
  const solver::Summary s = lm.solve(&p);
  CHECK(s.termination == Termination::kJacobianCheckFailed);
  CHECK_THAT(s.message, Catch::Contains("residual block 1"));
  CHECK(bad == before);  // states restored after the numeric differences
}

namespace {
/// VmFlags of the /proc/self/smaps mapping that contains p ("" if not found or not Linux).
std::string vm_flags_of(const void* p) {
  std::ifstream in("/proc/self/smaps");
  const auto a = reinterpret_cast<std::uintptr_t>(p);
  std::string line;
  bool inside = false;
  while (std::getline(in, line)) {
    unsigned long lo = 0, hi = 0;
    if (std::sscanf(line.c_str(), "%lx-%lx ", &lo, &hi) == 2 && line.find(':') > 8)
      inside = a >= lo && a < hi;
    else if (inside && line.rfind("VmFlags:", 0) == 0)
      return line;
  }
  return "";
}
}  // namespace

TEST_CASE("LargeArrayAllocator: own mappings for large arrays, coloured, values kept", "[solver]") {
  using Mat7 = Eigen::Matrix<double, 7, 7>;
  const bool huge_before = solver::large_array_huge_pages_enabled();
  solver::set_large_array_huge_pages(true);
  solver::release_large_array_cache();
  CHECK(solver::large_array_cache_bytes() == 0);
  const std::size_t n_big = solver::kLargeArrayThreshold / sizeof(double) + 3;
  std::vector<double, solver::LargeArrayAllocator<double>> a(n_big, 1.5), b(n_big, 2.5);
  const auto pa = reinterpret_cast<std::uintptr_t>(a.data());
  const auto pb = reinterpret_cast<std::uintptr_t>(b.data());
  CHECK(pa % 64 == 0);
  CHECK(pb % 64 == 0);
  // Consecutive large arrays start at different offsets within their first huge page.
  CHECK(pa % solver::kHugePageBytes != pb % solver::kHugePageBytes);
  CHECK(pa % solver::kHugePageBytes < 16 * 33 * 64);
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  // MADV_HUGEPAGE applied (where the kernel has transparent huge pages at all).
  if (std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled").good()) {
    CHECK_THAT(vm_flags_of(a.data()), Catch::Contains(" hg"));
    CHECK_THAT(vm_flags_of(a.data() + n_big - 1), Catch::Contains(" hg"));
  }
#endif
  a.back() = 4.0;
  const double* old_a = a.data();
  a.resize(a.size() * 2, -1.0);  // reallocation copies the values, keeps the old mapping
  CHECK(a.front() == 1.5);
  CHECK(a[n_big - 1] == 4.0);
  CHECK(a.back() == -1.0);
  CHECK(b[n_big / 2] == 2.5);
  std::vector<Mat7, solver::LargeArrayAllocator<Mat7>> small(3, Mat7::Constant(2.0));
  CHECK(reinterpret_cast<std::uintptr_t>(small.data()) % 64 == 0);
  CHECK(small[2](6, 6) == 2.0);
  CHECK_THAT(vm_flags_of(small.data()), !Catch::Contains(" hg"));  // ordinary heap
  {  // without the huge-page choice a new mapping is not marked
    solver::set_large_array_huge_pages(false);
    std::vector<double, solver::LargeArrayAllocator<double>> d(4 * n_big, 3.0);
    CHECK(reinterpret_cast<std::uintptr_t>(d.data()) % 64 == 0);
    CHECK(d.back() == 3.0);
    CHECK_THAT(vm_flags_of(d.data()), !Catch::Contains(" hg"));
    solver::set_large_array_huge_pages(true);
  }

  // A freed mapping is kept and handed to the next array that fits; released on request.
  const double* old_b = b.data();
  decltype(b)().swap(b);
  CHECK(solver::large_array_cache_bytes() >= n_big * sizeof(double));
  std::vector<double, solver::LargeArrayAllocator<double>> c(n_big + 100, 7.0);
  CHECK((c.data() == old_a || c.data() == old_b));  // both kept mappings fit
  CHECK(c[n_big + 99] == 7.0);
  decltype(c)().swap(c);
  decltype(a)().swap(a);
  solver::release_large_array_cache();
  CHECK(solver::large_array_cache_bytes() == 0);
  solver::set_large_array_huge_pages(huge_before);
}
