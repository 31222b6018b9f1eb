#pragma once

/// @file
/// BlockStructure: the sparsity pattern of the normal equations H = JᵀWJ, built once.
///
/// ## Layout (upper-triangle CSC, whole blocks)
///
/// H is made of blocks H_ab (size(a) x size(b)) between free parameter blocks a, b. Only block
/// columns b with row blocks a ≤ b are stored (the upper block triangle), in compressed sparse
/// column form over SCALAR columns, as CHOLMOD reads it (stype = +1: upper part used, the lower
/// part of diagonal blocks is stored too but ignored by CHOLMOD). Every scalar column of block
/// column b has the same row-block list R(b) = {a ≤ b : H_ab ≠ 0} (ascending, ending with b),
/// so its height is h_b = Σ_{a∈R(b)} size(a), and each block H_ab is a column-major dense
/// block inside `values` with outer stride h_b:
///
///     H_ab(i, j) = values[block_offset(a, b) + j·h_b + i]
///     block_offset(a, b) = base_b + Σ_{a'∈R(b), a'<a} size(a'),   base_b = col_ptr[col(b)].
///
/// ### Worked example
/// Three blocks: x0 (size 2), x1 (size 3), x2 (size 2); residuals couple (x0,x1) and (x0,x2).
/// Scalar columns: x0 → 0..1, x1 → 2..4, x2 → 5..6 (7 columns).
/// R(0) = {0}, h_0 = 2;  R(1) = {0, 1}, h_1 = 5;  R(2) = {0, 2}, h_2 = 4.
///
///     col      : 0    1    2    3    4    5    6
///     col_ptr  : 0    2    4    9    14   19   23   27
///     rows of col 0,1 : 0 1             (H_00, 2x2, offset 0, stride 2)
///     rows of col 2,3,4: 0 1 | 2 3 4    (H_01 at offset 4, H_11 at offset 6, stride 5)
///     rows of col 5,6  : 0 1 | 5 6      (H_02 at offset 19, H_22 at offset 21, stride 4)
///
/// so H_01(1, 2) = values[4 + 2·5 + 1] = values[15]. Each residual × parameter pair records
/// block_offset() and the stride once (Problem::finalize); iterations only zero `values` and
/// add JₐᵀJ_b at those offsets.

#include <algorithm>
#include <climits>
#include <cstdint>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::solver {

class BlockStructure {
 public:
  BlockStructure() = default;

  /// Builds the pattern.
  /// @param block_sizes size of each free block, in column order.
  /// @param couplings   pairs (a, b) of blocks that share a residual (any order, duplicates and
  ///                    a == b allowed); diagonal blocks are always present.
  /// @param num_eliminated the last `num_eliminated` blocks are the Schur-eliminated ones (BA
  ///                    points); 0 when no Schur ordering was requested.
  /// @throws InvalidArgument if a block size is ≤ 0, an index is out of range, or H would have
  ///         more than INT_MAX stored values (CHOLMOD's int interface).
  void build(const std::vector<int>& block_sizes, std::vector<std::pair<int, int>> couplings,
             int num_eliminated = 0) {
    const int nb = static_cast<int>(block_sizes.size());
    GEODRIFT_CHECK(num_eliminated >= 0 && num_eliminated <= nb,
                   "num_eliminated " << num_eliminated << " outside [0, " << nb << "]");
    size_ = block_sizes;
    num_eliminated_ = num_eliminated;
    col_.assign(nb + 1, 0);
    for (int b = 0; b < nb; ++b) {
      GEODRIFT_CHECK(size_[b] > 0, "block " << b << " has size " << size_[b]);
      col_[b + 1] = col_[b] + size_[b];
    }
    // Row-block lists per block column (upper triangle: a < b) + the diagonal.
    for (auto& c : couplings) {
      GEODRIFT_CHECK(c.first >= 0 && c.first < nb && c.second >= 0 && c.second < nb,
                     "coupling (" << c.first << ", " << c.second << ") outside [0, " << nb << ")");
      if (c.first > c.second) std::swap(c.first, c.second);
    }
    // Bucket the row blocks by column (counting sort), then sort and deduplicate each column's
    // short list: O(couplings + Σ r log r) instead of one global pair sort (BA windows build a
    // fresh pattern per window, this is part of their per-window cost).
    std::vector<int> cnt(nb + 1, 0);
    for (const auto& c : couplings) ++cnt[c.second + 1];
    for (int b = 0; b < nb; ++b) cnt[b + 1] += cnt[b] + 1;  // + the diagonal block
    std::vector<int> rows(static_cast<std::size_t>(cnt[nb]));
    std::vector<int> fill(cnt.begin(), cnt.end() - 1);
    for (int b = 0; b < nb; ++b) rows[fill[b]++] = b;
    for (const auto& c : couplings) rows[fill[c.second]++] = c.first;
    bcol_ptr_.assign(nb + 1, 0);
    brow_.clear();
    brow_.reserve(rows.size());
    for (int b = 0; b < nb; ++b) {
      const auto first = rows.begin() + cnt[b], last = rows.begin() + cnt[b + 1];
      std::sort(first, last);
      brow_.insert(brow_.end(), first, std::unique(first, last));
      bcol_ptr_[b + 1] = static_cast<int>(brow_.size());
    }

    // Scalar CSC.
    height_.assign(nb, 0);
    boff_.assign(brow_.size(), 0);
    std::int64_t nnz = 0;
    for (int b = 0; b < nb; ++b) {
      int h = 0;
      for (int k = bcol_ptr_[b]; k < bcol_ptr_[b + 1]; ++k) h += size_[brow_[k]];
      height_[b] = h;
      nnz += static_cast<std::int64_t>(h) * size_[b];
    }
    GEODRIFT_CHECK(nnz <= INT_MAX, "H would hold " << nnz << " values (> INT_MAX)");
    col_ptr_.assign(col_[nb] + 1, 0);
    diag_.resize(col_[nb]);
    int p = 0;
    for (int b = 0; b < nb; ++b) {
      int pos = 0;
      for (int k = bcol_ptr_[b]; k < bcol_ptr_[b + 1]; ++k) {
        boff_[k] = p + pos;
        pos += size_[brow_[k]];
      }
      for (int j = 0; j < size_[b]; ++j) {
        col_ptr_[col_[b] + j] = p;
        p += height_[b];
        // diagonal entry (j, j) of H_bb: last row block is b itself.
        diag_[col_[b] + j] = boff_[bcol_ptr_[b + 1] - 1] + j * height_[b] + j;
      }
    }
    col_ptr_[col_[nb]] = p;
    GEODRIFT_ASSERT(p == nnz);
  }

  int num_blocks() const { return static_cast<int>(size_.size()); }
  int num_cols() const { return col_.empty() ? 0 : col_.back(); }
  int num_values() const { return col_ptr_.empty() ? 0 : col_ptr_.back(); }
  /// Blocks [num_blocks() - num_eliminated(), num_blocks()) are eliminated by Schur.
  int num_eliminated() const { return num_eliminated_; }
  int block_size(int b) const { return size_[b]; }
  /// First scalar column of block b.
  int block_col(int b) const { return col_[b]; }
  /// Height h_b of every scalar column of block column b (the outer stride of its blocks).
  int column_height(int b) const { return height_[b]; }

  /// Block CSC: row blocks of block column b are block_rows()[block_col_ptr()[b] ..
  /// block_col_ptr()[b+1]), ascending, the last one is b; block_offsets() holds each block's
  /// start in `values`.
  const std::vector<int>& block_col_ptr() const { return bcol_ptr_; }
  const std::vector<int>& block_rows() const { return brow_; }
  const std::vector<int>& block_offsets() const { return boff_; }

  /// Offset of H_ab (a ≤ b) in values, or -1 if the block is not in the pattern.
  /// O(log |R(b)|); meant for finalize-time use.
  int block_offset(int a, int b) const {
    if (a > b) return -1;
    const auto first = brow_.begin() + bcol_ptr_[b];
    const auto last = brow_.begin() + bcol_ptr_[b + 1];
    const auto it = std::lower_bound(first, last, a);
    if (it == last || *it != a) return -1;
    return boff_[it - brow_.begin()];
  }

  /// Scalar CSC column pointers (size num_cols()+1), as CHOLMOD reads them.
  const std::vector<int>& col_ptr() const { return col_ptr_; }
  /// Scalar CSC row indices (size num_values()), built on each call, O(num_values()): only the
  /// scalar solvers need them (CholmodSolver and DenseSolver keep a copy from analyze()), so the
  /// block solvers' problems do not carry one int per stored value (14 MB at 10k Sim(3) keyframes).
  std::vector<int> row_idx() const {
    std::vector<int> rows(static_cast<std::size_t>(num_values()));
    int p = 0;
    for (int b = 0; b < num_blocks(); ++b)
      for (int j = 0; j < size_[b]; ++j)
        for (int k = bcol_ptr_[b]; k < bcol_ptr_[b + 1]; ++k) {
          const int a = brow_[k];
          for (int i = 0; i < size_[a]; ++i) rows[static_cast<std::size_t>(p++)] = col_[a] + i;
        }
    GEODRIFT_ASSERT(p == num_values());
    return rows;
  }
  /// Position in values of each diagonal entry H(c, c).
  const std::vector<int>& diagonal_positions() const { return diag_; }

  /// The block-level pattern (sizes, block CSC, eliminated count): two structures with equal
  /// patterns have identical scalar layouts, so a symbolic factorisation can be reused.
  struct Pattern {
    std::vector<int> sizes, block_col_ptr, block_rows;
    int num_eliminated = 0;
    bool operator==(const Pattern& o) const {
      return sizes == o.sizes && block_col_ptr == o.block_col_ptr && block_rows == o.block_rows &&
             num_eliminated == o.num_eliminated;
    }
  };
  Pattern pattern() const { return Pattern{size_, bcol_ptr_, brow_, num_eliminated_}; }
  bool same_pattern(const Pattern& p) const {
    return size_ == p.sizes && bcol_ptr_ == p.block_col_ptr && brow_ == p.block_rows &&
           num_eliminated_ == p.num_eliminated;
  }

 private:
  std::vector<int> size_, col_, height_;
  std::vector<int> bcol_ptr_, brow_, boff_;
  std::vector<int> col_ptr_, diag_;
  int num_eliminated_ = 0;
};

}  // namespace geodrift::solver
