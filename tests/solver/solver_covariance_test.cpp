// Covariance: marginal covariance blocks against the dense inverse of J̃ᵀJ̃ (SE3 / Sim3 pose
// graphs with priors, robust losses, fill-in, mixed block sizes), closed forms of linear-Gaussian
// chains (Brownian bridge, random walk between two soft anchors), rank deficiency as a status,
// invalid requests.

#include <Eigen/Cholesky>
#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/covariance.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"

using namespace geodrift;
using solver::Covariance;
using solver::CovarianceStatus;
using solver::Problem;
using solver::RobustLoss;

namespace {

/// |A − B|_F / |B|_F (|A|_F when B = 0).
double rel_error(const Eigen::MatrixXd& A, const Eigen::MatrixXd& B) {
  const double d = (A - B).norm(), n = B.norm();
  return n > 0.0 ? d / n : d;
}

Eigen::MatrixXd random_spd(std::mt19937& rng, int n, double scale) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd M(n, n);
  for (int i = 0; i < M.size(); ++i) M.data()[i] = g(rng);
  return scale * (M * M.transpose() / n + Eigen::MatrixXd::Identity(n, n));
}

/// r = c(S) − p: the camera centre of S_cw at a free point p (couples a pose and an R³ block:
/// mixed block sizes).
template <class G>
struct CentreAtPoint {
  static constexpr int kNumResiduals = 3;
  bool operator()(const G& S, const Eigen::Vector3d& p, Eigen::Vector3d* r,
                  Eigen::Matrix<double, 3, G::kDoF>* J_S = nullptr,
                  Eigen::Matrix3d* J_p = nullptr) const {
    const solver::CameraCentrePriorResidual<G> c{p};
    if (!c(S, r, J_S)) return false;
    if (J_p) *J_p = -Eigen::Matrix3d::Identity();
    return true;
  }
};

/// r = x_j − x_i (R^N random-walk step).
template <int N>
struct Step {
  static constexpr int kNumResiduals = N;
  using V = Eigen::Matrix<double, N, 1>;
  using M = Eigen::Matrix<double, N, N>;
  bool operator()(const V& a, const V& b, V* r, M* Ja = nullptr, M* Jb = nullptr) const {
    *r = b - a;
    if (Ja) *Ja = -M::Identity();
    if (Jb) *Jb = M::Identity();
    return true;
  }
};

/// r = x − y (R^N prior).
template <int N>
struct Prior {
  static constexpr int kNumResiduals = N;
  using V = Eigen::Matrix<double, N, 1>;
  using M = Eigen::Matrix<double, N, N>;
  V y;
  bool operator()(const V& x, V* r, M* J = nullptr) const {
    *r = x - y;
    if (J) J->setIdentity();
    return true;
  }
};

/// r = a (the second parameter has a zero Jacobian column).
struct OnlyFirst {
  static constexpr int kNumResiduals = 1;
  using V1 = Eigen::Matrix<double, 1, 1>;
  bool operator()(const V1& a, const V1&, V1* r, V1* Ja = nullptr, V1* Jb = nullptr) const {
    *r = a;
    if (Ja) Ja->setOnes();
    if (Jb) Jb->setZero();
    return true;
  }
};

/// A residual that cannot be evaluated.
struct Broken {
  static constexpr int kNumResiduals = 1;
  bool operator()(const Eigen::Matrix<double, 1, 1>&, Eigen::Matrix<double, 1, 1>*,
                  Eigen::Matrix<double, 1, 1>* = nullptr) const {
    return false;
  }
};

/// Poses along a curve (world→body), noisy relative edges to the next 1–3 nodes, loop
/// closures (0, n−1) and (5, 20) (fill-in in the natural order), camera-centre priors on a few
/// nodes (they fix the gauge), robust loss on part of the edges; optionally an R³ point tied to
/// three camera centres.
template <class G>
struct Graph {
  static constexpr int D = G::kDoF;
  std::vector<G> poses;
  Eigen::Vector3d point = Eigen::Vector3d(1.0, 2.0, 0.5);
  Problem problem;

  Graph(int n, bool with_point, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0.0, 1.0);
    std::vector<G> truth;
    for (int k = 0; k < n; ++k) {
      const double a = 2.0 * M_PI * k / n;
      const lie::SO3d R = lie::SO3d::exp(Eigen::Vector3d(0.1 * std::sin(3 * a), 0.05, a));
      const Eigen::Vector3d c(20.0 * std::cos(a), 20.0 * std::sin(a), 0.5 * std::sin(2 * a));
      const lie::SE3d T_bw = lie::SE3d(R, c).inverse();
      if constexpr (D == 6) {
        truth.push_back(T_bw);
      } else {
        const double s = std::exp(0.3 * std::sin(a));
        truth.push_back(G(T_bw.rotation(), s * T_bw.translation(), s));
      }
    }
    const auto noise = [&](double sd) {
      typename G::Tangent xi;
      for (int i = 0; i < D; ++i) xi[i] = sd * g(rng);
      return xi;
    };
    poses = truth;
    for (auto& S : poses) S = G::exp(noise(0.02)) * S;
    int e = 0;
    const auto add = [&](int i, int j) {
      const G dS = G::exp(noise(0.01)) * truth[j] * truth[i].inverse();
      const Eigen::Matrix<double, D, D> info = random_spd(rng, D, 1e3);
      // Every third edge robust, with a threshold its weighted residual often exceeds.
      const RobustLoss loss = (e++ % 3 == 0) ? RobustLoss::huber(0.3) : RobustLoss();
      problem.add_residual_block(solver::RelativePoseResidual<G>{dS}, loss, info, &poses[i],
                                 &poses[j]);
    };
    for (int k = 0; k + 1 < n; ++k)
      for (int d = 1; d <= 3 && k + d < n; ++d)
        if (d == 1 || (k + d) % 2 == 0) add(k, k + d);
    add(0, n - 1);
    add(5, 20);
    for (int k : {0, 7, 15, 22}) {
      const Eigen::Vector3d c = truth[k].inverse().act(Eigen::Vector3d::Zero());
      problem.add_residual_block(solver::CameraCentrePriorResidual<G>{c + 0.1 * g3(rng)},
                                 RobustLoss(), 4.0, &poses[k]);
    }
    if (with_point) {
      for (int k : {3, 4, 5})
        problem.add_residual_block(CentreAtPoint<G>{}, RobustLoss(), 0.5, &poses[k], &point);
    }
  }

  static Eigen::Vector3d g3(std::mt19937& rng) {
    std::normal_distribution<double> g(0.0, 1.0);
    return Eigen::Vector3d(g(rng), g(rng), g(rng));
  }

  /// Dense (J̃ᵀJ̃)⁻¹ from the problem's own weighted, loss-corrected Jacobian.
  Eigen::MatrixXd dense_inverse() {
    Eigen::SparseMatrix<double> J;
    Eigen::VectorXd r;
    REQUIRE(problem.evaluate_jacobian(&J, &r));
    const Eigen::MatrixXd Jd(J);
    const Eigen::MatrixXd H = Jd.transpose() * Jd;
    const Eigen::LLT<Eigen::MatrixXd> llt(H);
    REQUIRE(llt.info() == Eigen::Success);
    return llt.solve(Eigen::MatrixXd::Identity(H.rows(), H.cols()));
  }

  Eigen::MatrixXd ref_block(const Eigen::MatrixXd& S, const void* a, const void* b) const {
    const auto& pa = problem.parameter_block(a);
    const auto& pb = problem.parameter_block(b);
    return S.block(pa.col, pb.col, pa.dof, pb.dof);
  }
};

}  // namespace

TEMPLATE_TEST_CASE("Covariance blocks match the dense inverse of the Gauss-Newton matrix",
                   "[solver][covariance]", lie::SE3d, lie::Sim3d) {
  for (const bool with_point : {false, true}) {
    INFO("with an R^3 point (mixed block sizes): " << with_point);
    Graph<TestType> graph(30, with_point, 11);
    solver::Options o;
    o.max_iterations = 50;
    const solver::Summary sum = solver::LevenbergMarquardt(o).solve(&graph.problem);
    INFO(sum.brief_report());
    REQUIRE(sum.final_cost < sum.initial_cost);

    std::vector<const void*> blocks;
    for (const auto& S : graph.poses) blocks.push_back(&S);
    if (with_point) blocks.push_back(&graph.point);
    // On the pattern: (0,1) edge, (0,29) loop closure, (4,4); reversed order (2,1); off the
    // pattern (solves): (3,17), (17,3), (8,26), (point, 28).
    std::vector<Covariance::Pair> pairs = {
        {&graph.poses[0], &graph.poses[1]},  {&graph.poses[0], &graph.poses[29]},
        {&graph.poses[4], &graph.poses[4]},  {&graph.poses[2], &graph.poses[1]},
        {&graph.poses[3], &graph.poses[17]}, {&graph.poses[17], &graph.poses[3]},
        {&graph.poses[8], &graph.poses[26]}};
    if (with_point) pairs.push_back({&graph.point, &graph.poses[28]});

    Covariance cov;
    std::string why;
    REQUIRE(cov.compute(graph.problem, blocks, pairs, &why));
    CHECK(why.empty());
    CHECK(cov.status() == CovarianceStatus::kSuccess);
    CHECK(cov.min_pivot_ratio() > 1e-8);
    CHECK(cov.min_scaled_eigenvalue() > 1e-8);

    const Eigen::MatrixXd S = graph.dense_inverse();
    double worst = 0.0;
    for (const void* b : blocks) {
      const Eigen::MatrixXd got = cov.block(b), ref = graph.ref_block(S, b, b);
      REQUIRE(got.rows() == ref.rows());
      REQUIRE(got.cols() == ref.cols());
      CHECK(got.allFinite());
      worst = std::max(worst, rel_error(got, ref));
      CHECK(rel_error(got, got.transpose()) == 0.0);  // symmetrised
    }
    for (const auto& [a, b] : pairs) {
      const Eigen::MatrixXd ref = graph.ref_block(S, a, b);
      worst = std::max(worst, rel_error(cov.block(a, b), ref));
      worst = std::max(worst, rel_error(cov.block(b, a), ref.transpose()));
    }
    INFO("worst relative block error " << worst);
    CHECK(worst < 1e-9);
  }
}

TEST_CASE("Covariance with a constant pose conditions on it and matches the dense inverse",
          "[solver][covariance]") {
  Graph<lie::Sim3d> graph(30, false, 5);
  graph.problem.set_constant(&graph.poses[12]);
  std::vector<const void*> blocks;
  for (std::size_t k = 0; k < graph.poses.size(); ++k)
    if (k != 12) blocks.push_back(&graph.poses[k]);
  Covariance cov;
  REQUIRE(cov.compute(graph.problem, blocks));
  const Eigen::MatrixXd S = graph.dense_inverse();
  for (const void* b : blocks) CHECK(rel_error(cov.block(b), graph.ref_block(S, b, b)) < 1e-9);
  // Only what was asked for is kept.
  CHECK_FALSE(cov.has_block(&graph.poses[12]));
  CHECK_THROWS_AS(cov.block(&graph.poses[12]), InvalidArgument);
  CHECK_THROWS_AS(cov.block(&graph.poses[0], &graph.poses[1]), InvalidArgument);
  // Requesting a constant block, or a state that is not a parameter, is an error.
  CHECK_THROWS_AS(cov.compute(graph.problem, {&graph.poses[12]}), InvalidArgument);
  const lie::Sim3d stranger;
  CHECK_THROWS_AS(cov.compute(graph.problem, {&stranger}), InvalidArgument);
  CHECK_THROWS_AS(cov.compute(graph.problem, {}, {{&graph.poses[1], &graph.poses[12]}}),
                  InvalidArgument);
}

TEST_CASE("Covariance of a Brownian bridge in R^3 matches t(T-t)/T times the step covariance",
          "[solver][covariance]") {
  // x_0 and x_T fixed, steps x_{t+1} − x_t with covariance C: cov(x_s, x_t) = C·s(T−t)/T, s ≤ t.
  std::mt19937 rng(7);
  const int T = 60;
  const Eigen::Matrix3d C = random_spd(rng, 3, 0.04);
  std::vector<Eigen::Vector3d> x(T + 1, Eigen::Vector3d::Zero());
  std::normal_distribution<double> g(0.0, 1.0);
  for (int t = 1; t <= T; ++t) x[t] = x[t - 1] + Eigen::Vector3d(g(rng), g(rng), g(rng));
  Problem p;
  for (int t = 0; t < T; ++t)
    p.add_residual_block(Step<3>{}, RobustLoss(), Eigen::Matrix3d(C.inverse()), &x[t], &x[t + 1]);
  p.set_constant(&x[0]);
  p.set_constant(&x[T]);

  std::vector<const void*> blocks;
  for (int t = 1; t < T; ++t) blocks.push_back(&x[t]);
  std::vector<Covariance::Pair> pairs;
  for (int s = 1; s < T; s += 7)
    for (int t = s; t < T; t += 5) pairs.emplace_back(&x[s], &x[t]);
  Covariance cov;
  std::string why;
  REQUIRE(cov.compute(p, blocks, pairs, &why));
  double worst = 0.0;
  for (int t = 1; t < T; ++t) {
    const Eigen::Matrix3d expected = C * (double(t) * (T - t) / T);
    worst = std::max(worst, rel_error(cov.block(&x[t]), expected));
  }
  for (const auto& [a, b] : pairs) {
    const int s = static_cast<int>(static_cast<const Eigen::Vector3d*>(a) - x.data());
    const int t = static_cast<int>(static_cast<const Eigen::Vector3d*>(b) - x.data());
    const Eigen::Matrix3d expected = C * (double(s) * (T - t) / T);
    worst = std::max(worst, rel_error(cov.block(a, b), expected));
    worst = std::max(worst, rel_error(cov.block(b, a), expected.transpose()));
  }
  INFO("worst relative error " << worst);
  CHECK(worst < 1e-9);
}

TEST_CASE("Covariance of a long 1-D random walk between two soft anchors matches the closed form",
          "[solver][covariance]") {
  // Priors x_0 ~ N(a, σa²), x_T ~ N(b, σb²), steps with variance σ² and neighbours up to 1: the
  // two halves of the chain are independent given x_t, so var(x_t) = 1/(1/(σa²+tσ²) +
  // 1/(σb²+(T−t)σ²)).
  const int T = 2000;
  const double sa2 = 0.5, sb2 = 2.0, s2 = 0.01;
  using V1 = Eigen::Matrix<double, 1, 1>;
  std::vector<V1> x(T + 1, V1::Zero());
  Problem p;
  p.add_residual_block(Prior<1>{V1::Constant(1.0)}, RobustLoss(), 1.0 / sa2, &x[0]);
  p.add_residual_block(Prior<1>{V1::Constant(3.0)}, RobustLoss(), 1.0 / sb2, &x[T]);
  for (int t = 0; t < T; ++t)
    p.add_residual_block(Step<1>{}, RobustLoss(), 1.0 / s2, &x[t], &x[t + 1]);
  std::vector<const void*> blocks;
  for (auto& v : x) blocks.push_back(&v);
  Covariance cov;
  REQUIRE(cov.compute(p, blocks));
  double worst = 0.0;
  for (int t = 0; t <= T; ++t) {
    const double expected = 1.0 / (1.0 / (sa2 + t * s2) + 1.0 / (sb2 + (T - t) * s2));
    worst = std::max(worst, std::abs(cov.block(&x[t])(0, 0) - expected) / expected);
  }
  INFO("worst relative error " << worst);
  CHECK(worst < 1e-9);
}

TEST_CASE("Covariance reports rank deficiency as a status, never NaN", "[solver][covariance]") {
  SECTION("Sim3 chain with relative edges only (7-dof gauge)") {
    Graph<lie::Sim3d> ref(30, false, 3);
    std::vector<lie::Sim3d> poses = ref.poses;
    Problem p;
    for (int k = 0; k + 1 < 30; ++k)
      p.add_residual_block(
          solver::RelativePoseResidual<lie::Sim3d>{poses[k + 1] * poses[k].inverse()}, RobustLoss(),
          1e5, &poses[k], &poses[k + 1]);
    std::vector<const void*> blocks;
    for (const auto& S : poses) blocks.push_back(&S);
    Covariance cov;
    std::string why;
    CHECK_FALSE(cov.compute(p, blocks, &why));
    CHECK(cov.status() == CovarianceStatus::kRankDeficient);
    CHECK(why.find("rank deficient") != std::string::npos);
    CHECK(cov.message() == why);
    // The factorisation finds it: the state whose pivot failed is one of the chain's.
    CHECK(std::find(blocks.begin(), blocks.end(), cov.rank_deficient_state()) != blocks.end());
    CHECK_FALSE(cov.has_block(&poses[0]));
    CHECK_THROWS_AS(cov.block(&poses[3]), InvalidArgument);
    // Fixing the gauge makes it well posed.
    p.set_constant(&poses[0]);
    blocks.erase(blocks.begin());
    REQUIRE(cov.compute(p, blocks, &why));
    CHECK(cov.block(&poses[29]).allFinite());
    CHECK(cov.rank_deficient_state() == nullptr);
  }
  SECTION("Sim3 chains anchored by two camera centres: rotation about their line is free") {
    // One null direction: rounding leaves its Cholesky pivot positive about half the time, and
    // then as large as 1e-7 (long chains, 3 km from the origin); the Rayleigh-quotient test
    // catches those. Both paths must occur among these cases.
    int by_pivot = 0, by_rayleigh = 0;
    for (const int n : {30, 300})
      for (unsigned seed = 0; seed < 8; ++seed) {
        std::mt19937 rng(seed);
        std::normal_distribution<double> g(0.0, 1.0);
        std::vector<lie::Sim3d> S;
        for (int k = 0; k < n; ++k) {
          const double a = 0.002 * k;
          const lie::SE3d T =
              lie::SE3d(lie::SO3d::exp(Eigen::Vector3d(0, 0, a)),
                        Eigen::Vector3d(3000 + 1000 * std::sin(a), 1000 * (1 - std::cos(a)), 0))
                  .inverse();
          S.emplace_back(T.rotation(), T.translation(), 1.0);
        }
        Problem p;
        for (int k = 0; k + 1 < n; ++k) {
          Eigen::Matrix<double, 7, 1> xi;
          for (int i = 0; i < 7; ++i) xi[i] = 1e-3 * g(rng);
          p.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{lie::Sim3d::exp(xi) *
                                                                        S[k + 1] * S[k].inverse()},
                               RobustLoss(), 1e5, &S[k], &S[k + 1]);
        }
        for (const int k : {0, n - 1})
          p.add_residual_block(solver::CameraCentrePriorResidual<lie::Sim3d>{S[k].inverse().act(
                                   Eigen::Vector3d::Zero())},
                               RobustLoss(), 1.0, &S[k]);
        Covariance cov;
        std::string why;
        INFO("n " << n << " seed " << seed);
        CHECK_FALSE(cov.compute(p, {&S[n / 2]}, &why));
        CHECK(cov.status() == CovarianceStatus::kRankDeficient);
        INFO(why);
        if (why.find("pivot") != std::string::npos) ++by_pivot;
        if (why.find("inverse iteration") != std::string::npos) {
          ++by_rayleigh;
          CHECK(cov.min_pivot_ratio() > 0.0);
          CHECK(std::abs(cov.min_scaled_eigenvalue()) < 1e-14);
        }
        // A third, non-collinear centre fixes it.
        p.add_residual_block(
            solver::CameraCentrePriorResidual<lie::Sim3d>{
                S[n / 3].inverse().act(Eigen::Vector3d::Zero()) + Eigen::Vector3d(0, 0, 50)},
            RobustLoss(), 1.0, &S[n / 3]);
        CHECK(cov.compute(p, {&S[n / 2]}, &why));
        CHECK(cov.block(&S[n / 2]).allFinite());
      }
    CHECK(by_pivot + by_rayleigh == 16);
    CHECK(by_pivot > 0);
    CHECK(by_rayleigh > 0);
  }
  SECTION("1-D chain of 5000 without an anchor") {
    using V1 = Eigen::Matrix<double, 1, 1>;
    std::vector<V1> x(5000, V1::Zero());
    Problem p;
    for (std::size_t t = 0; t + 1 < x.size(); ++t)
      p.add_residual_block(Step<1>{}, RobustLoss(), 1.0, &x[t], &x[t + 1]);
    Covariance cov;
    std::string why;
    CHECK_FALSE(cov.compute(p, {&x[100]}, &why));
    CHECK(cov.status() == CovarianceStatus::kRankDeficient);
  }
  SECTION("a parameter no residual constrains (zero Jacobian column)") {
    using V1 = Eigen::Matrix<double, 1, 1>;
    V1 a = V1::Zero(), b = V1::Zero();
    Problem p;
    p.add_residual_block(OnlyFirst{}, RobustLoss(), 1.0, &a, &b);
    Covariance cov;
    CHECK_FALSE(cov.compute(p, {&a}));
    CHECK(cov.status() == CovarianceStatus::kRankDeficient);
  }
}

TEST_CASE("Covariance reports an unevaluable residual as a status", "[solver][covariance]") {
  Eigen::Matrix<double, 1, 1> x = Eigen::Matrix<double, 1, 1>::Zero();
  Problem p;
  p.add_residual_block(Broken{}, RobustLoss(), 1.0, &x);
  Covariance cov;
  std::string why;
  CHECK_FALSE(cov.compute(p, {&x}, &why));
  CHECK(cov.status() == CovarianceStatus::kEvaluationFailed);
  CHECK(!why.empty());
}

TEST_CASE("CovarianceOptions are validated", "[solver][covariance]") {
  solver::CovarianceOptions o;
  CHECK(o.validate());
  o.rank_tolerance = 0.0;
  std::string why;
  CHECK_FALSE(o.validate(&why));
  CHECK(why.find("rank_tolerance") != std::string::npos);
  CHECK_THROWS_AS(Covariance(o), InvalidArgument);
}
