#pragma once

/// @file
/// CholmodSolver: supernodal sparse Cholesky of H through CHOLMOD (SuiteSparse). The only
/// geodrift file that includes cholmod.h.

#include <cholmod.h>

#include <string>
#include <vector>

#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

/// RAII, non-copyable owner of one cholmod_common and its factor.
///  - analyze(): fill-reducing ordering = AMD on the BLOCK pattern (one node per parameter block,
///    expanded to scalar columns; cheaper than AMD on the scalar pattern and as good for
///    fixed-size blocks), then CHOLMOD's supernodal symbolic analysis. Runs once per pattern;
///    LevenbergMarquardt calls it again only when the pattern changes.
///  - factorize(): numeric supernodal LLᵀ on a cholmod_sparse VIEW of H's CSC arrays (no copy
///    on our side; CHOLMOD itself forms P·H·Pᵀ internally), with quick_return_if_not_posdef.
///  - solve(): cholmod_solve2 with workspaces kept between calls.
/// CHOLMOD's printing is silenced (print = 0, no error handler); its status maps onto
/// LinearSolverStatus with a message.
class CholmodSolver final : public LinearSolver {
 public:
  enum class Ordering {
    kBlockAmd,  ///< AMD on the block pattern, expanded (default)
    kAmd,       ///< CHOLMOD's AMD on the scalar pattern
  };

  explicit CholmodSolver(Ordering ordering = Ordering::kBlockAmd) : ordering_(ordering) {
    cholmod_start(&cc_);
    cc_.print = 0;
    cc_.error_handler = nullptr;
    cc_.supernodal = CHOLMOD_SUPERNODAL;
    cc_.quick_return_if_not_posdef = 1;
    cc_.nmethods = 1;
    cc_.method[0].ordering = ordering_ == Ordering::kBlockAmd ? CHOLMOD_GIVEN : CHOLMOD_AMD;
    cc_.postorder = 1;
  }
  ~CholmodSolver() override {
    free_factor();
    cholmod_finish(&cc_);
  }

  LinearSolverStatus analyze(const BlockStructure& s) override {
    message_.clear();
    free_factor();
    n_ = s.num_cols();
    row_idx_ = s.row_idx();
    cholmod_sparse A = view(s, nullptr);
    A.xtype = CHOLMOD_PATTERN;
    if (ordering_ == Ordering::kBlockAmd) {
      const int nb = s.num_blocks();
      // Block pattern (upper, with diagonal) as a CHOLMOD pattern matrix.
      cholmod_sparse B{};
      B.nrow = B.ncol = static_cast<size_t>(nb);
      B.nzmax = s.block_rows().size();
      B.p = const_cast<int*>(s.block_col_ptr().data());
      B.i = const_cast<int*>(s.block_rows().data());
      B.stype = 1;
      B.itype = CHOLMOD_INT;
      B.xtype = CHOLMOD_PATTERN;
      B.dtype = CHOLMOD_DOUBLE;
      B.sorted = 1;
      B.packed = 1;
      std::vector<int> block_perm(nb);
      if (nb > 0 && !cholmod_amd(&B, nullptr, 0, block_perm.data(), &cc_)) {
        return fail("cholmod_amd on the block pattern failed");
      }
      perm_.resize(n_);
      int k = 0;
      for (int q = 0; q < nb; ++q) {
        const int b = block_perm[q];
        for (int j = 0; j < s.block_size(b); ++j) perm_[k++] = s.block_col(b) + j;
      }
      L_ = cholmod_analyze_p(&A, perm_.data(), nullptr, 0, &cc_);
    } else {
      L_ = cholmod_analyze(&A, &cc_);
    }
    if (!L_ || cc_.status < CHOLMOD_OK) return fail("cholmod_analyze failed");
    return LinearSolverStatus::kSuccess;
  }

  LinearSolverStatus factorize(const BlockSparseMatrix& H) override {
    message_.clear();
    if (!L_) return fail("factorize() before analyze()");
    if (H.rows() != n_) return fail("matrix size differs from the analysed one");
    cholmod_sparse A = view(H.structure(), H.values());
    cholmod_factorize(&A, L_, &cc_);
    if (cc_.status == CHOLMOD_NOT_POSDEF || (cc_.status >= CHOLMOD_OK && L_->minor < L_->n)) {
      message_ = "CHOLMOD: matrix not positive definite (column " + std::to_string(L_->minor) + ")";
      return LinearSolverStatus::kNotPositiveDefinite;
    }
    if (cc_.status < CHOLMOD_OK) return fail("cholmod_factorize failed");
    return LinearSolverStatus::kSuccess;
  }

  LinearSolverStatus solve(const double* b, double* x) override {
    message_.clear();
    cholmod_dense B{};
    B.nrow = static_cast<size_t>(n_);
    B.ncol = 1;
    B.nzmax = B.nrow;
    B.d = B.nrow;
    B.x = const_cast<double*>(b);
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, L_, &B, nullptr, &X_, nullptr, &Y_, &E_, &cc_) ||
        cc_.status < CHOLMOD_OK) {
      return fail("cholmod_solve2 failed");
    }
    const double* xs = static_cast<const double*>(X_->x);
    for (int i = 0; i < n_; ++i) x[i] = xs[i];
    return LinearSolverStatus::kSuccess;
  }

  std::string name() const override { return "cholmod"; }
  double factor_nnz() const override { return L_ ? static_cast<double>(cc_.lnz) : 0.0; }
  /// Whether the factor is supernodal (always after analyze()).
  bool is_supernodal() const { return L_ && L_->is_super; }

 private:
  // The analysed pattern's scalar CSC (row indices from analyze()) with `values`.
  cholmod_sparse view(const BlockStructure& s, const double* values) {
    cholmod_sparse A{};
    A.nrow = A.ncol = static_cast<size_t>(s.num_cols());
    A.nzmax = static_cast<size_t>(s.num_values());
    A.p = const_cast<int*>(s.col_ptr().data());
    A.i = row_idx_.data();
    A.x = const_cast<double*>(values);
    A.stype = 1;  // upper triangle used; lower entries of diagonal blocks ignored
    A.itype = CHOLMOD_INT;
    A.xtype = CHOLMOD_REAL;
    A.dtype = CHOLMOD_DOUBLE;
    A.sorted = 1;
    A.packed = 1;
    return A;
  }

  LinearSolverStatus fail(const std::string& what) {
    message_ = "CHOLMOD: " + what + " (status " + std::to_string(cc_.status) + ")";
    return LinearSolverStatus::kFatal;
  }

  void free_factor() {
    if (L_) cholmod_free_factor(&L_, &cc_);
    if (X_) cholmod_free_dense(&X_, &cc_);
    if (Y_) cholmod_free_dense(&Y_, &cc_);
    if (E_) cholmod_free_dense(&E_, &cc_);
  }

  Ordering ordering_;
  cholmod_common cc_{};
  cholmod_factor* L_ = nullptr;
  cholmod_dense* X_ = nullptr;
  cholmod_dense* Y_ = nullptr;
  cholmod_dense* E_ = nullptr;
  std::vector<int> perm_;
  std::vector<int> row_idx_;  ///< scalar row indices of the analysed pattern
  int n_ = 0;
};

}  // namespace geodrift::solver
