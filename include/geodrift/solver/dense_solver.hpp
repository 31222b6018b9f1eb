#pragma once

/// @file
/// DenseSolver: dense Cholesky (LLᵀ) of H, for tests and tiny problems (O(n³)).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <string>

#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

/// Dense LLᵀ of the full symmetric H (built from its upper triangle). Memory is allocated in
/// analyze(); the first factorize() sizes the factor, later factorize()/solve() do not allocate.
class DenseSolver final : public LinearSolver {
 public:
  LinearSolverStatus analyze(const BlockStructure& s) override {
    n_ = s.num_cols();
    A_.setZero(n_, n_);
    // No pre-sized LLT: Eigen's LLT(Index) leaves its `info` member uninitialised, and moving
    // such an object reads it (UBSan: invalid enum load). compute() sizes it on first use.
    x_.resize(n_);
    row_idx_ = s.row_idx();
    message_.clear();
    return LinearSolverStatus::kSuccess;
  }

  LinearSolverStatus factorize(const BlockSparseMatrix& H) override {
    message_.clear();
    if (H.rows() != n_) {
      message_ = "dense solver: matrix size differs from the analysed one";
      return LinearSolverStatus::kFatal;
    }
    const BlockStructure& s = H.structure();
    const double* v = H.values();
    // Upper triangle from the CSC arrays (the lower part of diagonal blocks is ignored, as
    // CHOLMOD does), mirrored.
    for (int c = 0; c < n_; ++c) {
      for (int p = s.col_ptr()[c]; p < s.col_ptr()[c + 1]; ++p) {
        const int r = row_idx_[static_cast<std::size_t>(p)];
        if (r <= c) A_(r, c) = A_(c, r) = v[p];
      }
    }
    llt_.compute(A_);
    if (llt_.info() != Eigen::Success) {
      message_ = "dense LLT: matrix is not positive definite";
      return LinearSolverStatus::kNotPositiveDefinite;
    }
    return LinearSolverStatus::kSuccess;
  }

  LinearSolverStatus solve(const double* b, double* x) override {
    x_ = Eigen::Map<const Eigen::VectorXd>(b, n_);
    llt_.solveInPlace(x_);
    Eigen::Map<Eigen::VectorXd>(x, n_) = x_;
    return LinearSolverStatus::kSuccess;
  }

  std::string name() const override { return "dense"; }
  double factor_nnz() const override { return 0.5 * double(n_) * double(n_ + 1); }

 private:
  std::vector<int> row_idx_;  ///< scalar row indices of the analysed pattern
  int n_ = 0;
  Eigen::MatrixXd A_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  Eigen::VectorXd x_;
};

}  // namespace geodrift::solver
