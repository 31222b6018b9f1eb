#pragma once

/// @file
/// BlockCholeskySolver: sparse Cholesky LLᵀ of H on its BLOCK pattern with fixed-size dense
/// kernels, for problems whose free parameter blocks all have the same size B ∈ {6, 7} (SE(3) /
/// Sim(3) pose graphs).
///
/// Why. On chain-shaped graphs (odometry + a few neighbours, the monocular-drift Sim(3) graph)
/// the factor has no fill beyond a narrow block band and CHOLMOD's supernodes are tiny, so its
/// per-supernode bookkeeping and BLAS calls on 7×7…42×42 panels dominate (≈ 1 GFlop/s). Here
/// every operation is a B×B product with compile-time sizes (detail/block_kernels.hpp: Eigen
/// fixed-size kernels, or AVX2 + FMA ones chosen at run time; no BLAS call, no index arithmetic
/// inside a block).
///
/// Algorithm (works on any block pattern, not only bands).
///  - analyze(): ordering of the block graph = the natural order if it has no fill, else the
///    better (fewer factorisation flops) of the natural order and AMD (Eigen's AMDOrdering on
///    the block pattern); block elimination tree and column structures of L by the usual
///    symbolic Cholesky (struct(L_j) = adj⁺(j) ∪ ⋃_{children c} struct(L_c) \ {c}); for every
///    stored block of H its slot in L (and whether it lands transposed). Runs once per pattern.
///  - factorize(): left-looking block Cholesky (column j gathers L_ij −= L_ik·L_jkᵀ from the
///    columns k whose next row is j, linked lists as in CSparse's cs_chol, T. Davis, "Direct
///    Methods for Sparse Linear Systems", SIAM 2006, ch. 4), then L_jj = chol(H_jj − …) and
///    L_ij ← L_ij·L_jj⁻ᵀ with the explicit inverse of the B×B triangle (cholesky_inverse()).
///    A diagonal block that is not positive definite (or not finite) returns
///    kNotPositiveDefinite (LM rejects the step), never throws. No allocation.
///  - solve(): block forward / backward substitution: y −= L_ij·x and t −= L_ijᵀ·y by the same
///    kernels, the diagonal triangles by substitution (not the products with their inverses:
///    detail::lower_solve). factorize_and_solve() does the forward half inside factorize().
///  - In place (factorize_and_solve_in_place(), what LM uses): when the order is the natural one
///    and has no fill, L's block pattern is H's own, and the factor is written over H's values
///    instead of a matrix of its own: block column i of H's upper storage becomes block row i
///    of L, computed row by row (up-looking; BlockFactor::factorize_in_place_with). No memory for
///    L (137 MB at 50k Sim(3) keyframes, whose first touch cost more than the factorisation on
///    the project's VMs: round 14 of BENCHMARKS.md's history, `git show 3d5878d:BENCHMARKS.md`)
///    and no copy of H into it.

#include <Eigen/Core>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>
#include <algorithm>
#include <limits>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "geodrift/solver/detail/block_kernels.hpp"
#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

/// LinearSolverType::kAuto (and the Schur path's reduced camera system) use the block Cholesky
/// when L has at most this many blocks per block column on average. Measured (BENCHMARKS.md): the
/// block Cholesky is faster than CHOLMOD on the drift graph (7 blocks per column) and on all four
/// g2o graphs (parking-garage 7, cubicle 15, torus3D 17, sphere2500 21); beyond that CHOLMOD's
/// dense supernodes (BLAS-3) are expected to win, so larger fill goes to CHOLMOD.
inline constexpr double kAutoMaxBlocksPerColumn = 24.0;

namespace detail {

/// Symbolic block factor shared by the fixed-size kernels.
struct BlockSymbolic {
  int nb = 0;                  ///< block columns
  std::vector<int> perm;       ///< new position -> original block
  std::vector<int> inv;        ///< original block -> new position
  std::vector<int> col_ptr;    ///< L block CSC (lower, first row of column j is j)
  std::vector<int> row;        ///< row blocks (new numbering), ascending per column
  std::vector<int> src_slot;   ///< per stored H block (BlockStructure order): its slot in L
  std::vector<char> src_tr;    ///< ... and whether it is stored transposed there
  std::vector<char> src_diag;  ///< ... and whether it is a diagonal block
  /// H blocks landing in L's block column j: src_list[src_ptr[j] .. src_ptr[j+1]) (indices
  /// into the BlockStructure order), so factorize() loads each column just before using it.
  std::vector<int> src_ptr, src_list;
  std::vector<int> src_stride;  ///< per stored H block: its outer stride (column height)
  std::vector<char> fill_slot;  ///< per slot of L: 1 if no block of H lands there (fill-in)
  double flops = 0.0;           ///< factorisation flops (B×B GEMM = 2B³)
  int max_row_blocks = 0;       ///< most blocks in one block row of L
  /// The natural order without fill: L's block pattern is H's, so the factor can overwrite H
  /// (BlockFactor::factorize_in_place).
  bool in_place = false;
  /// With in_place: block row j of H's upper storage (the blocks H_ji, i > j, = the blocks of
  /// column j of L in place) as CSR: t_ptr[j] .. t_ptr[j+1] index t_col (i), t_off (the block's
  /// offset in H's values) and t_stride (its column stride, column i's height), for the
  /// backward substitution.
  std::vector<int> t_ptr, t_col, t_off, t_stride;

  /// L's column structure for ordering `perm` of the block graph given as symmetric lower
  /// adjacency of original blocks; returns Σ (column count)² as a cost proxy when dry, and in
  /// *fill (if given) the number of blocks of L that are not blocks of H.
  static double build(const BlockStructure& s, const std::vector<int>& perm, int B,
                      BlockSymbolic* out, long* fill = nullptr) {
    const int nb = s.num_blocks();
    std::vector<int> inv(nb);
    for (int q = 0; q < nb; ++q) inv[perm[q]] = q;
    // Lower adjacency in the new numbering (CSR by column j: rows i > j).
    std::vector<int> cnt(nb + 1, 0);
    const auto& bcp = s.block_col_ptr();
    const auto& brow = s.block_rows();
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        if (brow[k] != b) ++cnt[std::min(inv[brow[k]], inv[b]) + 1];
    for (int j = 0; j < nb; ++j) cnt[j + 1] += cnt[j];
    std::vector<int> adj(cnt[nb]), fillp(cnt.begin(), cnt.end() - 1);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        if (brow[k] != b) {
          const int i = inv[brow[k]], j = inv[b];
          adj[fillp[std::min(i, j)]++] = std::max(i, j);
        }
    // Column structures, children lists through the elimination tree.
    std::vector<int> col_ptr(nb + 1, 0), rows;
    rows.reserve(static_cast<std::size_t>(cnt[nb] + nb) * 2);
    std::vector<int> mark(nb, -1), child_head(nb, -1), child_next(nb, -1);
    double cost = 0.0, flops = 0.0;
    long fill_blocks = 0;
    const double gemm = 2.0 * B * B * B;
    for (int j = 0; j < nb; ++j) {
      const std::size_t start = rows.size();
      rows.push_back(j);
      mark[j] = j;
      for (int p = cnt[j]; p < cnt[j + 1]; ++p)
        if (mark[adj[p]] != j) {
          mark[adj[p]] = j;
          rows.push_back(adj[p]);
        }
      for (int c = child_head[j]; c >= 0; c = child_next[c])
        for (int p = col_ptr[c] + 1; p < col_ptr[c + 1]; ++p) {
          const int i = rows[p];
          if (i != j && mark[i] != j) {
            mark[i] = j;
            rows.push_back(i);
            ++fill_blocks;
          }
        }
      std::sort(rows.begin() + static_cast<std::ptrdiff_t>(start) + 1, rows.end());
      col_ptr[j + 1] = static_cast<int>(rows.size());
      const double m = static_cast<double>(rows.size() - start - 1);  // off-diagonal blocks
      cost += (m + 1.0) * (m + 1.0);
      flops += gemm * (m * (m + 1.0) / 2.0 + m) + 2.0 * B * B * B / 3.0;
      if (m > 0) {
        const int parent = rows[start + 1];
        child_next[j] = child_head[parent];
        child_head[parent] = j;
      }
    }
    if (fill) *fill = fill_blocks;
    if (!out) return cost;
    out->nb = nb;
    out->perm = perm;
    out->inv = std::move(inv);
    out->col_ptr = std::move(col_ptr);
    out->row = std::move(rows);
    out->flops = flops;
    // Slot of every stored block of H.
    const std::size_t nh = brow.size();
    out->src_slot.assign(nh, -1);
    out->src_tr.assign(nh, 0);
    out->src_diag.assign(nh, 0);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) {
        const int ia = out->inv[brow[k]], ib = out->inv[b];
        const int i = std::max(ia, ib), j = std::min(ia, ib);
        const auto first = out->row.begin() + out->col_ptr[j];
        const auto last = out->row.begin() + out->col_ptr[j + 1];
        const auto it = std::lower_bound(first, last, i);
        out->src_slot[k] = static_cast<int>(it - out->row.begin());
        out->src_diag[k] = brow[k] == b;
        // H_ab has a's rows; L(i, j) has block i's rows: transposed when a is the column.
        out->src_tr[k] = ia < ib;
      }
    out->fill_slot.assign(out->row.size(), 1);
    for (std::size_t k = 0; k < nh; ++k) out->fill_slot[out->src_slot[k]] = 0;
    std::vector<int> row_blocks(nb, 0);
    for (const int r : out->row) ++row_blocks[r];
    out->max_row_blocks = nb > 0 ? *std::max_element(row_blocks.begin(), row_blocks.end()) : 0;
    bool natural = true;
    for (int q = 0; q < nb; ++q) natural = natural && perm[q] == q;
    out->in_place = natural && fill_blocks == 0;
    out->t_ptr.assign(static_cast<std::size_t>(nb) + 1, 0);
    out->t_col.clear();
    out->t_off.clear();
    out->t_stride.clear();
    if (out->in_place) {
      for (int b = 0; b < nb; ++b)
        for (int k = bcp[b]; k < bcp[b + 1] - 1; ++k) ++out->t_ptr[brow[k] + 1];
      for (int j = 0; j < nb; ++j) out->t_ptr[j + 1] += out->t_ptr[j];
      const std::size_t nt = static_cast<std::size_t>(out->t_ptr[nb]);
      out->t_col.resize(nt);
      out->t_off.resize(nt);
      out->t_stride.resize(nt);
      std::vector<int> next(out->t_ptr.begin(), out->t_ptr.end() - 1);
      for (int b = 0; b < nb; ++b)  // columns ascending: each row's list comes out sorted
        for (int k = bcp[b]; k < bcp[b + 1] - 1; ++k) {
          const int at = next[brow[k]]++;
          out->t_col[at] = b;
          out->t_off[at] = s.block_offsets()[k];
          out->t_stride[at] = s.column_height(b);
        }
    }
    out->src_stride.assign(nh, 0);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) out->src_stride[k] = s.column_height(b);
    out->src_ptr.assign(static_cast<std::size_t>(nb) + 1, 0);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        ++out->src_ptr[std::min(out->inv[brow[k]], out->inv[b]) + 1];
    for (int j = 0; j < nb; ++j) out->src_ptr[j + 1] += out->src_ptr[j];
    out->src_list.resize(nh);
    std::vector<int> next(out->src_ptr.begin(), out->src_ptr.end() - 1);
    for (int b = 0; b < nb; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k)
        out->src_list[next[std::min(out->inv[brow[k]], out->inv[b])]++] = k;
    return cost;
  }
};

class BlockFactorBase {
 public:
  virtual ~BlockFactorBase() = default;
  virtual void setup(const BlockSymbolic* sym) = 0;
  /// 0 on success, else 1 + the (new-numbering) block column that is not positive definite.
  /// With b (and x) non-null, also x = H⁻¹·b on success (forward substitution column by column
  /// during the factorisation, then the backward one).
  virtual int factorize(const BlockStructure& s, const double* values, const double* b = nullptr,
                        double* x = nullptr) = 0;
  /// factorize() with the factor written over H's values (only when BlockSymbolic::in_place);
  /// solve() then reads them, so they must stay untouched until the last solve.
  virtual int factorize_in_place(const BlockStructure& s, double* values, const double* b,
                                 double* x) = 0;
  virtual void solve(const double* b, double* x) = 0;
};

template <int B>
class BlockFactor final : public BlockFactorBase {
 public:
  using Mat = Eigen::Matrix<double, B, B>;
  using Vec = Eigen::Matrix<double, B, 1>;
  using ConstMap = Eigen::Map<const Mat, 0, Eigen::OuterStride<>>;

  void setup(const BlockSymbolic* sym) override {
    sym_ = sym;
    // L is allocated by the first factorize() that needs it (factorize_in_place() does not)
    // and not zeroed: factorize() writes every block of it (H's blocks, zeroed fill-in) before
    // reading it, and BlockCholeskySolver::solve() refuses to run before a successful
    // factorisation.
    L_.clear();
    in_place_ = false;
    pa_.assign(static_cast<std::size_t>(sym->max_row_blocks), nullptr);
    pb_.assign(static_cast<std::size_t>(sym->max_row_blocks), nullptr);
    Linv_.assign(static_cast<std::size_t>(sym->nb), Mat::Zero());
    y_.assign(static_cast<std::size_t>(sym->nb), Vec::Zero());
    slot_of_row_.assign(static_cast<std::size_t>(sym->nb), -1);
    head_.assign(static_cast<std::size_t>(sym->nb), -1);
    next_.assign(static_cast<std::size_t>(sym->nb), -1);
    ptr_.assign(static_cast<std::size_t>(sym->nb), -1);
  }

  int factorize(const BlockStructure& s, const double* values, const double* b = nullptr,
                double* x = nullptr) override {
#ifdef GEODRIFT_AVX2_KERNELS
    if (block_kernels_avx2()) return factorize_with<BlockKernelsAvx2<B>>(s, values, b, x);
#endif
    return factorize_with<BlockKernelsEigen<B>>(s, values, b, x);
  }

  int factorize_in_place(const BlockStructure& s, double* values, const double* b,
                         double* x) override {
    GEODRIFT_ASSERT(sym_->in_place);
#ifdef GEODRIFT_AVX2_KERNELS
    if (block_kernels_avx2()) return factorize_in_place_with<BlockKernelsAvx2<B>>(s, values, b, x);
#endif
    return factorize_in_place_with<BlockKernelsEigen<B>>(s, values, b, x);
  }

  void solve(const double* b, double* x) override {
#ifdef GEODRIFT_AVX2_KERNELS
    if (block_kernels_avx2()) {
      if (in_place_) return solve_in_place_with<BlockKernelsAvx2<B>>(b, x);
      return solve_with<BlockKernelsAvx2<B>>(b, x);
    }
#endif
    if (in_place_) return solve_in_place_with<BlockKernelsEigen<B>>(b, x);
    solve_with<BlockKernelsEigen<B>>(b, x);
  }

 private:
  // ---- the factor in H's values (natural order without fill) --------------------------------
  // Block column i of H's upper CSC holds H_ji for j ∈ R(i) (ascending, ending with i), each
  // column-major with the column's height h_i as stride. It becomes block row i of L: L_ij in
  // H_ji's place (same stride), L_ii (lower, zeros above) in H_ii's. Rows are computed in order
  // (up-looking Cholesky): L_ij = (H_ij − Σ_{k<j} L_ik·L_jkᵀ)·L_jj⁻ᵀ for j ∈ R(i), j < i, then
  // L_ii = chol(H_ii − Σ_{k<i} L_ik·L_ikᵀ); H_ji is read just before L_ij is written over it, and
  // without fill every L_ik, L_jk that is not zero has a place in H. Same flops as the
  // left-looking factorize(), no second matrix.
  template <class Kernels>
  int factorize_in_place_with(const BlockStructure& s, double* values, const double* b, double* x) {
    const int nb = s.num_blocks();
    const int* bcp = s.block_col_ptr().data();
    const int* brow = s.block_rows().data();
    const int* boff = s.block_offsets().data();
    const double** pa = pa_.data();
    const double** pb = pb_.data();
    in_place_ = false;
    in_place_s_ = &s;
    in_place_values_ = values;
    if (b) load_rhs(b);
    alignas(32) double C[B * B];
    for (int i = 0; i < nb; ++i) {
      const int p0 = bcp[i], pd = bcp[i + 1] - 1;  // pd: H_ii
      const int h = s.column_height(i);
      for (int q = p0; q < pd; ++q) {
        const int j = brow[q];
        Kernels::load_transposed(values + boff[q], h, C);  // H_ij = H_jiᵀ
        // k < j with L_ik (row i, positions p0..q-1, already factored) and L_jk (row j) ≠ 0.
        int m = 0;
        for (int u = p0, v = bcp[j], ve = bcp[j + 1] - 1; u < q && v < ve;) {
          if (brow[u] < brow[v]) {
            ++u;
          } else if (brow[v] < brow[u]) {
            ++v;
          } else {
            pa[m] = values + boff[u];
            pb[m] = values + boff[v];
            ++m, ++u, ++v;
          }
        }
        Kernels::nt_sum(C, m, pa, h, pb, s.column_height(j));
        Kernels::scale_store(C, Linv_[j].data(), values + boff[q], h);
      }
      double* Hd = values + boff[pd];
      for (int c = 0; c < B; ++c)
        for (int r = 0; r <= c; ++r) C[r + c * B] = C[c + r * B] = Hd[r + c * h];  // upper
      int m = 0;
      for (int u = p0; u < pd; ++u) pa[m++] = values + boff[u];
      Kernels::nt_sum(C, m, pa, h, pa, h);
      if (!cholesky_inverse<B>(C, Linv_[i].data())) return i + 1;
      for (int c = 0; c < B; ++c)
        for (int r = 0; r < B; ++r) Hd[r + c * h] = C[r + c * B];
      if (b) forward_row_in_place<Kernels>(i);  // row i of L is still in cache
    }
    in_place_ = true;
    if (b) backward_in_place<Kernels>(x);
    return 0;
  }
  /// y_i ← L_ii⁻¹·(y_i − Σ_{j<i} L_ij·y_j).
  template <class Kernels>
  void forward_row_in_place(int i) {
    const BlockStructure& s = *in_place_s_;
    const int* boff = s.block_offsets().data();
    const int* brow = s.block_rows().data();
    const int p0 = s.block_col_ptr()[i], pd = s.block_col_ptr()[i + 1] - 1;
    const int h = s.column_height(i);
    double* y = y_.data()->data();
    Kernels::row_mat_vec_sub(in_place_values_, boff + p0, h, brow + p0, pd - p0, y, y + B * i);
    lower_solve<B>(in_place_values_ + boff[pd], Linv_[i].data(), y + B * i, h);
  }
  /// Lᵀ·x = y from the last block: x_j = L_jj⁻ᵀ·(y_j − Σ_{i>j} L_ijᵀ·x_i), the L_ij of column j
  /// gathered from H's block row j (BlockSymbolic::t_*).
  template <class Kernels>
  void backward_in_place(double* x) {
    const BlockSymbolic& S = *sym_;
    const BlockStructure& s = *in_place_s_;
    const int* boff = s.block_offsets().data();
    const int* bcp = s.block_col_ptr().data();
    double* y = y_.data()->data();
    for (int j = S.nb - 1; j >= 0; --j) {
      const int t0 = S.t_ptr[j], tn = S.t_ptr[j + 1] - t0;
      Kernels::transpose_gather(in_place_values_, S.t_off.data() + t0, S.t_stride.data() + t0,
                                S.t_col.data() + t0, tn, y, y + B * j);
      lower_transpose_solve<B>(in_place_values_ + boff[bcp[j + 1] - 1], Linv_[j].data(), y + B * j,
                               s.column_height(j));
    }
    for (int j = 0; j < S.nb; ++j) Eigen::Map<Vec>(x + B * S.perm[j]) = y_[j];
  }
  template <class Kernels>
  void solve_in_place_with(const double* b, double* x) {
    load_rhs(b);
    for (int i = 0; i < sym_->nb; ++i) forward_row_in_place<Kernels>(i);
    backward_in_place<Kernels>(x);
  }

  // ---- the factor in its own storage L_ (any order) -----------------------------------------
  template <class Kernels>
  void solve_with(const double* b, double* x) {
    const BlockSymbolic& S = *sym_;
    const int nb = S.nb;
    const int* cp = S.col_ptr.data();
    const int* rw = S.row.data();
    static_assert(sizeof(Vec) == sizeof(double) * B, "y_ is B-vectors back to back");
    load_rhs(b);
    for (int j = 0; j < nb; ++j) forward_column<Kernels>(j, cp, rw);  // L·y = b
    backward<Kernels>(x);
  }

  void load_rhs(const double* b) {
    for (int j = 0; j < sym_->nb; ++j) y_[j] = Eigen::Map<const Vec>(b + B * sym_->perm[j]);
  }
  /// y_j ← L_jj⁻¹·y_j by substitution, then y_i −= L_ij·y_j below it.
  template <class Kernels>
  void forward_column(int j, const int* cp, const int* rw) {
    double* y = y_.data()->data();
    lower_solve<B>(L_[cp[j]].data(), Linv_[j].data(), y + B * j);
    Kernels::lower_update(L_.data()->data(), cp[j] + 1, cp[j + 1], rw, y + B * j, y);
  }
  /// Lᵀ·x = y, x permuted back.
  template <class Kernels>
  void backward(double* x) {
    const BlockSymbolic& S = *sym_;
    const int* cp = S.col_ptr.data();
    const int* rw = S.row.data();
    const double* L = L_.data()->data();
    double* y = y_.data()->data();
    Vec t;
    for (int j = S.nb - 1; j >= 0; --j) {
      t = y_[j];
      Kernels::transpose_update(L, cp[j] + 1, cp[j + 1], rw, y, t.data());
      lower_transpose_solve<B>(L + static_cast<std::size_t>(cp[j]) * B * B, Linv_[j].data(),
                               t.data());
      y_[j] = t;
    }
    for (int j = 0; j < S.nb; ++j) Eigen::Map<Vec>(x + B * S.perm[j]) = y_[j];
  }

  template <class Kernels>
  int factorize_with(const BlockStructure& s, const double* values, const double* b, double* x) {
    const BlockSymbolic& S = *sym_;
    const int nb = S.nb;
    const int* cp = S.col_ptr.data();
    const int* rw = S.row.data();
    static_assert(sizeof(Mat) == sizeof(double) * B * B, "L_ is B×B blocks back to back");
    in_place_ = false;
    if (L_.size() != S.row.size()) L_.resize(S.row.size());  // once (see setup())
    double* L = L_.data()->data();
    // One pass over L: column j is zeroed and loaded from H just before its updates (it is
    // still in cache when the updates and the diagonal solve touch it).
    const auto& boff = s.block_offsets();
    const int* sp = S.src_ptr.data();
    const int* sl = S.src_list.data();
    std::fill(head_.begin(), head_.end(), -1);
    if (b) load_rhs(b);
    for (int j = 0; j < nb; ++j) {
      for (int p = cp[j]; p < cp[j + 1]; ++p) {
        slot_of_row_[rw[p]] = p;
        if (S.fill_slot[p]) L_[p].setZero();
      }
      for (int t = sp[j]; t < sp[j + 1]; ++t) {
        const int k = sl[t];
        const ConstMap A(values + boff[k], B, B, Eigen::OuterStride<>(S.src_stride[k]));
        Mat& dst = L_[static_cast<std::size_t>(S.src_slot[k])];
        if (S.src_diag[k])
          dst = A.template selfadjointView<Eigen::Upper>();
        else if (S.src_tr[k])
          Kernels::load_transposed(values + boff[k], S.src_stride[k], dst.data());
        else
          dst = A;
      }
      // Updates from every column k with L_jk ≠ 0 (k < j).
      for (int k = head_[j]; k >= 0;) {
        const int nk = next_[k];
        const int p = ptr_[k];
        Kernels::update(L, p, cp[k + 1], rw, slot_of_row_.data());
        if (p + 1 < cp[k + 1]) {
          ptr_[k] = p + 1;
          const int i = rw[p + 1];
          next_[k] = head_[i];
          head_[i] = k;
        }
        k = nk;
      }
      // Diagonal block.
      Mat& Li = Linv_[j];
      if (!cholesky_inverse<B>(L_[cp[j]].data(), Li.data())) return j + 1;
      Kernels::scale(L, cp[j] + 1, cp[j + 1], Li.data());
      if (cp[j] + 1 < cp[j + 1]) {
        ptr_[j] = cp[j] + 1;
        const int i = rw[cp[j] + 1];
        next_[j] = head_[i];
        head_[i] = j;
      }
      if (b) forward_column<Kernels>(j, cp, rw);  // column j of L is still in cache
    }
    if (b) backward<Kernels>(x);
    return 0;
  }

  const BlockSymbolic* sym_ = nullptr;
  // Ordinary allocation: on the solver's own large-array mappings (huge pages or not) this
  // factorisation ran 25-30 % slower in the 10k drift solve (BENCHMARKS.md "Tried and not
  // kept"; round 6 of its history, `git show 3d5878d:BENCHMARKS.md`).
  std::vector<Mat, Eigen::aligned_allocator<Mat>> L_, Linv_;
  std::vector<Vec, Eigen::aligned_allocator<Vec>> y_;
  std::vector<int> slot_of_row_, head_, next_, ptr_;
  // The in-place factor: whether the last successful factorisation is in H's values, which
  // matrix, and the block pointers of one row's products.
  bool in_place_ = false;
  const BlockStructure* in_place_s_ = nullptr;
  const double* in_place_values_ = nullptr;
  std::vector<const double*> pa_, pb_;
};

}  // namespace detail

/// Block sparse Cholesky with B×B fixed-size kernels (see the file comment).
class BlockCholeskySolver final : public LinearSolver {
 public:
  enum class Ordering {
    kBest,     ///< natural if it has no fill, else natural or AMD, whichever needs fewer flops
    kNatural,  ///< the problem's block order
    kAmd,      ///< AMD on the block pattern
  };
  explicit BlockCholeskySolver(Ordering ordering = Ordering::kBest) : ordering_(ordering) {}

  /// The common block size if every block of `s` has the same size 6 or 7 and nothing is
  /// Schur-eliminated; 0 otherwise (then this solver cannot be used).
  static int supported_block_size(const BlockStructure& s) {
    if (s.num_blocks() == 0 || s.num_eliminated() != 0) return 0;
    const int B = s.block_size(0);
    if (B != 6 && B != 7) return 0;
    for (int b = 1; b < s.num_blocks(); ++b)
      if (s.block_size(b) != B) return 0;
    return B;
  }

  /// Whether block Cholesky suits `s`: a supported block size and, with the ordering analyze()
  /// would choose, at most `max_blocks_per_column` blocks per column of L on average.
  static bool thin_factor(const BlockStructure& s, double max_blocks_per_column) {
    return BlockCholeskySolver().symbolic_if_thin(s, max_blocks_per_column);
  }

  LinearSolverStatus analyze(const BlockStructure& s) override {
    return analyze_if_thin(s, std::numeric_limits<double>::infinity())
               ? LinearSolverStatus::kSuccess
               : LinearSolverStatus::kFatal;
  }

  /// analyze() for kAuto's decision in one pass (the ordering and the symbolic factor are what
  /// the decision needs): true and analysed when `s` is supported and the factor has at most
  /// `max_blocks_per_column` blocks per column on average; false otherwise, with nothing of the
  /// numeric factor allocated (a thick factor goes to CHOLMOD, see LinearSolverType::kAuto).
  bool analyze_if_thin(const BlockStructure& s, double max_blocks_per_column) {
    if (!symbolic_if_thin(s, max_blocks_per_column)) return false;
    if (B_ == 6)
      factor_ = std::make_unique<detail::BlockFactor<6>>();
    else
      factor_ = std::make_unique<detail::BlockFactor<7>>();
    factor_->setup(&sym_);
    factorized_ = false;
    n_ = s.num_cols();
    nb_ = s.num_blocks();
    nvalues_ = s.num_values();
    return true;
  }

  LinearSolverStatus factorize(const BlockSparseMatrix& H) override {
    return factorize_impl(H, nullptr, nullptr);
  }

  LinearSolverStatus solve(const double* b, double* x) override {
    message_.clear();
    if (!factorized_) {
      message_ = "block Cholesky: solve() without a successful factorize()";
      return LinearSolverStatus::kFatal;
    }
    factor_->solve(b, x);
    return LinearSolverStatus::kSuccess;
  }

  /// factorize(H) with the forward substitution of b done column by column inside it.
  LinearSolverStatus factorize_and_solve(const BlockSparseMatrix& H, const double* b,
                                         double* x) override {
    return factorize_impl(H, b, x);
  }

  /// Whether the analysed pattern lets the factor overwrite H (the natural order without fill,
  /// as on chains of keyframes linked to their next few): then factorize_and_solve_in_place()
  /// needs no memory for L (at 50k Sim(3) keyframes 137 MB less to allocate and first-touch,
  /// and no copy of H into it).
  bool in_place() const { return factor_ && sym_.in_place; }

  /// With in_place(): the factor is written over H's values (row by row, see BlockFactor), and
  /// solve() reads it there until the next factorisation, so H must not change meanwhile.
  /// Otherwise factorize_and_solve().
  LinearSolverStatus factorize_and_solve_in_place(BlockSparseMatrix* H, const double* b, double* x,
                                                  bool* overwritten) override {
    *overwritten = false;
    if (!in_place()) return factorize_impl(*H, b, x);
    const LinearSolverStatus st = check(*H);
    if (st != LinearSolverStatus::kSuccess) return st;
    *overwritten = true;
    return finish(factor_->factorize_in_place(H->structure(), H->values(), b, x));
  }

  std::string name() const override { return "block-cholesky"; }
  double factor_nnz() const override {
    if (!factor_) return 0.0;
    const double off = static_cast<double>(sym_.row.size()) - sym_.nb;
    return off * B_ * B_ + static_cast<double>(sym_.nb) * B_ * (B_ + 1) / 2.0;
  }
  /// Average number of blocks per block column of L (after analyze(); 0 before).
  double blocks_per_column() const {
    return factor_ && sym_.nb > 0 ? static_cast<double>(sym_.row.size()) / sym_.nb : 0.0;
  }
  /// Flops of one numeric factorisation (after analyze()).
  double flops() const { return factor_ ? sym_.flops : 0.0; }
  /// Block ordering chosen by analyze(): position -> block.
  const std::vector<int>& permutation() const { return sym_.perm; }

 private:
  LinearSolverStatus check(const BlockSparseMatrix& H) {
    message_.clear();
    factorized_ = false;
    if (!factor_) {
      message_ = "block Cholesky: factorize() before analyze()";
      return LinearSolverStatus::kFatal;
    }
    if (H.rows() != n_ || H.structure().num_blocks() != nb_ ||
        H.structure().num_values() != nvalues_) {
      message_ = "block Cholesky: matrix size or pattern differs from the analysed one";
      return LinearSolverStatus::kFatal;
    }
    return LinearSolverStatus::kSuccess;
  }
  LinearSolverStatus factorize_impl(const BlockSparseMatrix& H, const double* b, double* x) {
    const LinearSolverStatus st = check(H);
    if (st != LinearSolverStatus::kSuccess) return st;
    return finish(factor_->factorize(H.structure(), H.values(), b, x));
  }
  /// The status of a factorisation that returned `bad` (0 or 1 + the failing block column).
  LinearSolverStatus finish(int bad) {
    if (bad != 0) {
      message_ = "block Cholesky: matrix not positive definite (block " +
                 std::to_string(sym_.perm[bad - 1]) + ")";
      return LinearSolverStatus::kNotPositiveDefinite;
    }
    factorized_ = true;
    return LinearSolverStatus::kSuccess;
  }

  /// The part of analyze_if_thin() that decides: B_, the ordering and the symbolic factor sym_
  /// (cleared when the factor is thicker than max_blocks_per_column); no numeric storage.
  bool symbolic_if_thin(const BlockStructure& s, double max_blocks_per_column) {
    message_.clear();
    factor_.reset();
    factorized_ = false;
    B_ = supported_block_size(s);
    if (B_ == 0) {
      message_ =
          "block Cholesky: needs every free parameter block of size 6 or 7 and no Schur "
          "elimination";
      return false;
    }
    if (ordering_ == Ordering::kBest) {
      // The natural order's symbolic factor, built once: kept without running AMD (which
      // minimises fill: there is none to remove) when it has no fill, as on a chain of keyframes
      // linked to their next few; otherwise whichever of it and AMD's order needs fewer flops.
      std::vector<int> natural(static_cast<std::size_t>(s.num_blocks()));
      std::iota(natural.begin(), natural.end(), 0);
      long fill = 0;
      const double natural_cost = detail::BlockSymbolic::build(s, natural, B_, &sym_, &fill);
      if (fill != 0) {
        const std::vector<int> amd = amd_order(s);
        if (detail::BlockSymbolic::build(s, amd, B_, nullptr) < natural_cost)
          detail::BlockSymbolic::build(s, amd, B_, &sym_);
      }
    } else {
      detail::BlockSymbolic::build(s, choose_order(s, ordering_), B_, &sym_);
    }
    if (static_cast<double>(sym_.row.size()) > max_blocks_per_column * s.num_blocks()) {
      message_ = "block Cholesky: factor thicker than " + std::to_string(max_blocks_per_column) +
                 " blocks per column";
      sym_ = detail::BlockSymbolic();
      return false;
    }
    return true;
  }

  /// The order of kNatural / kAmd (kBest decides in symbolic_if_thin()).
  static std::vector<int> choose_order(const BlockStructure& s, Ordering ordering) {
    if (ordering == Ordering::kAmd) return amd_order(s);
    std::vector<int> natural(static_cast<std::size_t>(s.num_blocks()));
    std::iota(natural.begin(), natural.end(), 0);
    return natural;
  }

  static std::vector<int> amd_order(const BlockStructure& s) {
    const int nb = s.num_blocks();
    std::vector<Eigen::Triplet<double>> t;
    t.reserve(2 * s.block_rows().size());
    for (int b = 0; b < nb; ++b)
      for (int k = s.block_col_ptr()[b]; k < s.block_col_ptr()[b + 1]; ++k) {
        t.emplace_back(s.block_rows()[k], b, 1.0);
        t.emplace_back(b, s.block_rows()[k], 1.0);
      }
    Eigen::SparseMatrix<double, Eigen::ColMajor, int> A(nb, nb);
    A.setFromTriplets(t.begin(), t.end());
    Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> P;
    Eigen::AMDOrdering<int> amd;
    amd(A, P);
    // Eigen returns the inverse permutation (SimplicialCholesky inverts it before twistedBy):
    // indices()[new position] = old block.
    return std::vector<int>(P.indices().data(), P.indices().data() + nb);
  }

  Ordering ordering_;
  int B_ = 0, n_ = 0, nb_ = 0, nvalues_ = 0;  ///< size, blocks and values of the analysed H
  bool factorized_ = false;                   ///< L holds the factor of the last factorize()
  detail::BlockSymbolic sym_;
  std::unique_ptr<detail::BlockFactorBase> factor_;
};

}  // namespace geodrift::solver
