#pragma once

/// @file
/// LinearSolver: the interface LevenbergMarquardt uses to solve H·x = b for a symmetric
/// positive definite block-sparse H (the damped normal equations).

#include <string>

#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/block_structure.hpp"

namespace geodrift::solver {

/// Outcome of a linear-solver step. kNotPositiveDefinite is a numerical outcome (LM rejects the
/// step and raises λ); kFatal ends the solve (out of memory, invalid input, ...).
enum class LinearSolverStatus { kSuccess, kNotPositiveDefinite, kFatal };

inline const char* to_string(LinearSolverStatus s) {
  switch (s) {
    case LinearSolverStatus::kSuccess:
      return "success";
    case LinearSolverStatus::kNotPositiveDefinite:
      return "not positive definite";
    case LinearSolverStatus::kFatal:
      return "fatal";
  }
  return "?";
}

/// analyze() once per pattern, factorize() every iteration (values only), solve() per step.
/// One virtual call per phase and iteration (never per residual).
class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  LinearSolver() = default;
  LinearSolver(const LinearSolver&) = delete;
  LinearSolver& operator=(const LinearSolver&) = delete;

  /// Symbolic analysis of `s` (ordering, memory); values are not read.
  virtual LinearSolverStatus analyze(const BlockStructure& s) = 0;
  /// Numeric factorisation of H (pattern = the analysed one).
  virtual LinearSolverStatus factorize(const BlockSparseMatrix& H) = 0;
  /// x = H⁻¹·b with the last factorisation; b and x have H.rows() entries (may not alias).
  virtual LinearSolverStatus solve(const double* b, double* x) = 0;
  /// factorize(H), then x = H⁻¹·b (x unspecified unless kSuccess). Solvers that can fold the
  /// forward substitution into the factorisation, while each column of the factor is still in
  /// cache, override it (BlockCholeskySolver: one pass over the factor less per iteration).
  virtual LinearSolverStatus factorize_and_solve(const BlockSparseMatrix& H, const double* b,
                                                 double* x) {
    const LinearSolverStatus st = factorize(H);
    return st == LinearSolverStatus::kSuccess ? solve(b, x) : st;
  }
  /// factorize_and_solve() that may keep the factor in H's own values instead of a matrix of
  /// its own (*overwritten = true: H no longer holds H, and must stay untouched until the last
  /// solve() with this factorisation); otherwise *overwritten = false and H is unchanged. LM
  /// uses it and writes H again before it needs H after such a call (Options::in_place_factor).
  /// Default: factorize_and_solve(), never in place (BlockCholeskySolver overrides it).
  virtual LinearSolverStatus factorize_and_solve_in_place(BlockSparseMatrix* H, const double* b,
                                                          double* x, bool* overwritten) {
    *overwritten = false;
    return factorize_and_solve(*H, b, x);
  }
  /// Name for reports ("cholmod", "schur+cholmod", "dense").
  virtual std::string name() const = 0;
  /// Detail of the last non-success status (empty otherwise).
  const std::string& message() const { return message_; }
  /// Nonzeros of the factor (0 if unknown), for reports.
  virtual double factor_nnz() const { return 0.0; }

 protected:
  std::string message_;
};

}  // namespace geodrift::solver
