// Whole problems: pose graphs (SE3, Sim3) and bundle adjustment, their assembled Jacobians and
// normal equations checked numerically, and every linear-solver path reaching the same optimum.

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/dense_solver.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"
#include "geodrift/solver/schur.hpp"
#include "support/numeric_jacobian.hpp"
#include "support/samples.hpp"

using namespace geodrift;
using solver::LevenbergMarquardt;
using solver::LinearSolverType;
using solver::Options;
using solver::Problem;
using solver::RobustLoss;
using solver::Termination;

namespace {

template <class G>
typename G::Tangent noise_tangent(std::mt19937& rng, double rot, double trans, double sigma) {
  std::normal_distribution<double> n(0.0, 1.0);
  typename G::Tangent xi;
  const Eigen::Vector3d w(n(rng) * rot, n(rng) * rot, n(rng) * rot);
  const Eigen::Vector3d v(n(rng) * trans, n(rng) * trans, n(rng) * trans);
  if constexpr (G::kDoF == 6) {
    xi << w, v;
  } else {
    xi << w, n(rng) * sigma, v;
  }
  return xi;
}

/// A loop-shaped pose graph with world→body poses: chain edges (i, i+1), (i, i+2) and a few
/// loop closures. Measurements dS_ij = S_j·S_i⁻¹ (exact) or with noise.
template <class G>
struct PoseGraph {
  std::vector<G> truth, poses;
  struct Edge {
    int i, j;
    G dS;
  };
  std::vector<Edge> edges;
  Eigen::Matrix<double, G::kDoF, G::kDoF> info;

  PoseGraph(int n, double noise, unsigned seed) {
    std::mt19937 rng(seed);
    for (int k = 0; k < n; ++k) {
      const double a = 2.0 * M_PI * k / n;
      const lie::SO3d R = lie::SO3d::exp(Eigen::Vector3d(0.1 * std::sin(3 * a), 0.05, a));
      const Eigen::Vector3d c(20.0 * std::cos(a), 20.0 * std::sin(a), 0.5 * std::sin(2 * a));
      // world→body: t = −R·c (scaled for Sim3)
      const lie::SE3d T_bw = lie::SE3d(R, c).inverse();
      if constexpr (G::kDoF == 6) {
        truth.push_back(T_bw);
      } else {
        const double s = std::exp(0.3 * std::sin(a));
        truth.push_back(G(T_bw.rotation(), s * T_bw.translation(), s));
      }
    }
    const auto add = [&](int i, int j) {
      const G dS =
          G::exp(noise_tangent<G>(rng, noise, noise, noise)) * truth[j] * truth[i].inverse();
      edges.push_back({i, j, dS});
    };
    for (int k = 0; k + 1 < n; ++k) add(k, k + 1);
    for (int k = 0; k + 2 < n; ++k) add(k, k + 2);
    for (int k = 0; k + n / 2 < n; k += 5) add(k, k + n / 2);
    add(n - 1, 0);
    info.setIdentity();
    info.template topLeftCorner<3, 3>() *= 100.0;  // rotation more certain
    poses = truth;
    for (int k = 1; k < n; ++k)
      poses[k] = G::exp(noise_tangent<G>(rng, 0.05, 0.5, 0.05)) * truth[k];
  }

  void build(Problem* p, const RobustLoss& loss = RobustLoss()) {
    for (const auto& e : edges)
      p->add_residual_block(solver::RelativePoseResidual<G>{e.dS}, loss, info, &poses[e.i],
                            &poses[e.j]);
    p->set_constant(&poses[0]);
  }
};

/// Small synthetic BA: cameras on a line looking at +z, points in a box in front of them.
struct BaScene {
  std::vector<lie::SE3d> cams, cams_truth;
  std::vector<Eigen::Vector3d> points, points_truth;
  struct Obs {
    int cam, point;
    Eigen::Vector2d uv;
  };
  std::vector<Obs> obs;
  double fx = 500, fy = 510, cx = 320, cy = 240;

  BaScene(int num_cams, int num_points, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n(0.0, 1.0);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < num_cams; ++i) {
      const lie::SO3d R =
          lie::SO3d::exp(Eigen::Vector3d(0.05 * n(rng), 0.05 * n(rng), 0.02 * n(rng)));
      const Eigen::Vector3d c(1.5 * i - 0.75 * num_cams, 0.3 * n(rng), -12.0);
      cams_truth.push_back(lie::SE3d(R, -(R.matrix() * c)));
    }
    for (int k = 0; k < num_points; ++k)
      points_truth.emplace_back(4.0 * u(rng), 3.0 * u(rng), 2.0 * u(rng));
    for (int k = 0; k < num_points; ++k) {
      for (int i = 0; i < num_cams; ++i) {
        if ((k + i) % 4 == 3) continue;  // not every camera sees every point
        const Eigen::Vector3d p = cams_truth[i].act(points_truth[k]);
        const Eigen::Vector2d uv(fx * p.x() / p.z() + cx + 0.5 * n(rng),
                                 fy * p.y() / p.z() + cy + 0.5 * n(rng));
        obs.push_back({i, k, uv});
      }
    }
    cams = cams_truth;
    for (int i = 2; i < num_cams; ++i)
      cams[i] = lie::SE3d::exp(noise_tangent<lie::SE3d>(rng, 0.01, 0.1, 0.0)) * cams_truth[i];
    points = points_truth;
    for (auto& p : points) p += 0.1 * Eigen::Vector3d(n(rng), n(rng), n(rng));
  }

  void build(Problem* p, const RobustLoss& loss) {
    for (const auto& o : obs) {
      solver::ReprojectionResidual r;
      r.fx = fx;
      r.fy = fy;
      r.cx = cx;
      r.cy = cy;
      r.uv = o.uv;
      p->add_residual_block(r, loss, 1.0, &cams[o.cam], &points[o.point]);
    }
    p->set_constant(&cams[0]);  // gauge: 6 dof + scale
    p->set_constant(&cams[1]);
  }
};

Options tight(LinearSolverType t) {
  Options o;
  o.linear_solver = t;
  o.max_iterations = 200;
  o.function_tolerance = 1e-16;
  o.gradient_tolerance = 1e-13;
  o.parameter_tolerance = 1e-14;
  return o;
}

/// Numeric full Jacobian of the weighted residual vector: column by column, each free block
/// perturbed on the left through its manifold retraction (the solver's plus()).
Eigen::MatrixXd numeric_problem_jacobian(Problem* p) {
  Eigen::SparseMatrix<double> J;
  Eigen::VectorXd r0, rp, rm;
  REQUIRE(p->evaluate_jacobian(&J, &r0));
  const int n = p->num_effective_parameters();
  Eigen::MatrixXd N(r0.size(), n);
  const double h = 1e-6;
  Eigen::VectorXd d = Eigen::VectorXd::Zero(n);
  for (int c = 0; c < n; ++c) {
    p->save_state();
    d.setZero();
    d[c] = h;
    p->plus(d.data());
    REQUIRE(p->evaluate_jacobian(&J, &rp));
    p->restore_state();
    d[c] = -h;
    p->plus(d.data());
    REQUIRE(p->evaluate_jacobian(&J, &rm));
    p->restore_state();
    N.col(c) = (rp - rm) / (2 * h);
  }
  return N;
}

template <class G>
double max_pose_error(const std::vector<G>& a, const std::vector<G>& b) {
  double e = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) e = std::max(e, (a[k] * b[k].inverse()).log().norm());
  return e;
}

}  // namespace

TEMPLATE_TEST_CASE("Assembled pose-graph Jacobian and normal equations match numeric ones",
                   "[solver][jacobian]", lie::SE3d, lie::Sim3d) {
  PoseGraph<TestType> g(8, 0.05, 3);
  Problem p;
  g.build(&p);
  p.finalize();
  Eigen::SparseMatrix<double> J;
  Eigen::VectorXd r;
  REQUIRE(p.evaluate_jacobian(&J, &r));
  const Eigen::MatrixXd Jd(J), N = numeric_problem_jacobian(&p);
  CHECK(J.rows() == int(g.edges.size()) * TestType::kDoF);
  CHECK(J.cols() == 7 * TestType::kDoF);
  CHECK(test::near(Jd, N, 1e-6, test::rounding_floor(1e3, 1e-6)));
  // H and g from the block-sparse assembly equal JᵀJ and Jᵀr.
  solver::BlockSparseMatrix H(&p.structure());
  Eigen::VectorXd gvec(p.num_effective_parameters());
  double cost = 0.0;
  solver::LinearizeTimes t;
  REQUIRE(p.linearize(&H, gvec.data(), &cost, &t));
  CHECK(test::near(H.to_dense(), Jd.transpose() * Jd, 1e-12));
  CHECK(test::near(gvec, Jd.transpose() * r, 1e-12));
  CHECK(cost == Approx(0.5 * r.squaredNorm()).epsilon(1e-12));
}

/// RelativePoseResidual without its LinkGroup: forces ResidualBlock's generic accumulation.
template <class G>
struct UnlinkedRelativePose {
  static constexpr int kNumResiduals = G::kDoF;
  solver::RelativePoseResidual<G> f;
  bool operator()(const G& S_i, const G& S_j, typename solver::RelativePoseResidual<G>::Vec* r,
                  typename solver::RelativePoseResidual<G>::Mat* J_i = nullptr,
                  typename solver::RelativePoseResidual<G>::Mat* J_j = nullptr) const {
    return f(S_i, S_j, r, J_i, J_j);
  }
};

TEMPLATE_TEST_CASE("Linked relative-pose accumulation gives the generic H and g", "[solver]",
                   lie::SE3d, lie::Sim3d) {
  // H_ij = −H_ii·Ad(G), H_jj = Ad(G)ᵀ·H_ii·Ad(G), g_j = −Ad(G)ᵀ·g_i (residual_block.hpp) against
  // the generic J̃ᵀJ̃ with J̃_j formed: full information matrix, Huber and Cauchy with residuals
  // on both sides of the threshold, edges in both column orders, a constant pose (generic path).
  using G = TestType;
  constexpr int D = G::kDoF;
  static_assert(solver::ResidualBlock<solver::RelativePoseResidual<G>, G, G>::kHasLink);
  static_assert(!solver::ResidualBlock<UnlinkedRelativePose<G>, G, G>::kHasLink);
  PoseGraph<G> g(30, 0.02, 17);
  std::mt19937 rng(18);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 3; k < 30; k += 4) g.edges.push_back({k, k - 3, g.edges[k].dS.inverse()});
  Eigen::Matrix<double, D, D> A;
  for (int k = 0; k < D * D; ++k) A.data()[k] = n(rng);
  const Eigen::Matrix<double, D, D> info =
      10.0 * (A * A.transpose() + Eigen::Matrix<double, D, D>::Identity());
  // Weighted residual norms |Lᵀr| (Λ = L·Lᵀ): the loss scale is their median.
  const Eigen::Matrix<double, D, D> L = info.llt().matrixL();
  std::vector<double> norms;
  for (const auto& e : g.edges) {
    typename G::Tangent r;
    solver::RelativePoseResidual<G>{e.dS}(g.poses[e.i], g.poses[e.j], &r);
    norms.push_back((L.transpose() * r).norm());
  }
  std::vector<double> sorted = norms;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  for (const RobustLoss& loss :
       {RobustLoss(), RobustLoss::huber(median), RobustLoss::cauchy(median)}) {
    std::vector<G> poses_generic = g.poses;
    Problem linked, generic;
    int robust = 0;
    for (std::size_t k = 0; k < g.edges.size(); ++k) {
      const auto& e = g.edges[k];
      linked.add_residual_block(solver::RelativePoseResidual<G>{e.dS}, loss, info, &g.poses[e.i],
                                &g.poses[e.j]);
      generic.add_residual_block(UnlinkedRelativePose<G>{{e.dS}}, loss, info, &poses_generic[e.i],
                                 &poses_generic[e.j]);
      robust += norms[k] > loss.parameter() ? 1 : 0;
    }
    linked.set_constant(&g.poses[0]);
    generic.set_constant(&poses_generic[0]);
    linked.finalize();
    generic.finalize();
    solver::BlockSparseMatrix H1(&linked.structure()), H2(&generic.structure());
    Eigen::VectorXd g1(linked.num_effective_parameters()), g2(generic.num_effective_parameters());
    double c1 = 0.0, c2 = 0.0;
    solver::LinearizeTimes t;
    REQUIRE(linked.linearize(&H1, g1.data(), &c1, &t));
    REQUIRE(generic.linearize(&H2, g2.data(), &c2, &t));
    INFO("loss " << int(loss.type()) << ", " << robust << " of " << g.edges.size()
                 << " edges beyond the loss parameter");
    if (!loss.is_trivial()) {
      CHECK(robust > 5);
      CHECK(robust < int(g.edges.size()) - 5);
    }
    const Eigen::MatrixXd D1 = H1.to_dense(), D2 = H2.to_dense();
    // H is overwritten whatever it held (each block's first writer assigns, no zeroing pass),
    // with one thread or two (other work lists, other first writers).
    for (int threads : {1, 2}) {
      linked.set_num_threads(threads);
      std::fill(H1.values(), H1.values() + linked.structure().num_values(),
                std::numeric_limits<double>::quiet_NaN());
      g1.setConstant(std::numeric_limits<double>::quiet_NaN());
      REQUIRE(linked.linearize(&H1, g1.data(), &c1, &t));
      CHECK((H1.to_dense() - D1).norm() <= 1e-14 * D1.norm());
    }
    linked.set_num_threads(1);
    CHECK((D1 - D2).norm() <= 1e-12 * D2.norm());
    CHECK((D1 - D2).cwiseAbs().maxCoeff() <= 1e-12 * D2.cwiseAbs().maxCoeff());
    CHECK((g1 - g2).norm() <= 1e-12 * g2.norm());
    CHECK(c1 == Approx(c2).epsilon(1e-14));
  }
}

TEMPLATE_TEST_CASE("Noiseless pose graphs reach cost below 1e-20", "[solver]", lie::SE3d,
                   lie::Sim3d) {
  PoseGraph<TestType> g(60, 0.0, 5);
  Problem p;
  g.build(&p);
  Options o;
  o.function_tolerance = 0.0;
  o.gradient_tolerance = 0.0;
  o.parameter_tolerance = 0.0;
  o.max_iterations = 50;
  LevenbergMarquardt lm(o);
  const solver::Summary s = lm.solve(&p);
  INFO(s.brief_report());
  CHECK(s.initial_cost > 1.0);
  CHECK(s.final_cost < 1e-20);
  CHECK(max_pose_error(g.poses, g.truth) < 1e-9);
  CHECK(s.termination != Termination::kLinearSolverFailure);
  CHECK(s.termination != Termination::kNonFiniteResidual);
}

TEST_CASE("A noisy Sim3 pose graph: CHOLMOD and dense reach the same optimum", "[solver]") {
  PoseGraph<lie::Sim3d> g1(40, 0.01, 11), g2(40, 0.01, 11);
  Problem p1, p2;
  g1.build(&p1, RobustLoss::huber(0.5));
  g2.build(&p2, RobustLoss::huber(0.5));
  LevenbergMarquardt lm1(tight(LinearSolverType::kCholmod)), lm2(tight(LinearSolverType::kDense));
  const solver::Summary s1 = lm1.solve(&p1), s2 = lm2.solve(&p2);
  INFO(s1.brief_report() << "\n" << s2.brief_report());
  CHECK(s1.converged());
  CHECK(s2.converged());
  CHECK(s1.final_cost < 0.01 * s1.initial_cost);
  CHECK(s1.final_cost == Approx(s2.final_cost).epsilon(1e-10));
  CHECK(max_pose_error(g1.poses, g2.poses) < 1e-8);
  CHECK(s1.linear_solver == "cholmod");
  CHECK(s2.linear_solver == "dense");
}

TEST_CASE("Assembled BA Jacobian and normal equations match numeric ones", "[solver][jacobian]") {
  BaScene scene(4, 12, 21);
  Problem p;
  scene.build(&p, RobustLoss());
  p.finalize(/*schur_ordering=*/true);
  CHECK(p.structure().num_eliminated() == 12);
  CHECK(p.parameter_block(&scene.points[0]).col == 2 * 6);  // points after the free cameras
  Eigen::SparseMatrix<double> J;
  Eigen::VectorXd r;
  REQUIRE(p.evaluate_jacobian(&J, &r));
  const Eigen::MatrixXd Jd(J), N = numeric_problem_jacobian(&p);
  CHECK(test::near(Jd, N, 1e-6, test::rounding_floor(1e3, 1e-6)));
  solver::BlockSparseMatrix H(&p.structure());
  Eigen::VectorXd gvec(p.num_effective_parameters());
  double cost = 0.0;
  solver::LinearizeTimes t;
  REQUIRE(p.linearize(&H, gvec.data(), &cost, &t));
  const Eigen::MatrixXd Hd = Jd.transpose() * Jd;
  CHECK(test::near(H.to_dense(), Hd, 1e-12));
  CHECK(test::near(gvec, Jd.transpose() * r, 1e-12));

  // Schur: the reduced camera matrix equals A − B·C⁻¹·Bᵀ, and the solve equals a dense solve.
  const int nc = 12, n = p.num_effective_parameters();
  for (int c = 0; c < n; ++c) H.values()[p.structure().diagonal_positions()[c]] += 1e-3;
  const Eigen::MatrixXd Hdamped = H.to_dense();
  solver::SchurSolver schur(std::make_unique<solver::DenseSolver>());
  REQUIRE(schur.analyze(p.structure()) == solver::LinearSolverStatus::kSuccess);
  REQUIRE(schur.factorize(H) == solver::LinearSolverStatus::kSuccess);
  const Eigen::MatrixXd A = Hdamped.topLeftCorner(nc, nc), B = Hdamped.topRightCorner(nc, n - nc),
                        C = Hdamped.bottomRightCorner(n - nc, n - nc);
  const Eigen::MatrixXd S = A - B * C.inverse() * B.transpose();
  CHECK(test::near(schur.reduced_matrix().to_dense(), S, 1e-10));
  Eigen::VectorXd x(n);
  REQUIRE(schur.solve(gvec.data(), x.data()) == solver::LinearSolverStatus::kSuccess);
  CHECK(test::near(x, Hdamped.ldlt().solve(gvec), 1e-9));
}

TEST_CASE("BA: plain sparse, Schur and dense solves reach the same solution", "[solver]") {
  const LinearSolverType types[] = {
      LinearSolverType::kCholmod,      LinearSolverType::kSchur,
      LinearSolverType::kDense,        LinearSolverType::kSchurDense,
      LinearSolverType::kSchurCholmod, LinearSolverType::kSchurBlockCholesky};
  std::vector<BaScene> scenes;
  std::vector<solver::Summary> sums;
  for (const auto t : types) {
    scenes.emplace_back(6, 60, 31);
    Problem p;
    scenes.back().build(&p, RobustLoss::huber(1.0));
    LevenbergMarquardt lm(tight(t));
    sums.push_back(lm.solve(&p));
    INFO(sums.back().brief_report());
    CHECK(sums.back().converged());
    CHECK(sums.back().final_cost < 0.05 * sums.back().initial_cost);
  }
  // 4 free cameras: the reduced camera system is thin, kSchur takes the block Cholesky.
  CHECK(sums[1].linear_solver == "schur+block-cholesky");
  CHECK(sums[4].linear_solver == "schur+cholmod");
  CHECK(sums[5].linear_solver == "schur+block-cholesky");
  const auto rel = [](const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return (a - b).norm() / (1.0 + b.norm());
  };
  for (std::size_t k = 1; k < scenes.size(); ++k) {
    INFO("solver " << k << ": " << sums[k].brief_report());
    CHECK(sums[k].final_cost == Approx(sums[0].final_cost).epsilon(1e-10));
    for (std::size_t i = 0; i < scenes[0].cams.size(); ++i) {
      Eigen::Matrix<double, 7, 1> a, b;
      a << scenes[k].cams[i].rotation().matrix().reshaped<Eigen::RowMajor>().head<4>(),
          scenes[k].cams[i].translation();
      b << scenes[0].cams[i].rotation().matrix().reshaped<Eigen::RowMajor>().head<4>(),
          scenes[0].cams[i].translation();
      CHECK(rel(a, b) < 1e-8);
    }
    for (std::size_t j = 0; j < scenes[0].points.size(); ++j)
      CHECK(rel(scenes[k].points[j], scenes[0].points[j]) < 1e-8);
  }
}

TEST_CASE("Schur: the block-Cholesky reduced camera system equals the CHOLMOD one",
          "[solver][block_cholesky]") {
  // 24 free cameras, every point seen by 3 of 4 cameras: S is dense (12.5 blocks per column
  // of L), the block Cholesky's domain; the same damped H through both reduced solvers and a
  // dense solve of the whole H.
  BaScene scene(26, 150, 61);
  Problem p;
  scene.build(&p, RobustLoss::huber(1.0));
  p.finalize(/*schur_ordering=*/true);
  solver::BlockSparseMatrix H(&p.structure());
  Eigen::VectorXd g(p.num_effective_parameters());
  double cost = 0.0;
  solver::LinearizeTimes t;
  REQUIRE(p.linearize(&H, g.data(), &cost, &t));
  for (int c = 0; c < p.num_effective_parameters(); ++c)
    H.values()[p.structure().diagonal_positions()[c]] *= 1.0 + 1e-4;
  using RS = solver::SchurSolver::ReducedSolver;
  solver::SchurSolver sc(RS::kCholmod), sb(RS::kBlockCholesky), sa(RS::kAuto);
  Eigen::VectorXd xc(g.size()), xb(g.size()), xa(g.size());
  for (auto* s : {&sc, &sb, &sa}) {
    REQUIRE(s->analyze(p.structure()) == solver::LinearSolverStatus::kSuccess);
    REQUIRE(s->factorize(H) == solver::LinearSolverStatus::kSuccess);
  }
  CHECK(sc.name() == "schur+cholmod");
  CHECK(sb.name() == "schur+block-cholesky");
  CHECK(sa.name() == "schur+block-cholesky");
  CHECK(sc.reduced_structure().num_blocks() == 24);
  // Same elimination: identical reduced matrices.
  CHECK(sb.reduced_matrix().to_dense() == sc.reduced_matrix().to_dense());
  REQUIRE(sc.solve(g.data(), xc.data()) == solver::LinearSolverStatus::kSuccess);
  REQUIRE(sb.solve(g.data(), xb.data()) == solver::LinearSolverStatus::kSuccess);
  REQUIRE(sa.solve(g.data(), xa.data()) == solver::LinearSolverStatus::kSuccess);
  const Eigen::VectorXd xd = H.to_dense().ldlt().solve(g);
  INFO("|xb - xc| / |xc| = " << (xb - xc).norm() / xc.norm());
  CHECK((xb - xc).norm() <= 1e-11 * xc.norm());
  CHECK((xa - xb).norm() == 0.0);
  CHECK((xb - xd).norm() <= 1e-9 * xd.norm());

  // A point block that is not positive definite is a status through either reduced solver.
  const solver::BlockStructure& s = p.structure();
  const int last = s.num_blocks() - 1;
  H.values()[s.block_offsets()[s.block_col_ptr()[last + 1] - 1]] = -1.0;
  CHECK(sb.factorize(H) == solver::LinearSolverStatus::kNotPositiveDefinite);
  CHECK(sc.factorize(H) == solver::LinearSolverStatus::kNotPositiveDefinite);
  CHECK_THAT(sb.message(), Catch::Contains("point block"));
}

TEST_CASE("Schur kAuto: CHOLMOD for a dense reduced system beyond the block Cholesky's range",
          "[solver]") {
  // 62 free cameras all sharing points: S is dense with 31.5 blocks per column > 24.
  BaScene scene(64, 40, 71);
  Problem p;
  scene.build(&p, RobustLoss());
  p.finalize(/*schur_ordering=*/true);
  solver::SchurSolver sa(solver::SchurSolver::ReducedSolver::kAuto);
  REQUIRE(sa.analyze(p.structure()) == solver::LinearSolverStatus::kSuccess);
  CHECK(sa.name() == "schur+cholmod");
}

TEST_CASE("BA with raw double[3] points (Euclidean<3>) matches Eigen points", "[solver]") {
  BaScene a(5, 30, 41), b(5, 30, 41);
  Problem pa, pb;
  a.build(&pa, RobustLoss::cauchy(2.0));
  for (const auto& o : b.obs) {
    solver::ReprojectionResidual r;
    r.fx = b.fx;
    r.fy = b.fy;
    r.cx = b.cx;
    r.cy = b.cy;
    r.uv = o.uv;
    pb.add_residual_block(r, RobustLoss::cauchy(2.0), 1.0, &b.cams[o.cam],
                          solver::euclidean<3>(b.points[o.point].data()));
  }
  pb.set_constant(&b.cams[0]);
  pb.set_constant(&b.cams[1]);
  LevenbergMarquardt lm(tight(LinearSolverType::kSchur));
  const solver::Summary sa = lm.solve(&pa);
  const solver::Summary sb = lm.solve(&pb);
  INFO(sa.brief_report() << "\n" << sb.brief_report());
  CHECK(sb.converged());
  CHECK(sa.final_cost == Approx(sb.final_cost).epsilon(1e-12));
  for (std::size_t j = 0; j < a.points.size(); ++j)
    CHECK((a.points[j] - b.points[j]).norm() < 1e-9);
}

TEST_CASE("Two evaluation threads give the same solves as one, bit for bit", "[solver]") {
  // Sim3 pose graph (CHOLMOD) and BA (Schur), 1 vs 2 threads: both take every sum in the same
  // order (Problem::set_num_threads), so the iterations, costs and states are identical.
  PoseGraph<lie::Sim3d> g1(50, 0.01, 13), g2(50, 0.01, 13);
  Problem p1, p2;
  g1.build(&p1);
  g2.build(&p2);
  Options o1 = tight(LinearSolverType::kCholmod), o2 = o1;
  o2.num_threads = 2;
  LevenbergMarquardt lm1(o1), lm2(o2);
  const solver::Summary s1 = lm1.solve(&p1), s2 = lm2.solve(&p2);
  INFO(s1.brief_report() << "\n" << s2.brief_report());
  CHECK(p2.num_threads() == 2);
  CHECK(s2.converged());
  CHECK(s1.initial_cost == s2.initial_cost);
  CHECK(s1.final_cost == s2.final_cost);
  CHECK(s1.iterations == s2.iterations);
  for (std::size_t k = 0; k < g1.poses.size(); ++k) {
    CHECK(g1.poses[k].matrix() == g2.poses[k].matrix());
  }

  BaScene a(6, 60, 51), b(6, 60, 51);
  Problem pa, pb;
  a.build(&pa, RobustLoss::huber(1.0));
  b.build(&pb, RobustLoss::huber(1.0));
  Options oa = tight(LinearSolverType::kSchur), ob = oa;
  ob.num_threads = 2;
  LevenbergMarquardt lma(oa), lmb(ob);
  const solver::Summary sa = lma.solve(&pa), sb = lmb.solve(&pb);
  CHECK(sb.converged());
  CHECK(sa.final_cost == sb.final_cost);
  for (std::size_t j = 0; j < a.points.size(); ++j) CHECK(a.points[j] == b.points[j]);

  // An unevaluable residual is reported with two threads too (it sits in the second half).
  Problem pc;
  BaScene c(6, 60, 51);
  c.build(&pc, RobustLoss());
  c.points.back() = Eigen::Vector3d(0.0, 0.0, -100.0);  // behind every camera
  LevenbergMarquardt lmc(ob);
  const solver::Summary sc = lmc.solve(&pc);
  CHECK(sc.termination == Termination::kNonFiniteResidual);
  CHECK_THAT(sc.message, Catch::Contains("residual block"));
}

TEST_CASE("With two threads the cost-only pass sums exactly as the linearisation does",
          "[solver]") {
  // LM compares a trial cost from evaluate_cost() with one from linearize(): with two threads
  // both use the same work lists and summation order, so equal states give equal costs, bit
  // for bit; before finalize() evaluate_cost() runs every block on the calling thread.
  for (const double noise : {0.01, 0.03, 0.1}) {
    PoseGraph<lie::Sim3d> graph(200, noise, 13);
    Problem p;
    graph.build(&p, RobustLoss::cauchy(0.5));
    double c_before = 0.0;
    REQUIRE(p.evaluate_cost(&c_before));
    p.set_num_threads(2);
    p.finalize();
    solver::BlockSparseMatrix H;
    H.reset(&p.structure());
    Eigen::VectorXd g(p.num_effective_parameters());
    solver::LinearizeTimes lt;
    double c_lin = 0.0, c_cost = 0.0;
    REQUIRE(p.linearize(&H, g.data(), &c_lin, &lt));
    REQUIRE(p.evaluate_cost(&c_cost));
    INFO("noise " << noise);
    CHECK(c_cost == c_lin);
    CHECK(c_before == Approx(c_lin).epsilon(1e-13));
    CHECK(c_lin > 1e-3);  // a perturbed graph: not a vacuous sum
  }
}

TEMPLATE_TEST_CASE("Block Cholesky and kAuto reach the CHOLMOD and dense solution on pose graphs",
                   "[solver][block_cholesky]", lie::SE3d, lie::Sim3d) {
  const LinearSolverType types[] = {LinearSolverType::kCholmod, LinearSolverType::kDense,
                                    LinearSolverType::kBlockCholesky, LinearSolverType::kAuto};
  std::vector<PoseGraph<TestType>> graphs;
  std::vector<solver::Summary> sums;
  for (const auto t : types) {
    graphs.emplace_back(60, 0.01, 17);
    Problem p;
    graphs.back().build(&p, RobustLoss::huber(0.5));
    LevenbergMarquardt lm(tight(t));
    sums.push_back(lm.solve(&p));
    INFO(sums.back().brief_report());
    CHECK(sums.back().converged());
    CHECK(sums.back().final_cost < 0.05 * sums.back().initial_cost);
    if (t == LinearSolverType::kAuto) {
      const bool thin =
          solver::BlockCholeskySolver::thin_factor(p.structure(), solver::kAutoMaxBlocksPerColumn);
      CHECK(sums.back().linear_solver == (thin ? "block-cholesky" : "cholmod"));
    }
    // the trace: start + one record per iteration, costs never increase
    REQUIRE(static_cast<int>(sums.back().trace.size()) >= sums.back().iterations);
    CHECK(sums.back().trace.front().cost == sums.back().initial_cost);
    for (std::size_t k = 1; k < sums.back().trace.size(); ++k)
      CHECK(sums.back().trace[k].cost <= sums.back().trace[k - 1].cost);
  }
  CHECK(sums[2].linear_solver == "block-cholesky");
  for (std::size_t k = 1; k < graphs.size(); ++k) {
    INFO("solver " << sums[k].linear_solver);
    CHECK(sums[k].final_cost == Approx(sums[0].final_cost).epsilon(1e-10));
    // 5e-8: the two reference solvers themselves (CHOLMOD, dense) stop 1.1e-8 apart on this
    // Huber Sim3 graph (flat optimum, parameter-tolerance stop); a wrong factor is off by ≫ 1e-6.
    CHECK(max_pose_error(graphs[k].poses, graphs[0].poses) < 5e-8);
  }
}

namespace {
struct PointPrior {
  static constexpr int kNumResiduals = 3;
  bool operator()(const Eigen::Vector3d& p, Eigen::Vector3d* r,
                  Eigen::Matrix3d* J = nullptr) const {
    *r = p - Eigen::Vector3d(1.5, 2.0, 2.0);
    if (J) J->setIdentity();
    return true;
  }
};
}  // namespace

TEST_CASE("kAuto picks the block Cholesky on a chain and CHOLMOD on mixed block sizes",
          "[solver][block_cholesky]") {
  // Chain-shaped Sim3 graph (edges k -> k+1, k+2 only): thin factor.
  PoseGraph<lie::Sim3d> g(40, 0.01, 23), ref(40, 0.01, 23);
  const auto chain_only = [](PoseGraph<lie::Sim3d>* pg) {
    std::vector<typename PoseGraph<lie::Sim3d>::Edge> keep;
    for (const auto& e : pg->edges)
      if (e.j - e.i == 1 || e.j - e.i == 2) keep.push_back(e);
    pg->edges = keep;
  };
  chain_only(&g);
  chain_only(&ref);
  Problem p, pr;
  g.build(&p);
  ref.build(&pr);
  LevenbergMarquardt lm(tight(LinearSolverType::kAuto)), lmr(tight(LinearSolverType::kCholmod));
  const solver::Summary s = lm.solve(&p), sr = lmr.solve(&pr);
  INFO(s.brief_report());
  CHECK(s.linear_solver == "block-cholesky");
  CHECK(s.converged());
  CHECK(s.final_cost == Approx(sr.final_cost).epsilon(1e-10));
  // The chain-only graph is flat along its weakly constrained far end: block Cholesky, CHOLMOD
  // and a dense solve stop (|δ| ≈ 5e-13, costs equal to 1e-15) 2e-8 … 6.5e-8 apart in pose, so the
  // bound is 1e-7 (a wrong factor moves the optimum by orders more; see the cost check above).
  CHECK(max_pose_error(g.poses, ref.poses) < 1e-7);
  // Solving again reuses the analysis.
  const solver::Summary s2 = lm.solve(&p);
  CHECK(s2.time_analyze == 0.0);
  CHECK(s2.linear_solver == "block-cholesky");

  // A Sim3 pose with an R^3 point attached: mixed sizes; kBlockCholesky is an invalid problem,
  // kAuto uses CHOLMOD.
  PoseGraph<lie::Sim3d> m(10, 0.01, 5);
  Eigen::Vector3d x(1.0, 2.0, 3.0);
  Problem pm;
  m.build(&pm);
  pm.add_residual_block(solver::CameraCentrePriorResidual<lie::Sim3d>{Eigen::Vector3d(0, 0, 1)},
                        RobustLoss(), 1.0, &m.poses[3]);
  pm.add_residual_block(PointPrior{}, RobustLoss(), 1.0, &x);
  LevenbergMarquardt bad(tight(LinearSolverType::kBlockCholesky));
  const solver::Summary sb = bad.solve(&pm);
  CHECK(sb.termination == Termination::kInvalidProblem);
  CHECK_THAT(sb.message, Catch::Contains("size 6 or 7"));
  LevenbergMarquardt aut(tight(LinearSolverType::kAuto));
  const solver::Summary sa = aut.solve(&pm);
  CHECK(sa.linear_solver == "cholmod");
  CHECK(sa.converged());
}

TEST_CASE("Speculative linearisation and the damping limit change the cost, not the optimum",
          "[solver]") {
  // Same problem, four settings: speculative on/off must take identical steps; Nielsen's 1/3
  // and Marquardt's 1/10 limit reach the same optimum.
  struct Run {
    bool speculative;
    double limit;
  };
  const Run runs[] = {{true, 0.1}, {false, 0.1}, {true, 1.0 / 3.0}, {false, 1.0 / 3.0}};
  std::vector<PoseGraph<lie::Sim3d>> graphs;
  std::vector<solver::Summary> sums;
  for (const Run& r : runs) {
    graphs.emplace_back(50, 0.01, 29);
    Problem p;
    graphs.back().build(&p, RobustLoss::cauchy(1.0));
    Options o = tight(LinearSolverType::kAuto);
    o.speculative_linearization = r.speculative;
    o.lambda_decrease_limit = r.limit;
    LevenbergMarquardt lm(o);
    sums.push_back(lm.solve(&p));
    INFO(sums.back().brief_report());
    CHECK(sums.back().converged());
  }
  for (int k : {0, 2}) {
    CHECK(sums[k].iterations == sums[k + 1].iterations);
    CHECK(sums[k].successful_steps == sums[k + 1].successful_steps);
    REQUIRE(sums[k].trace.size() == sums[k + 1].trace.size());
    for (std::size_t t = 0; t < sums[k].trace.size(); ++t)
      CHECK(sums[k].trace[t].cost == Approx(sums[k + 1].trace[t].cost).epsilon(1e-12));
  }
  for (std::size_t k = 1; k < sums.size(); ++k) {
    CHECK(sums[k].final_cost == Approx(sums[0].final_cost).epsilon(1e-10));
    CHECK(max_pose_error(graphs[k].poses, graphs[0].poses) < 1e-8);
  }
}

TEST_CASE("One LevenbergMarquardt reuses its symbolic analysis across problems of the same pattern",
          "[solver][reuse]") {
  // Sliding-window use: a sequence of DIFFERENT Problem objects (other measurements, other start
  // values) with the same block pattern, solved by one LM object. From the second on the analysis
  // is reused, and every result equals a fresh LM's (which analyses from scratch). A problem of
  // another pattern is analysed again and is still solved correctly; the first pattern after it
  // is analysed again too (one cached analysis).
  for (const auto type :
       {LinearSolverType::kCholmod, LinearSolverType::kBlockCholesky, LinearSolverType::kAuto}) {
    LevenbergMarquardt shared(tight(type));
    const struct {
      int n;
      unsigned seed;
      bool reused;
    } runs[] = {{30, 1, false}, {30, 2, true},  {30, 3, true},
                {36, 4, false}, {30, 5, false}, {30, 6, true}};
    for (const auto& run : runs) {
      INFO("type " << static_cast<int>(type) << " n " << run.n << " seed " << run.seed);
      PoseGraph<lie::Sim3d> g(run.n, 0.01, run.seed), ref(run.n, 0.01, run.seed);
      Problem p, pr;
      g.build(&p);
      ref.build(&pr);
      const solver::Summary s = shared.solve(&p);
      LevenbergMarquardt fresh(tight(type));
      const solver::Summary sr = fresh.solve(&pr);
      INFO(s.brief_report());
      CHECK(s.analysis_reused == run.reused);
      CHECK((s.time_analyze == 0.0) == run.reused);
      CHECK_FALSE(sr.analysis_reused);
      CHECK(s.converged());
      CHECK(s.final_cost < 1e-2 * s.initial_cost);
      CHECK(s.final_cost == Approx(sr.final_cost).epsilon(1e-12));
      CHECK(s.iterations == sr.iterations);
      CHECK(max_pose_error(g.poses, ref.poses) < 1e-10);
    }
  }
  // BA windows through the Schur path: same cameras/points/visibility, other noise and start.
  LevenbergMarquardt shared(tight(LinearSolverType::kSchur));
  for (unsigned seed : {51u, 52u, 53u}) {
    INFO("BA seed " << seed);
    BaScene a(6, 50, seed), b(6, 50, seed);
    Problem pa, pb;
    a.build(&pa, RobustLoss::huber(1.0));
    b.build(&pb, RobustLoss::huber(1.0));
    const solver::Summary s = shared.solve(&pa);
    const solver::Summary sr = LevenbergMarquardt(tight(LinearSolverType::kSchur)).solve(&pb);
    INFO(s.brief_report());
    CHECK(s.analysis_reused == (seed != 51u));
    CHECK(s.converged());
    CHECK(s.final_cost == Approx(sr.final_cost).epsilon(1e-12));
    for (std::size_t j = 0; j < a.points.size(); ++j)
      CHECK((a.points[j] - b.points[j]).norm() < 1e-9 * (1.0 + b.points[j].norm()));
  }
}

namespace {

/// Geodesic-acceleration right-hand side from assembled Jacobians, block by block: `plain` holds
/// the same blocks without loss (its evaluate_jacobian gives e = W·r and W·J), `loss` is the
/// tested problem's loss, m the rows of every block. rhs = Σ J̃ᵀ·(2/h)·(C·(e_h − e)/h − J̃·v),
/// C the Triggs corrector at e (identity without a loss), J̃ = C·W·J.
Eigen::VectorXd reference_acceleration(Problem* plain, const RobustLoss& loss, int m,
                                       const Eigen::VectorXd& v, double h) {
  Eigen::SparseMatrix<double> Js, Jh;
  Eigen::VectorXd e, eh;
  REQUIRE(plain->evaluate_jacobian(&Js, &e));
  const Eigen::VectorXd hv = h * v;
  plain->save_state();
  plain->plus(hv.data());
  REQUIRE(plain->evaluate_jacobian(&Jh, &eh));
  plain->restore_state();
  const Eigen::MatrixXd J = Js;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(v.size());
  for (int k = 0; k * m < e.size(); ++k) {
    Eigen::VectorXd ek = e.segment(k * m, m);
    Eigen::VectorXd de = (eh.segment(k * m, m) - ek) / h;
    Eigen::MatrixXd Jk = J.middleRows(k * m, m);
    if (!loss.is_trivial()) {
      double rho[3];
      const double s = ek.squaredNorm();
      loss.evaluate(s, rho);
      const solver::TriggsCorrector C(s, rho);
      C.correct_jacobian(ek, Jk);
      C.correct_jacobian(ek, de);
    }
    rhs += Jk.transpose() * ((2.0 / h) * (de - Jk * v));
  }
  return rhs;
}

/// acceleration_rhs() of p after a linearisation that keeps the acceleration stores, along v.
Eigen::VectorXd library_acceleration(Problem* p, const Eigen::VectorXd& v, double h) {
  p->finalize(p->has_schur_ordering());
  p->reserve_acceleration(true);
  solver::BlockSparseMatrix H;
  H.reset(&p->structure());
  Eigen::VectorXd g(p->num_effective_parameters()), rhs(p->num_effective_parameters());
  solver::LinearizeTimes lt;
  double cost = 0.0;
  REQUIRE(p->linearize(&H, g.data(), &cost, &lt, nullptr, true));
  REQUIRE(p->acceleration_rhs(v.data(), h, rhs.data()));
  return rhs;
}

Eigen::VectorXd random_step(int n, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> d(0.0, scale);
  Eigen::VectorXd v(n);
  for (int c = 0; c < n; ++c) v[c] = d(rng);
  return v;
}

double relative_difference(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).lpNorm<Eigen::Infinity>() / std::max(1e-300, b.lpNorm<Eigen::Infinity>());
}

}  // namespace

TEMPLATE_TEST_CASE(
    "Geodesic acceleration right-hand side equals J̃ᵀ·r̃'' from the assembled "
    "Jacobian",
    "[solver][acceleration]", lie::SE3d, lie::Sim3d) {
  // Pose graph with a 6/7-dof information matrix (the container's sqrt-information table),
  // without and with a Cauchy loss, one and two threads; BA (SE3 + R³, two constant cameras)
  // with Huber through the Schur ordering.
  const double h = 0.1;
  for (const RobustLoss& loss : {RobustLoss(), RobustLoss::cauchy(0.5)}) {
    PoseGraph<TestType> a(30, 0.02, 41), b(30, 0.02, 41);
    Problem pa, pb;
    a.build(&pa, loss);
    b.build(&pb);
    pa.finalize();
    const Eigen::VectorXd v = random_step(pa.num_effective_parameters(), 0.02, 5);
    const Eigen::VectorXd ref = reference_acceleration(&pb, loss, TestType::kDoF, v, h);
    const Eigen::VectorXd got = library_acceleration(&pa, v, h);
    INFO("loss trivial " << loss.is_trivial() << " |ref| " << ref.lpNorm<Eigen::Infinity>());
    CHECK(ref.lpNorm<Eigen::Infinity>() > 1e-3);  // a curved problem: not a vacuous check
    CHECK(relative_difference(got, ref) < 1e-9);
    pa.set_num_threads(2);
    const Eigen::VectorXd got2 = library_acceleration(&pa, v, h);
    CHECK(relative_difference(got2, got) < 1e-13);
    // The states are back where they were, bit for bit.
    for (std::size_t k = 0; k < a.poses.size(); ++k) {
      CHECK(a.poses[k].translation() == b.poses[k].translation());
      CHECK(a.poses[k].rotation().quaternion().coeffs() ==
            b.poses[k].rotation().quaternion().coeffs());
    }
  }
}

TEST_CASE("Geodesic acceleration right-hand side tends to Jᵀ·r'' as h shrinks, at first order",
          "[solver][acceleration]") {
  // The library's one-sided difference (e at x ⊞ h·v against e and J kept from x) has the limit
  // J(x)ᵀ·r''_v, r''_v the second directional derivative: here a central difference, ε = 1e-4.
  PoseGraph<lie::Sim3d> a(30, 0.02, 41), b(30, 0.02, 41);
  Problem pa, pb;
  a.build(&pa);
  b.build(&pb);
  pa.finalize();
  pb.finalize();
  const Eigen::VectorXd v = random_step(pa.num_effective_parameters(), 0.02, 5);
  Eigen::SparseMatrix<double> J, Jp, Jm;
  Eigen::VectorXd e, ep, em;
  REQUIRE(pb.evaluate_jacobian(&J, &e));
  const double eps = 1e-4;
  const Eigen::VectorXd sv = eps * v, msv = -eps * v;
  pb.save_state();
  pb.plus(sv.data());
  REQUIRE(pb.evaluate_jacobian(&Jp, &ep));
  pb.restore_state();
  pb.plus(msv.data());
  REQUIRE(pb.evaluate_jacobian(&Jm, &em));
  pb.restore_state();
  const Eigen::VectorXd ref = J.transpose() * ((ep - 2.0 * e + em) / (eps * eps));
  // h = 0.1 (the default) and 0.01; smaller h would meet the reference's own rounding.
  const double err_1 = relative_difference(library_acceleration(&pa, v, 1e-1), ref);
  const double err_2 = relative_difference(library_acceleration(&pa, v, 1e-2), ref);
  INFO("|ref| " << ref.lpNorm<Eigen::Infinity>() << " error at h = 0.1 " << err_1 << ", at 0.01 "
                << err_2);
  CHECK(ref.lpNorm<Eigen::Infinity>() > 1e-3);
  CHECK(err_1 < 1e-2);
  CHECK(err_2 < 1e-3);
  CHECK(err_1 / err_2 > 5.0);  // O(h): a tenth of h, about a tenth of the error
  CHECK(err_1 / err_2 < 20.0);
}

TEST_CASE("Geodesic acceleration right-hand side for BA with Huber and constant cameras",
          "[solver][acceleration]") {
  const double h = 0.1;
  BaScene a(6, 40, 23), b(6, 40, 23);
  Problem pa, pb;
  a.build(&pa, RobustLoss::huber(0.5));  // 0.5 px noise: some residuals are beyond 0.5
  b.build(&pb, RobustLoss());
  pa.finalize(true);
  pb.finalize(true);
  const int n = pa.num_effective_parameters();
  const Eigen::VectorXd v = random_step(n, 0.01, 9);
  const Eigen::VectorXd ref = reference_acceleration(&pb, RobustLoss::huber(0.5), 2, v, h);
  const Eigen::VectorXd got = library_acceleration(&pa, v, h);
  CHECK(ref.lpNorm<Eigen::Infinity>() > 1e-3);
  CHECK(relative_difference(got, ref) < 1e-9);
}

namespace {

/// A monocular-drift Sim(3) chain (the bench_solver drift graph in small): keyframes every
/// 1.5 m along straight blocks with 90° turns, VO odometry whose translation scale follows a
/// log random walk (sd `drift` per keyframe), edges to the next 4 keyframes (weight 1e4), a 1 m
/// camera-centre prior every 50 keyframes. States start at the chained odometry.
struct DriftChain {
  std::vector<lie::Sim3d> truth, S;
  explicit DriftChain(int n, double drift, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> N(0.0, 1.0);
    Eigen::Vector3d c(0, 0, 0);
    double heading = 0.0;
    for (int k = 0; k < n; ++k) {
      if (k > 0 && k % 80 == 0) heading += (N(rng) > 0 ? 1.0 : -1.0) * M_PI / 2;
      c += 1.5 * Eigen::Vector3d(std::cos(heading), std::sin(heading), 0.0);
      // camera z forward along the heading, y down
      Eigen::Matrix3d R_wc;
      R_wc.col(2) = Eigen::Vector3d(std::cos(heading), std::sin(heading), 0.0);
      R_wc.col(1) = Eigen::Vector3d(0, 0, -1);
      R_wc.col(0) = R_wc.col(1).cross(R_wc.col(2));
      const lie::SE3d T_cw = lie::SE3d(lie::SO3d(Eigen::Quaterniond(R_wc)), c).inverse();
      truth.emplace_back(T_cw.rotation(), T_cw.translation(), 1.0);
    }
    S.push_back(truth[0]);
    double log_scale = 0.0;
    for (int k = 0; k + 1 < n; ++k) {
      log_scale += drift * N(rng);
      lie::Sim3d d = truth[k + 1] * truth[k].inverse();
      d = lie::Sim3d(d.rotation(), std::exp(log_scale) * d.translation(), 1.0);
      const Eigen::Vector3d w(N(rng), N(rng), N(rng));
      d = lie::Sim3d(lie::SO3d::exp(5e-4 * w) * d.rotation(), d.translation(), 1.0);
      S.push_back(d * S.back());
    }
  }
  void build(Problem* p) {
    const int n = static_cast<int>(S.size());
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j <= std::min(n - 1, i + 4); ++j)
        p->add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{S[j] * S[i].inverse()},
                              RobustLoss(), 1e4, &S[i], &S[j]);
    for (int i = 0; i < n; i += 50) {
      solver::CameraCentrePriorResidual<lie::Sim3d> f;
      f.y = truth[i].inverse().translation();
      p->add_residual_block(f, RobustLoss(), 1.0, &S[i]);
    }
  }
};

/// LM with oa on chain a and with ob on chain b (two copies of one chain): their summaries.
std::pair<solver::Summary, solver::Summary> solve_both(DriftChain* a, DriftChain* b,
                                                       const Options& oa, const Options& ob) {
  Problem pa, pb;
  a->build(&pa);
  b->build(&pb);
  LevenbergMarquardt lma(oa), lmb(ob);
  const solver::Summary sa = lma.solve(&pa);
  return {sa, lmb.solve(&pb)};
}

/// First iteration whose cost is within rel of `target`.
int iterations_to_reach(const solver::Summary& s, double target, double rel) {
  for (const auto& r : s.trace)
    if (r.cost <= (1.0 + rel) * target) return r.iteration;
  return -1;
}

}  // namespace

TEST_CASE("Geodesic acceleration reaches the same optima, sooner on a drifting Sim3 chain",
          "[solver][acceleration]") {
  // Same optimum with and without: a noisy Sim3 loop graph with Cauchy (block Cholesky) and BA
  // with Huber (Schur).
  const auto plain_and_accelerated = [](auto& a, auto& b, const RobustLoss& loss,
                                        LinearSolverType type) {
    Problem pa, pb;
    a.build(&pa, loss);
    b.build(&pb, loss);
    Options oa = tight(type), ob = oa;
    ob.geodesic_acceleration = true;
    LevenbergMarquardt lma(oa), lmb(ob);
    const solver::Summary sa = lma.solve(&pa), sb = lmb.solve(&pb);
    INFO(sa.brief_report() << "\n" << sb.brief_report());
    CHECK(sb.converged());
    CHECK(sb.accelerated_steps > 0);
    CHECK(sb.final_cost == Approx(sa.final_cost).epsilon(1e-10));
  };
  {
    PoseGraph<lie::Sim3d> a(50, 0.01, 29), b(50, 0.01, 29);
    plain_and_accelerated(a, b, RobustLoss::cauchy(1.0), LinearSolverType::kAuto);
    CHECK(max_pose_error(a.poses, b.poses) < 1e-8);
  }
  {
    BaScene a(6, 60, 51), b(6, 60, 51);
    plain_and_accelerated(a, b, RobustLoss::huber(1.0), LinearSolverType::kSchur);
    for (std::size_t j = 0; j < a.points.size(); ++j)
      CHECK((a.points[j] - b.points[j]).norm() < 1e-8 * (1.0 + a.points[j].norm()));
  }
  // The drifting chain: 600 keyframes, log-scale random walk of 2 % per keyframe (1.5 m):
  // the curved valley the acceleration is for. Both start at λ0 = 1e-8 (no damping-limited
  // start), one and two threads.
  for (int threads : {1, 2}) {
    DriftChain a(600, 0.02, 3), b(600, 0.02, 3);
    Options oa;
    oa.initial_lambda = 1e-8;
    oa.num_threads = threads;
    Options ob = oa;
    ob.geodesic_acceleration = true;
    const auto [sa, sb] = solve_both(&a, &b, oa, ob);
    INFO(sa.brief_report() << "\n" << sb.brief_report());
    REQUIRE(sa.converged());
    REQUIRE(sb.converged());
    CHECK(sb.final_cost == Approx(sa.final_cost).epsilon(1e-6));
    CHECK(sa.initial_cost > 50.0 * sa.final_cost);  // far from the optimum at the start
    const double target = std::min(sa.final_cost, sb.final_cost);
    const int ia = iterations_to_reach(sa, target, 1e-3),
              ib = iterations_to_reach(sb, target, 1e-3);
    INFO("iterations to within 0.1 %: plain " << ia << ", accelerated " << ib);
    CHECK(ib >= 1);
    CHECK(ib < ia);
  }
}

TEST_CASE("Backtracking along a rejected step saves factorisations, same optimum",
          "[solver][backtracking]") {
  // A drifting chain with a 4 % log-scale walk per keyframe from λ0 = 1e-8, plain and
  // accelerated: full steps overshoot (4 and 3 rejected without backtracking), and the shortened
  // step t·v + (t²/2)·a lowers the cost instead (28 → 20 and 12 → 7 linear solves).
  for (bool accel : {false, true}) {
    DriftChain a(600, 0.04, 3), b(600, 0.04, 3);
    Options oa;
    oa.initial_lambda = 1e-8;
    oa.geodesic_acceleration = accel;
    Options ob = oa;
    ob.backtracking = true;
    const auto [sa, sb] = solve_both(&a, &b, oa, ob);
    INFO("accel " << accel << "\n" << sa.brief_report() << "\n" << sb.brief_report());
    REQUIRE(sa.converged());
    REQUIRE(sb.converged());
    CHECK(sa.unsuccessful_steps > 0);  // the case backtracking is for
    CHECK(sa.backtracked_steps == 0);
    CHECK(sb.backtracked_steps > 0);
    CHECK(sb.final_cost == Approx(sa.final_cost).epsilon(1e-6));
    CHECK(max_pose_error(a.S, b.S) < 1e-4);
    // Fewer linear solves to get within 0.1 % of the optimum; the cost never rises.
    const double target = std::min(sa.final_cost, sb.final_cost);
    const int ia = iterations_to_reach(sa, target, 1e-3),
              ib = iterations_to_reach(sb, target, 1e-3);
    INFO("iterations to within 0.1 %: without " << ia << ", with backtracking " << ib);
    CHECK(ib >= 1);
    CHECK(ib < ia);
    for (std::size_t k = 1; k < sb.trace.size(); ++k)
      CHECK(sb.trace[k].cost <= sb.trace[k - 1].cost);
  }
}

namespace {
/// Two solves took the same steps: iterations, accepted steps and, record by record, the same
/// accepted/rejected sequence and costs equal to `cost_epsilon` (relative).
void check_same_steps(const solver::Summary& sa, const solver::Summary& sb, double cost_epsilon) {
  CHECK(sa.iterations == sb.iterations);
  CHECK(sa.successful_steps == sb.successful_steps);
  REQUIRE(sa.trace.size() == sb.trace.size());
  for (std::size_t k = 0; k < sa.trace.size(); ++k) {
    CHECK(sa.trace[k].accepted == sb.trace[k].accepted);
    CHECK(sa.trace[k].cost == Approx(sb.trace[k].cost).epsilon(cost_epsilon));
  }
}
}  // namespace

TEST_CASE("Speculative linearisation takes the same steps through rejected trials",
          "[solver][backtracking]") {
  // A chain with 20 % scale drift per step: after an accepted step the next trial is often
  // linearised into H (and the acceleration store) and then rejected, so x is linearised again.
  // Speculation on and off must take the same steps, with and without acceleration and
  // backtracking.
  for (bool accel : {false, true}) {
    for (bool backtrack : {false, true}) {
      DriftChain a(600, 0.2, 8), b(600, 0.2, 8);
      Options oa;
      oa.initial_lambda = 1e-4;
      oa.max_iterations =
          40;  // the rejections come early; equal steps is the point, not the optimum
      oa.geodesic_acceleration = accel;
      oa.backtracking = backtrack;
      oa.speculative_linearization = true;
      Options ob = oa;
      ob.speculative_linearization = false;
      const auto [sa, sb] = solve_both(&a, &b, oa, ob);
      INFO("accel " << accel << " backtracking " << backtrack << "\n"
                    << sa.brief_report() << "\n"
                    << sb.brief_report());
      std::string pattern;
      for (const auto& t : sa.trace) pattern += t.accepted ? '+' : '-';
      INFO("trace " << pattern);
      REQUIRE((sa.converged() || sa.termination == Termination::kMaxIterations));
      // Trials made right after an accepted step (speculative ones) that were not accepted.
      int rejected_after_accept = 0;
      for (std::size_t k = 2; k < sa.trace.size(); ++k)
        rejected_after_accept += sa.trace[k - 1].accepted && !sa.trace[k].accepted;
      if (!backtrack) CHECK(rejected_after_accept > 0);
      check_same_steps(sa, sb, 1e-12);
      CHECK(sa.backtracked_steps == sb.backtracked_steps);
      // Same steps up to rounding (the cost-only and the linearising evaluation differ in the last
      // bit): 1e-10 on a 900 m chain is 1e-13 relative.
      CHECK(max_pose_error(a.S, b.S) < 1e-10);
    }
  }
}

TEST_CASE("The factor written over H takes the same steps as one of its own, through rejections",
          "[solver][block_cholesky]") {
  // The drifting chain of the case above (kAuto: the block Cholesky, natural order, no fill, so
  // in place). A rejected step has to get H back by linearising x again; without speculation
  // that is the only reason to do so. In place and separate must take the same steps: the same
  // accepted/rejected sequence and the same costs up to rounding. The two factorisations sum in
  // different orders (row by row in place, column by column otherwise), and this chain's H is
  // ill-conditioned (20 % scale steps), so their steps differ by ~1e-12 relative, which 40
  // iterations carry to 2e-12 in the cost (2e-9 with the acceleration, whose step is a
  // difference quotient of the residuals) and 2e-7 m on the 900 m chain; a factorisation of a
  // stale H (the factor itself) would not come near either bound.
  for (bool accel : {false, true}) {
    for (bool speculate : {false, true}) {
      DriftChain a(600, 0.2, 8), b(600, 0.2, 8);
      Options oa;
      oa.initial_lambda = 1e-4;
      oa.max_iterations = 40;
      oa.geodesic_acceleration = accel;
      oa.speculative_linearization = speculate;
      oa.in_place_factor = true;
      Options ob = oa;
      ob.in_place_factor = false;
      const auto [sa, sb] = solve_both(&a, &b, oa, ob);
      INFO("accel " << accel << " speculate " << speculate << "\n"
                    << sa.brief_report() << "\n"
                    << sb.brief_report());
      CHECK(sa.linear_solver == "block-cholesky");
      CHECK(sa.unsuccessful_steps > 0);  // the case the relinearisation is for
      check_same_steps(sa, sb, 1e-8);
      CHECK(max_pose_error(a.S, b.S) < 1e-5);
    }
  }
}

TEST_CASE("Geodesic acceleration options are validated", "[solver][acceleration]") {
  std::string why;
  Options o;
  o.acceleration_step = 0.0;
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("acceleration_step"));
  o = Options();
  o.max_acceleration_ratio = std::numeric_limits<double>::quiet_NaN();
  CHECK_FALSE(o.validate(&why));
  CHECK_THAT(why, Catch::Contains("max_acceleration_ratio"));
}
