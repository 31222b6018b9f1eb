#pragma once

/// @file
/// geodrift solver problems built from the benchmark data (the same data the Ceres twins use),
/// and the CHOLMOD "floor": one bare numeric factorisation of the problem's normal
/// matrix H (AMD ordering, symbolic analysis excluded), median of 5.

#include <cholmod.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <memory>
#include <vector>

#include "geodrift/io/g2o.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"
#include "support/ba_data.hpp"
#include "support/drift_graph.hpp"

namespace geodrift::bench {

/// States + problem; the states live in this object (the Problem points into them).
struct OurSe3Graph {
  std::vector<lie::SE3d> T;  ///< T_iw
  solver::Problem problem;
  explicit OurSe3Graph(const io::G2oPoseGraph3D& g) {
    T.resize(g.vertices.size());
    for (std::size_t k = 0; k < T.size(); ++k) {
      T[k] = lie::SE3d(lie::SO3d(g.vertices[k].q_wi.normalized()), g.vertices[k].t_wi).inverse();
    }
    for (const io::G2oEdgeSE3& e : g.edges) {
      const lie::SE3d Z(lie::SO3d(e.q_ij.normalized()), e.t_ij);
      problem.add_residual_block(
          solver::RelativePoseResidual<lie::SE3d>{Z.inverse()}, solver::RobustLoss(),
          solver::SqrtInformation<6>{e.sqrt_information_omega_nu()},
          &T[static_cast<std::size_t>(g.index(e.i))], &T[static_cast<std::size_t>(g.index(e.j))]);
    }
    problem.set_constant(&T[0]);
  }
};

struct OurDriftGraph {
  std::vector<lie::Sim3d> S;
  solver::Problem problem;
  explicit OurDriftGraph(const DriftGraph& g) : S(g.initial) {
    for (const DriftGraph::Edge& e : g.edges) {
      problem.add_residual_block(
          solver::RelativePoseResidual<lie::Sim3d>{e.dS_ij}, solver::RobustLoss(), g.edge_weight,
          &S[static_cast<std::size_t>(e.i)], &S[static_cast<std::size_t>(e.j)]);
    }
    for (const DriftGraph::Prior& p : g.priors) {
      solver::CameraCentrePriorResidual<lie::Sim3d> f;
      f.y = p.y;
      problem.add_residual_block(f, solver::RobustLoss(), g.prior_weight,
                                 &S[static_cast<std::size_t>(p.i)]);
    }
  }
};

struct OurBa {
  std::vector<lie::SE3d> poses;
  std::vector<Eigen::Vector3d> points;
  solver::Problem problem;
  explicit OurBa(const BaData& d) : poses(d.poses), points(d.points) {
    const solver::RobustLoss loss =
        d.huber > 0 ? solver::RobustLoss::huber(d.huber) : solver::RobustLoss();
    for (const BaData::Obs& o : d.observations) {
      solver::ReprojectionResidual f;
      f.fx = d.fx;
      f.fy = d.fy;
      f.cx = d.cx;
      f.cy = d.cy;
      f.uv = o.uv;
      problem.add_residual_block(f, loss, 1.0, &poses[static_cast<std::size_t>(o.camera)],
                                 &points[static_cast<std::size_t>(o.point)]);
    }
    for (const int c : d.fixed_cameras) problem.set_constant(&poses[static_cast<std::size_t>(c)]);
  }
};

/// Result of the floor measurement.
struct FactorFloor {
  double median_seconds = 0.0;
  double median_cpu_seconds = 0.0;  ///< process CPU time (std::clock), median of the same reps
  double nnz_factor = 0.0;
  double flops = 0.0;  ///< CHOLMOD's flop count of the numeric factorisation
  int n = 0;
  bool simplicial = false;  ///< the faster factor was the simplicial one (cholmod_floor)
};

/// One bare CHOLMOD numeric factorisation of the symmetric matrix A (upper CSC, stype +1), AMD
/// ordering, the faster of its supernodal and simplicial (LLᵀ) factors: the floor is CHOLMOD at
/// its best on the matrix, whichever kind geodrift's CholmodSolver uses there. The symbolic
/// analyses are done once and not timed; median of `reps` per kind.
template <typename Values>  // std::vector<double> or BlockSparseMatrix::ValueVector
FactorFloor cholmod_floor(int n, const std::vector<int>& col_ptr, const std::vector<int>& row_idx,
                          const Values& values, int reps = 5) {
  cholmod_sparse A{};
  A.nrow = A.ncol = static_cast<size_t>(n);
  A.nzmax = values.size();
  A.p = const_cast<int*>(col_ptr.data());
  A.i = const_cast<int*>(row_idx.data());
  A.x = const_cast<double*>(values.data());
  A.stype = 1;
  A.itype = CHOLMOD_INT;
  A.xtype = CHOLMOD_REAL;
  A.dtype = CHOLMOD_DOUBLE;
  A.sorted = 1;
  A.packed = 1;
  FactorFloor best;
  for (const int kind : {CHOLMOD_SUPERNODAL, CHOLMOD_SIMPLICIAL}) {
    cholmod_common cc;
    cholmod_start(&cc);
    cc.print = 0;
    cc.supernodal = kind;
    cc.final_ll = 1;
    cc.nmethods = 1;
    cc.method[0].ordering = CHOLMOD_AMD;
    cc.postorder = 1;
    cholmod_factor* L = cholmod_analyze(&A, &cc);
    std::vector<double> t, tc;
    for (int r = 0; r < reps; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      const std::clock_t c0 = std::clock();
      cholmod_factorize(&A, L, &cc);
      tc.push_back(static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
      t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(t.begin(), t.end());
    std::sort(tc.begin(), tc.end());
    FactorFloor f;
    f.median_seconds = t[t.size() / 2];
    f.median_cpu_seconds = tc[tc.size() / 2];
    f.nnz_factor = cc.lnz;
    f.flops = cc.fl;
    f.n = n;
    f.simplicial = kind == CHOLMOD_SIMPLICIAL;
    cholmod_free_factor(&L, &cc);
    cholmod_finish(&cc);
    if (best.n == 0 || f.median_cpu_seconds < best.median_cpu_seconds) best = f;
  }
  return best;
}

/// The floor for a finalized problem: H at the current states (plus LM-like damping 1e-4·diag
/// so it is positive definite in every case), all columns (no Schur ordering).
inline FactorFloor cholmod_floor(solver::Problem* problem) {
  problem->finalize(false);
  const solver::BlockStructure& s = problem->structure();
  solver::BlockSparseMatrix H(&s);
  std::vector<double> g(static_cast<std::size_t>(s.num_cols()));
  double cost = 0.0;
  solver::LinearizeTimes times;
  problem->linearize(&H, g.data(), &cost, &times);
  auto& v = H.value_vector();
  for (const int d : s.diagonal_positions()) v[static_cast<std::size_t>(d)] *= 1.0 + 1e-4;
  return cholmod_floor(s.num_cols(), s.col_ptr(), s.row_idx(), v);
}

/// The same H as cholmod_floor(problem), factorised by one of geodrift's linear solvers
/// (analysis excluded, ordering as in LM), median of `reps`. Zeros if the solver cannot analyse
/// the problem.
template <typename Solver>
FactorFloor solver_floor(solver::Problem* problem, int reps = 5) {
  problem->finalize(false);
  const solver::BlockStructure& s = problem->structure();
  FactorFloor f;
  solver::BlockSparseMatrix H(&s);
  std::vector<double> g(static_cast<std::size_t>(s.num_cols()));
  double cost = 0.0;
  solver::LinearizeTimes times;
  problem->linearize(&H, g.data(), &cost, &times);
  auto& v = H.value_vector();
  for (const int d : s.diagonal_positions()) v[static_cast<std::size_t>(d)] *= 1.0 + 1e-4;
  Solver solver;
  if (solver.analyze(s) != solver::LinearSolverStatus::kSuccess) return f;
  std::vector<double> t;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    if (solver.factorize(H) != solver::LinearSolverStatus::kSuccess) return f;
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(t.begin(), t.end());
  f.median_seconds = t[t.size() / 2];
  f.nnz_factor = solver.factor_nnz();
  f.n = s.num_cols();
  return f;
}

/// solver_floor() with geodrift's BlockCholeskySolver; flops = the block kernels' count.
/// Returns zeros when the problem's blocks are not all of size 6 or 7.
inline FactorFloor block_cholesky_floor(solver::Problem* problem, int reps = 5) {
  problem->finalize(false);
  if (solver::BlockCholeskySolver::supported_block_size(problem->structure()) == 0) return {};
  FactorFloor f = solver_floor<solver::BlockCholeskySolver>(problem, reps);
  solver::BlockCholeskySolver bc;
  if (f.median_seconds > 0.0 &&
      bc.analyze(problem->structure()) == solver::LinearSolverStatus::kSuccess)
    f.flops = bc.flops();
  return f;
}

/// The floor for BA: the reduced camera system S = H_cc − H_cp·H_pp⁻¹·H_pc of the data at its
/// start values (Gauss-Newton Jacobians, no robust weights: the pattern and size of S, which is
/// what the factorisation time depends on, are the same), fixed cameras removed.
inline FactorFloor cholmod_floor_reduced_camera_system(const BaData& d) {
  const int nc = static_cast<int>(d.poses.size());
  std::vector<int> col(static_cast<std::size_t>(nc), -1);
  int free = 0;
  for (int c = 0; c < nc; ++c) {
    if (std::find(d.fixed_cameras.begin(), d.fixed_cameras.end(), c) == d.fixed_cameras.end()) {
      col[static_cast<std::size_t>(c)] = free++;
    }
  }
  // Group observations by point.
  std::vector<std::vector<int>> by_point(d.points.size());
  for (std::size_t k = 0; k < d.observations.size(); ++k) {
    by_point[static_cast<std::size_t>(d.observations[k].point)].push_back(static_cast<int>(k));
  }
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  std::vector<std::vector<std::pair<int, Mat6>>> blocks(static_cast<std::size_t>(free));
  auto add = [&](int a, int b, const Mat6& M) {  // a <= b, block column b
    auto& colb = blocks[static_cast<std::size_t>(b)];
    for (auto& e : colb) {
      if (e.first == a) {
        e.second += M;
        return;
      }
    }
    colb.emplace_back(a, M);
  };
  solver::ReprojectionResidual f;
  f.fx = d.fx;
  f.fy = d.fy;
  f.cx = d.cx;
  f.cy = d.cy;
  std::vector<Eigen::Matrix<double, 6, 3>> W;
  std::vector<int> cams;
  for (std::size_t p = 0; p < d.points.size(); ++p) {
    Eigen::Matrix3d V = Eigen::Matrix3d::Zero();
    W.clear();
    cams.clear();
    for (const int k : by_point[p]) {
      const BaData::Obs& o = d.observations[static_cast<std::size_t>(k)];
      f.uv = o.uv;
      Eigen::Vector2d r;
      Eigen::Matrix<double, 2, 6> JT;
      Eigen::Matrix<double, 2, 3> JX;
      if (!f(d.poses[static_cast<std::size_t>(o.camera)], d.points[p], &r, &JT, &JX)) continue;
      V += JX.transpose() * JX;
      const int c = col[static_cast<std::size_t>(o.camera)];
      if (c < 0) continue;
      add(c, c, JT.transpose() * JT);
      W.push_back(JT.transpose() * JX);
      cams.push_back(c);
    }
    const Eigen::Matrix3d Vinv = V.inverse();
    for (std::size_t a = 0; a < cams.size(); ++a) {
      for (std::size_t b = 0; b < cams.size(); ++b) {
        if (cams[a] > cams[b]) continue;
        add(cams[a], cams[b], -(W[a] * Vinv * W[b].transpose()));
      }
    }
  }
  // Scalar upper CSC.
  const int n = 6 * free;
  std::vector<int> col_ptr(static_cast<std::size_t>(n + 1), 0), row_idx;
  std::vector<double> values;
  for (int b = 0; b < free; ++b) {
    auto& colb = blocks[static_cast<std::size_t>(b)];
    std::sort(colb.begin(), colb.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    for (int j = 0; j < 6; ++j) {
      for (const auto& e : colb) {
        for (int i = 0; i < 6; ++i) {
          if (e.first == b && i > j) continue;
          row_idx.push_back(6 * e.first + i);
          values.push_back(e.second(i, j) + (e.first == b && i == j ? 1e-4 * e.second(i, j) : 0.0));
        }
      }
      col_ptr[static_cast<std::size_t>(6 * b + j + 1)] = static_cast<int>(row_idx.size());
    }
  }
  return cholmod_floor(n, col_ptr, row_idx, values);
}

}  // namespace geodrift::bench
