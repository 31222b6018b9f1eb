#pragma once

/// @file
/// CholmodSolver: supernodal sparse Cholesky of H through CHOLMOD (SuiteSparse). The only
/// geodrift file that includes cholmod.h.

#include <cholmod.h>

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

/// RAII, non-copyable owner of one cholmod_common and its factor.
///  - analyze(): fill-reducing ordering = AMD on the BLOCK pattern (one node per parameter block,
///    expanded to scalar columns; cheaper than AMD on the scalar pattern and as good for
///    fixed-size blocks), then CHOLMOD's supernodal symbolic analysis. Runs once per pattern;
///    LevenbergMarquardt calls it again only when the pattern changes.
///  - factorize(), default ordering: H's upper triangle is gathered into the lower triangle of
///    P·H·Pᵀ (a CSC whose pattern and gather map analyze() built), which CHOLMOD factorises in
///    its natural order, i.e. as is. Given H itself with a permutation, cholmod_factorize forms
///    P·H·Pᵀ in a matrix it allocates and frees on every call (cholmod_ptranspose), which for
///    these sizes (tens to hundreds of MB) comes from fresh pages each time; the gather writes
///    into memory kept between calls. For that, analyze() combines the block AMD ordering with
///    a postorder of its block elimination tree (what CHOLMOD's own postordering would do, so
///    the supernodes are the same) and analyses P·H·Pᵀ with the natural ordering. With
///    quick_return_if_not_posdef.
///  - solve(): b permuted, cholmod_solve2 (workspaces kept between calls), x permuted back.
///  - Ordering::kAmd (CHOLMOD's AMD on the scalar pattern): a cholmod_sparse VIEW of H's CSC
///    arrays, CHOLMOD permutes internally.
///  - Factorization::kAuto (default): CHOLMOD's own rule, a simplicial (column-by-column)
///    factor where the analysis counts fewer than `supernodal_switch` (40) flops per nonzero of
///    L, else supernodal. Small thin systems (a sliding window's Sim(3) chain with scalar local
///    scale offsets: ~60 keyframes, 480 columns) are simplicial: Debian's supernodal numeric
///    factorisation enters OpenMP regions per supernode, ~220 futex calls per factorisation
///    even with OMP_NUM_THREADS=1, and took 0.57 ms per LM iteration there against 0.08 ms for
///    the same window without the offsets on the block Cholesky. Simplicial factors are LLᵀ
///    (final_ll), so a non-positive pivot is reported as for the supernodal factor.
/// CHOLMOD's printing is silenced (print = 0, no error handler); its status maps onto
/// LinearSolverStatus with a message.
class CholmodSolver final : public LinearSolver {
 public:
  enum class Ordering {
    kBlockAmd,  ///< AMD on the block pattern, expanded (default)
    kAmd,       ///< CHOLMOD's AMD on the scalar pattern
  };
  /// Supernodal or simplicial factor (class comment).
  enum class Factorization {
    kAuto,        ///< CHOLMOD's choice by flops per nonzero of L (default)
    kSupernodal,  ///< always supernodal (dense BLAS kernels on the supernodes)
    kSimplicial,  ///< always simplicial (column by column, no BLAS)
  };

  explicit CholmodSolver(Ordering ordering = Ordering::kBlockAmd,
                         Factorization factorization = Factorization::kAuto)
      : ordering_(ordering) {
    cholmod_start(&cc_);
    cc_.print = 0;
    cc_.error_handler = nullptr;
    cc_.supernodal = factorization == Factorization::kAuto         ? CHOLMOD_AUTO
                     : factorization == Factorization::kSupernodal ? CHOLMOD_SUPERNODAL
                                                                   : CHOLMOD_SIMPLICIAL;
    cc_.final_ll = 1;
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
    if (ordering_ == Ordering::kBlockAmd) {
      const int nb = s.num_blocks();
      // Block pattern (upper, with diagonal) as a CHOLMOD pattern matrix.
      cholmod_sparse B = csc(nb, s.block_rows().size(), s.block_col_ptr().data(),
                             s.block_rows().data(), nullptr, 1);
      std::vector<int> block_perm(nb);
      if (nb > 0 && !cholmod_amd(&B, nullptr, 0, block_perm.data(), &cc_)) {
        return fail("cholmod_amd on the block pattern failed");
      }
      postorder_blocks(s, &block_perm);
      build_permuted_lower(s, block_perm);
      cholmod_sparse P = permuted_view();
      P.xtype = CHOLMOD_PATTERN;
      // Natural order, no postorder: L->ordering stays CHOLMOD_NATURAL, so cholmod_factorize
      // takes P as it is (see the class comment).
      cc_.method[0].ordering = CHOLMOD_NATURAL;
      cc_.postorder = 0;
      L_ = cholmod_analyze(&P, &cc_);
      if (L_ && L_->ordering != CHOLMOD_NATURAL) return fail("analysis is not in natural order");
    } else {
      cholmod_sparse A = view(s, nullptr);  // pattern only
      L_ = cholmod_analyze(&A, &cc_);
    }
    if (!L_ || cc_.status < CHOLMOD_OK) return fail("cholmod_analyze failed");
    return LinearSolverStatus::kSuccess;
  }

  LinearSolverStatus factorize(const BlockSparseMatrix& H) override {
    message_.clear();
    if (!L_) return fail("factorize() before analyze()");
    if (H.rows() != n_) return fail("matrix size differs from the analysed one");
    if (permuted()) {
      const double* hv = H.values();
      const int* src = gather_.data();
      double* dst = px_.data();
      const std::size_t nnz = gather_.size();
      for (std::size_t k = 0; k < nnz; ++k) dst[k] = hv[src[k]];
      cholmod_sparse P = permuted_view();
      cholmod_factorize(&P, L_, &cc_);
    } else {
      cholmod_sparse A = view(H.structure(), H.values());
      cholmod_factorize(&A, L_, &cc_);
    }
    if (cc_.status == CHOLMOD_NOT_POSDEF || (cc_.status >= CHOLMOD_OK && L_->minor < L_->n)) {
      // L_->minor counts columns of P·H·Pᵀ on the permuted path: name H's column.
      const std::size_t minor = L_->minor;
      const long col = permuted() && minor < perm_.size() ? perm_[minor] : static_cast<long>(minor);
      message_ = "CHOLMOD: matrix not positive definite (column " + std::to_string(col) + ")";
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
    if (permuted()) {  // P·H·Pᵀ·(P·x) = P·b
      for (int i = 0; i < n_; ++i) pb_[i] = b[perm_[i]];
      B.x = pb_.data();
    } else {
      B.x = const_cast<double*>(b);
    }
    B.xtype = CHOLMOD_REAL;
    B.dtype = CHOLMOD_DOUBLE;
    if (!cholmod_solve2(CHOLMOD_A, L_, &B, nullptr, &X_, nullptr, &Y_, &E_, &cc_) ||
        cc_.status < CHOLMOD_OK) {
      return fail("cholmod_solve2 failed");
    }
    const double* xs = static_cast<const double*>(X_->x);
    if (permuted()) {
      for (int i = 0; i < n_; ++i) x[perm_[i]] = xs[i];
    } else {
      for (int i = 0; i < n_; ++i) x[i] = xs[i];
    }
    return LinearSolverStatus::kSuccess;
  }

  std::string name() const override { return "cholmod"; }
  double factor_nnz() const override { return L_ ? static_cast<double>(cc_.lnz) : 0.0; }
  /// Whether the factor is supernodal (after analyze(); see Factorization).
  bool is_supernodal() const { return L_ && L_->is_super; }

 private:
  /// A cholmod_sparse header over packed, sorted CSC arrays we own (CHOLMOD never frees them).
  static cholmod_sparse csc(int n, std::size_t nnz, const int* p, const int* i, const double* x,
                            int stype) {
    cholmod_sparse A{};
    A.nrow = A.ncol = static_cast<size_t>(n);
    A.nzmax = nnz;
    A.p = const_cast<int*>(p);
    A.i = const_cast<int*>(i);
    A.x = const_cast<double*>(x);
    A.stype = stype;
    A.itype = CHOLMOD_INT;
    A.xtype = x ? CHOLMOD_REAL : CHOLMOD_PATTERN;
    A.dtype = CHOLMOD_DOUBLE;
    A.sorted = 1;
    A.packed = 1;
    return A;
  }

  // The analysed pattern's scalar CSC (row indices from analyze()) with `values`; the upper
  // triangle is used, lower entries of diagonal blocks are ignored.
  cholmod_sparse view(const BlockStructure& s, const double* values) {
    return csc(s.num_cols(), static_cast<std::size_t>(s.num_values()), s.col_ptr().data(),
               row_idx_.data(), values, 1);
  }

  bool permuted() const { return ordering_ == Ordering::kBlockAmd; }

  /// Replaces the block order `order` (position -> block) by a postorder of the elimination
  /// tree of the block pattern in that order, children before parents (J. W. H. Liu, "The role
  /// of elimination trees in sparse factorization", SIAM J. Matrix Anal. Appl. 11(1), 1990:
  /// the tree by path-compressed ancestor walks, then a depth-first postorder). Same fill;
  /// every chain of the tree becomes consecutive columns, which CHOLMOD merges into supernodes.
  static void postorder_blocks(const BlockStructure& s, std::vector<int>* order) {
    const int nb = s.num_blocks();
    std::vector<int> pos(static_cast<std::size_t>(nb));
    for (int q = 0; q < nb; ++q) pos[(*order)[q]] = q;
    // Neighbours of each position at smaller positions (the upper pattern in the new order).
    std::vector<int> cnt(static_cast<std::size_t>(nb) + 1, 0);
    const auto& bcp = s.block_col_ptr();
    const auto& brow = s.block_rows();
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        if (brow[k] != b) ++cnt[std::max(pos[brow[k]], pos[b]) + 1];
    for (int q = 0; q < nb; ++q) cnt[q + 1] += cnt[q];
    std::vector<int> nbr(static_cast<std::size_t>(cnt[nb])), fill(cnt.begin(), cnt.end() - 1);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        if (brow[k] != b) {
          const int i = pos[brow[k]], j = pos[b];
          nbr[fill[std::max(i, j)]++] = std::min(i, j);
        }
    std::vector<int> parent(static_cast<std::size_t>(nb), -1), ancestor(parent);
    for (int j = 0; j < nb; ++j)
      for (int p = cnt[j]; p < cnt[j + 1]; ++p)
        for (int i = nbr[p]; i != -1 && i < j;) {
          const int next = ancestor[i];
          ancestor[i] = j;
          if (next == -1) parent[i] = j;
          i = next;
        }
    // Children lists (ascending), then an iterative depth-first postorder from each root.
    std::vector<int> head(static_cast<std::size_t>(nb), -1), next(head), stack;
    for (int j = nb - 1; j >= 0; --j)
      if (parent[j] >= 0) {
        next[j] = head[parent[j]];
        head[parent[j]] = j;
      }
    std::vector<int> post;
    post.reserve(static_cast<std::size_t>(nb));
    for (int r = 0; r < nb; ++r) {
      if (parent[r] != -1) continue;
      stack.push_back(r);
      while (!stack.empty()) {
        const int v = stack.back();
        if (head[v] >= 0) {  // descend into the next unvisited child
          const int c = head[v];
          head[v] = next[c];
          stack.push_back(c);
        } else {
          post.push_back(v);
          stack.pop_back();
        }
      }
    }
    std::vector<int> out(static_cast<std::size_t>(nb));
    for (int q = 0; q < nb; ++q) out[q] = (*order)[post[q]];
    *order = std::move(out);
  }

  /// perm_ (the block order `order`, position -> block, expanded to scalar columns), the
  /// lower-triangular CSC of P·H·Pᵀ for that P, rows ascending, and gather_: for each of its
  /// entries, the index of the same entry of H's upper triangle in H's value array. Built block by
  /// block: each upper block of H lands, whole or transposed, below the diagonal of its new block
  /// column, and the blocks of one new column are visited in ascending new block row.
  void build_permuted_lower(const BlockStructure& s, const std::vector<int>& order) {
    const int nb = s.num_blocks();
    std::vector<int> pos(static_cast<std::size_t>(nb)), start(static_cast<std::size_t>(nb) + 1, 0);
    perm_.resize(static_cast<std::size_t>(n_));
    for (int q = 0; q < nb; ++q) {
      const int b = order[q];
      pos[b] = q;
      start[q + 1] = start[q] + s.block_size(b);
      for (int j = 0; j < s.block_size(b); ++j) perm_[start[q] + j] = s.block_col(b) + j;
    }
    const auto& bcp = s.block_col_ptr();
    const auto& brow = s.block_rows();
    const auto& boff = s.block_offsets();
    struct Placed {
      int row_pos;  ///< new block row I (≥ the column's J)
      int k;        ///< index of the upper block (a, b) of H in the block CSC
      int b;        ///< its block column in H
    };
    std::vector<int> bucket(static_cast<std::size_t>(nb) + 1, 0);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) ++bucket[std::min(pos[brow[k]], pos[b]) + 1];
    for (int q = 0; q < nb; ++q) bucket[q + 1] += bucket[q];
    std::vector<Placed> placed(static_cast<std::size_t>(bucket[nb]));
    std::vector<int> fill(bucket.begin(), bucket.end() - 1);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) {
        const int qa = pos[brow[k]], qb = pos[b];
        placed[fill[std::min(qa, qb)]++] = {std::max(qa, qb), k, b};
      }
    pp_.assign(static_cast<std::size_t>(n_) + 1, 0);
    pi_.clear();
    gather_.clear();
    pi_.reserve(static_cast<std::size_t>(s.num_values()));
    gather_.reserve(static_cast<std::size_t>(s.num_values()));
    for (int J = 0; J < nb; ++J) {
      const auto first = placed.begin() + bucket[J], last = placed.begin() + bucket[J + 1];
      std::sort(first, last,
                [](const Placed& x, const Placed& y) { return x.row_pos < y.row_pos; });
      const int wJ = start[J + 1] - start[J];
      for (int t = 0; t < wJ; ++t) {  // scalar column start[J] + t
        for (auto it = first; it != last; ++it) {
          const int a = brow[it->k], b = it->b, stride = s.column_height(b), off = boff[it->k];
          const int rows = start[it->row_pos + 1] - start[it->row_pos];
          if (a == b) {  // diagonal block: its upper entries (t, u), u ≥ t, become rows u
            for (int u = t; u < rows; ++u) {
              pi_.push_back(start[J] + u);
              gather_.push_back(off + u * stride + t);
            }
          } else if (pos[a] > pos[b]) {  // stays below the diagonal: column t of the block
            for (int r = 0; r < rows; ++r) {
              pi_.push_back(start[it->row_pos] + r);
              gather_.push_back(off + t * stride + r);
            }
          } else {  // transposed: row t of the block becomes the column
            for (int c = 0; c < rows; ++c) {
              pi_.push_back(start[it->row_pos] + c);
              gather_.push_back(off + c * stride + t);
            }
          }
        }
        pp_[start[J] + t + 1] = static_cast<int>(pi_.size());
      }
    }
    px_.assign(pi_.size(), 0.0);
    pb_.assign(static_cast<std::size_t>(n_), 0.0);
  }

  /// The lower triangle of P·H·Pᵀ (values as last gathered).
  cholmod_sparse permuted_view() {
    return csc(n_, px_.size(), pp_.data(), pi_.data(), px_.data(), -1);
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
  std::vector<int> perm_;     ///< new position -> H column (kBlockAmd)
  std::vector<int> row_idx_;  ///< scalar row indices of the analysed pattern
  std::vector<int> pp_, pi_;  ///< CSC of the lower triangle of P·H·Pᵀ (kBlockAmd)
  std::vector<int> gather_;   ///< its entries' indices in H's value array
  std::vector<double> px_;    ///< its values, gathered by factorize()
  std::vector<double> pb_;    ///< P·b in solve()
  int n_ = 0;
};

}  // namespace geodrift::solver
