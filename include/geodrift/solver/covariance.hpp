#pragma once

/// @file
/// Covariance: marginal covariances of selected parameter blocks of a Problem at its current
/// state (the Laplace approximation of the posterior around a least-squares optimum), in the
/// spirit of Ceres' `Covariance`. For the corrected path's per-keyframe uncertainty (issue 24),
/// pose-graph nodes after PGO, BA points, ...
///
/// ## What is computed
/// H = J̃ᵀJ̃ is exactly the Gauss–Newton matrix LevenbergMarquardt factorises, without damping:
/// Problem::linearize() at the current states, J̃ the weighted residual Jacobians with the
/// robust losses' Triggs correction as the solver applies it there (loss.hpp; √ρ'·J in the robust
/// regions of Huber and Cauchy). Σ = H⁻¹ over the free parameter blocks (constant blocks own no
/// column: they are conditioned on, not marginalised), and the results are its blocks
///   Σ_kk = [H⁻¹]_kk  (dof_k × dof_k)   and selected  Σ_ab = [H⁻¹]_ab  (dof_a × dof_b).
///
/// ## Conventions
///  - Coordinates: the tangent of the solver's perturbation of each block, on the LEFT for
///    groups (X ← exp(δ)·X) and x ← x + δ for R^n, in the tangent order of DESIGN.md:
///    so(3) = ω; se(3) = (ω, ν); sim(3) = (ω, σ, ν), σ = log scale. So Σ of a world→camera
///    S_cw is the covariance of δ in exp(δ)·S_cw, i.e. expressed in the CAMERA frame.
///  - Units follow the residual weights: Σ is a covariance in metres², rad², ... only when every
///    weight is an information (inverse variance) in those units. With arbitrary weights (the
///    paper's λ1 = λ2 = 1e5, λ3 = 1) it is known up to a common factor; the usual estimate of that
///    factor is 2·cost / (residuals − free tangent columns) at the optimum (not applied here).
///  - Camera-centre covariance of a Sim(3) node S_cw = (R, t, s): c = −(1/s)·Rᵀ·t and, under
///    exp(δ)·S, dc/dδ = [0₃ₓ₃  0₃ₓ₁  −(1/s)·Rᵀ] (CameraCentrePriorResidual), so
///    Σ_c = (1/s²)·Rᵀ·Σ_νν·R with Σ_νν = Σ.bottomRightCorner<3, 3>() (W frame, metres² when the
///    weights are informations in metres).
///
/// @code
///   solver::LevenbergMarquardt(options).solve(&problem);       // states at the optimum
///   solver::Covariance cov;
///   std::string why;
///   std::vector<const void*> wanted;
///   for (const lie::Sim3d& S : poses)
///     if (!problem.is_constant(&S)) wanted.push_back(&S);
///   if (!cov.compute(problem, wanted, &why)) { /* cov.status(): kRankDeficient, ... */ }
///   const Eigen::Matrix<double, 7, 7> Sigma = cov.block(&poses[k]);   // (ω, σ, ν)
/// @endcode
///
/// ## Method and cost
/// One sparse Cholesky P·H·Pᵀ = L·Lᵀ on the block pattern the solver's BlockCholeskySolver uses
/// (detail::BlockSymbolic: block elimination tree, column structures; natural order when it
/// has no fill, as on keyframe chains, else the cheaper of natural and AMD), blocks of any size
/// (fixed-size kernels when every block is 6 or 7). The solver's factors keep L private (written
/// over H's storage, or CHOLMOD's supernodal scalar layout), so L is factorised again here into
/// a block store of its own: one more factorisation, the cost of one LM iteration.
/// Then the block Takahashi recursion (K. Takahashi, J. Fagan, M.-S. Chen, "Formation of a
/// sparse bus impedance matrix and its application to short circuit study", 1973; T. Davis,
/// "Direct Methods for Sparse Linear Systems", SIAM 2006) computes Σ = L⁻ᵀ·L⁻¹ on L's pattern
/// only, column by column from the last, in place of L:
///   A_k = L_kj·L_jj⁻¹,   Σ_ij = −Σ_{k∈S(j)} Σ_ik·A_k  (i ∈ S(j)),
///   Σ_jj = L_jj⁻ᵀ·L_jj⁻¹ − Σ_{k∈S(j)} Σ_kjᵀ·A_k,        S(j) = rows of L's column j below j,
/// where every Σ_ik needed lies on L's pattern (the rows of a column of L form a clique).
/// Why Takahashi and not solves for the wanted columns: the Corrector wants EVERY diagonal block
/// of up to 50k Sim(3) keyframes. Solves cost O(nnz(L)) per scalar column, 7·n of them: O(n²)
/// (≈ 1e13 flops at 50k). Takahashi costs Σ_j |S(j)|²·2B³ flops (a small multiple of the
/// factorisation) and L's memory (Σ overwrites it). Selected off-diagonal pairs whose blocks
/// are not on L's pattern (far apart in the graph) are the exception: each distinct second
/// block of such pairs costs one multi-right-hand-side solve with L (before Σ overwrites it).
/// Work: one linearisation + one factorisation + 4 solves (rank test) + the recursion from the
/// last column down to the earliest wanted one in the elimination order. Memory: H and L (≈ H
/// on chains) at the peak, then L only. Measured (all 7×7 diagonal blocks of a Sim(3) chain, each
/// keyframe linked to its next 5, 1 m anchors every 200; one core of the project VM, -O2):
/// 10k keyframes 0.19–0.20 s, 50k keyframes 0.97–1.02 s (linearise 0.15, factorise 0.28,
/// rank test 0.23, recursion and copies 0.31), against 0.3 s per LM iteration at 50k.
///
/// ## Failures
/// A gauge freedom or an unobservable direction makes H singular. Rounding usually lets the
/// Cholesky finish anyway, with pivots that on long chains are not small enough to tell (about
/// n²·1e-16 relative), so the rank test (CovarianceOptions::rank_tolerance) bounds the smallest
/// eigenvalue of the Jacobi-scaled H twice: by the pivots d_c/H_cc during the factorisation,
/// and by the Rayleigh quotient, computed with H itself, of a vector from a few steps of
/// inverse iteration (4 solves with the factor). Either at or below the tolerance gives
/// CovarianceStatus::kRankDeficient with a message (naming the parameter block and tangent
/// coordinate when a pivot failed); nothing is returned (no NaN, no huge numbers). Residual
/// blocks that cannot be evaluated, or a non-finite H, give kEvaluationFailed. Requesting a
/// constant block or a pointer that is not a parameter of the problem throws InvalidArgument.

#include <Eigen/Core>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/solver/block_cholesky_solver.hpp"
#include "geodrift/solver/block_sparse_matrix.hpp"
#include "geodrift/solver/block_structure.hpp"
#include "geodrift/solver/problem.hpp"

namespace geodrift::solver {

/// Outcome of Covariance::compute().
enum class CovarianceStatus {
  kNotComputed,       ///< compute() not called yet
  kSuccess,           ///< every requested block is available
  kRankDeficient,     ///< H is singular (gauge freedom, unobservable direction): see message()
  kEvaluationFailed,  ///< a residual block could not be evaluated, or H is not finite
};

inline const char* to_string(CovarianceStatus s) {
  switch (s) {
    case CovarianceStatus::kNotComputed:
      return "not computed";
    case CovarianceStatus::kSuccess:
      return "success";
    case CovarianceStatus::kRankDeficient:
      return "rank deficient";
    case CovarianceStatus::kEvaluationFailed:
      return "evaluation failed";
  }
  return "?";
}

/// Options of Covariance.
struct CovarianceOptions {
  /// Rank test on the Jacobi-scaled H̃ = D^-½·H·D^-½ (D = diag H; unit diagonal, so the test
  /// does not depend on the parameters' units): H counts as singular when its smallest
  /// eigenvalue λ_min(H̃) ≤ rank_tolerance, as shown by either
  ///  - a Cholesky pivot d_c ≤ rank_tolerance·H_cc (d_c/H_cc ≥ λ_min(H̃) by interlacing), or
  ///  - the Rayleigh quotient xᵀH̃x of the vector x that a few steps of inverse iteration with
  ///    the factor leave (an upper bound of λ_min(H̃), accurate to second order in the error of
  ///    x, and evaluated with H itself, not its rounded factor).
  /// Pivots alone cannot tell: with a free gauge, rounding leaves pivot ratios of either sign up
  /// to ≈ 3e-7 (measured on Sim(3) chains of 3k–20k nodes 3 km from the origin), as large as
  /// genuine ones of well-posed chains (4e-8 at 50k keyframes, λ1 = 1e5 edges to the next
  /// neighbour, 1 m anchors every 200). Measured Rayleigh quotients: |·| ≤ 4e-17 with a free
  /// gauge (chains of 30–20k nodes), ≥ 3.6e-10 on those well-posed chains of 10k–50k keyframes.
  /// Must be in (0, 1).
  double rank_tolerance = 1e-12;

  /// @return true if valid; otherwise false and *why (if given) says which option and why.
  bool validate(std::string* why = nullptr) const {
    if (rank_tolerance > 0.0 && rank_tolerance < 1.0) return true;
    if (why) {
      std::ostringstream os;
      os << "rank_tolerance " << rank_tolerance << " is not in (0, 1)";
      *why = os.str();
    }
    return false;
  }
};

/// Time split of the last Covariance::compute() (seconds).
struct CovarianceTimes {
  double linearize = 0.0;   ///< Problem::linearize (residuals, Jacobians, H)
  double analyze = 0.0;     ///< ordering + symbolic factor
  double factorize = 0.0;   ///< copying H into the block store + numeric Cholesky
  double rank_check = 0.0;  ///< inverse iteration for the rank test
  double solve = 0.0;       ///< off-pattern pairs: multi-right-hand-side solves
  double inverse = 0.0;     ///< Takahashi recursion + extracting the blocks
  double total() const { return linearize + analyze + factorize + rank_check + solve + inverse; }
};

namespace detail {

/// Block lower factor L of P·H·Pᵀ on a BlockSymbolic pattern, for blocks of any size; after
/// takahashi() the same storage holds Σ = (P·H·Pᵀ)⁻¹ on L's pattern. Block numbering in here is
/// the elimination order ("position" q; the BlockStructure block is sym.perm[q]).
class CovarianceFactor {
 public:
  /// Ordering + symbolic factor of `s` (see the file comment).
  void analyze(const BlockStructure& s) {
    const int nb = s.num_blocks();
    uniform_ = nb > 0 ? s.block_size(0) : 0;
    for (int b = 1; b < nb; ++b)
      if (s.block_size(b) != uniform_) uniform_ = 0;
    const int B = uniform_ > 0 ? uniform_ : 7;  // BlockSymbolic uses it for its flop count only
    std::vector<int> natural(static_cast<std::size_t>(nb));
    std::iota(natural.begin(), natural.end(), 0);
    long fill = 0;
    const double natural_cost = BlockSymbolic::build(s, natural, B, nullptr, &fill);
    std::vector<int> order = std::move(natural);
    if (fill != 0) {
      std::vector<int> amd = amd_order(s);
      if (BlockSymbolic::build(s, amd, B, nullptr) < natural_cost) order = std::move(amd);
    }
    BlockSymbolic::build(s, order, B, &sym_);
    size_.resize(static_cast<std::size_t>(nb));
    start_.assign(static_cast<std::size_t>(nb) + 1, 0);
    for (int q = 0; q < nb; ++q) {
      size_[q] = s.block_size(sym_.perm[q]);
      start_[q + 1] = start_[q] + size_[q];
    }
    const int* cp = sym_.col_ptr.data();
    const int* rw = sym_.row.data();
    off_.assign(sym_.row.size() + 1, 0);
    for (int j = 0; j < nb; ++j)
      for (int p = cp[j]; p < cp[j + 1]; ++p)
        off_[p + 1] = off_[p] + static_cast<std::size_t>(size_[rw[p]]) * size_[j];
    // Row lists of L below the diagonal (for row j: the columns k < j with L_jk in the pattern
    // and its slot), which the left-looking factorisation walks.
    rptr_.assign(static_cast<std::size_t>(nb) + 1, 0);
    for (int k = 0; k < nb; ++k)
      for (int p = cp[k] + 1; p < cp[k + 1]; ++p) ++rptr_[rw[p] + 1];
    for (int i = 0; i < nb; ++i) rptr_[i + 1] += rptr_[i];
    rcol_.resize(static_cast<std::size_t>(rptr_[nb]));
    rslot_.resize(rcol_.size());
    std::vector<int> next(rptr_.begin(), rptr_.end() - 1);
    for (int k = 0; k < nb; ++k)
      for (int p = cp[k] + 1; p < cp[k + 1]; ++p) {
        const int at = next[rw[p]]++;
        rcol_[at] = k;
        rslot_[at] = p;
      }
    where_.assign(static_cast<std::size_t>(nb), -1);
    std::size_t scratch = 0;
    for (int j = 0; j < nb; ++j) scratch = std::max(scratch, off_[cp[j + 1]] - off_[cp[j]]);
    scratch_.assign(2 * scratch, 0.0);
  }

  const BlockSymbolic& symbolic() const { return sym_; }
  int num_positions() const { return sym_.nb; }
  int size(int q) const { return size_[q]; }
  int start(int q) const { return start_[q]; }
  int num_cols() const { return start_.empty() ? 0 : start_.back(); }

  /// Copies H (upper block CSC, BlockStructure layout) into L's slots, zeroing fill-in, and
  /// H's diagonal (elimination order) into *hdiag. False if a value of H is not finite.
  bool load(const BlockSparseMatrix& H, std::vector<double>* hdiag) {
    const BlockStructure& s = H.structure();
    values_.assign(off_.back(), 0.0);
    hdiag->assign(static_cast<std::size_t>(num_cols()), 0.0);
    const auto& bcp = s.block_col_ptr();
    const auto& brow = s.block_rows();
    const auto& boff = s.block_offsets();
    for (int b = 0; b < s.num_blocks(); ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) {
        const int a = brow[k];
        const BlockSparseMatrix::ConstBlockMap Hab(H.values() + boff[k], s.block_size(a),
                                                   s.block_size(b),
                                                   Eigen::OuterStride<>(s.column_height(b)));
        double* dst = values_.data() + off_[sym_.src_slot[k]];
        if (sym_.src_diag[k]) {
          // Upper triangle authoritative (as for CHOLMOD and the block Cholesky).
          Eigen::Map<Eigen::MatrixXd> D(dst, Hab.rows(), Hab.cols());
          D = Hab.selfadjointView<Eigen::Upper>();
          if (!D.allFinite()) return false;
          const int c0 = start_[sym_.inv[b]];
          for (int c = 0; c < D.rows(); ++c) (*hdiag)[c0 + c] = D(c, c);
        } else {
          if (!Hab.allFinite()) return false;
          if (sym_.src_tr[k])
            Eigen::Map<Eigen::MatrixXd>(dst, Hab.cols(), Hab.rows()) = Hab.transpose();
          else
            Eigen::Map<Eigen::MatrixXd>(dst, Hab.rows(), Hab.cols()) = Hab;
        }
      }
    return true;
  }

  /// Numeric Cholesky of the loaded values with the rank test (see CovarianceOptions).
  /// @return -1 on success, else the scalar column (elimination order) whose pivot failed;
  ///         *min_ratio is the smallest pivot ratio d_c / H_cc seen.
  int factorize(const std::vector<double>& hdiag, double tol, double* min_ratio) {
    if (uniform_ == 6) return factorize_with<6>(hdiag, tol, min_ratio);
    if (uniform_ == 7) return factorize_with<7>(hdiag, tol, min_ratio);
    return factorize_with<Eigen::Dynamic>(hdiag, tol, min_ratio);
  }

  /// X ← (P·H·Pᵀ)⁻¹·X with the factor (before takahashi()); X has num_cols() rows in
  /// elimination order.
  void solve(Eigen::MatrixXd* X) const {
    if (uniform_ == 6) return solve_with<6>(X);
    if (uniform_ == 7) return solve_with<7>(X);
    solve_with<Eigen::Dynamic>(X);
  }

  /// Replaces L by Σ on L's pattern for block columns stop..nb−1 (the recursion runs from the
  /// last column down; columns before `stop` keep L).
  void takahashi(int stop) {
    if (uniform_ == 6) return takahashi_with<6>(stop);
    if (uniform_ == 7) return takahashi_with<7>(stop);
    takahashi_with<Eigen::Dynamic>(stop);
  }

  /// Slot of block (i, j), i ≥ j, in L's pattern, or -1.
  int find(int i, int j) const {
    const auto first = sym_.row.begin() + sym_.col_ptr[j];
    const auto last = sym_.row.begin() + sym_.col_ptr[j + 1];
    const auto it = std::lower_bound(first, last, i);
    return it != last && *it == i ? static_cast<int>(it - sym_.row.begin()) : -1;
  }
  /// The block at `slot` (its rows' size × its column's size).
  Eigen::Map<const Eigen::MatrixXd> block(int slot) const {
    return Eigen::Map<const Eigen::MatrixXd>(values_.data() + off_[slot], rows_of(slot),
                                             cols_of(slot));
  }

  /// Frees the numeric storage.
  void release() {
    std::vector<double>().swap(values_);
    std::vector<double>().swap(scratch_);
  }

 private:
  int rows_of(int slot) const { return size_[sym_.row[slot]]; }
  int cols_of(int slot) const {
    // The column of a slot: the last column whose first slot is ≤ slot.
    const auto it = std::upper_bound(sym_.col_ptr.begin(), sym_.col_ptr.end(), slot);
    return size_[static_cast<int>(it - sym_.col_ptr.begin()) - 1];
  }

  template <int B>
  using Mat = Eigen::Matrix<double, B, B>;
  template <int B>
  Eigen::Map<Mat<B>> at(double* base, std::size_t off, int rows, int cols) {
    return Eigen::Map<Mat<B>>(base + off, rows, cols);
  }

  /// Y·Lᵀ = X for Y, in place (X: r × n, L: n × n lower): row by row, forward substitution.
  template <int B, class X, class L>
  static void solve_right_transpose(X& x, const L& l) {
    const int n = B == Eigen::Dynamic ? static_cast<int>(l.rows()) : B;
    for (int r = 0; r < x.rows(); ++r)
      for (int c = 0; c < n; ++c) {
        double v = x(r, c);
        for (int k = 0; k < c; ++k) v -= x(r, k) * l(c, k);
        x(r, c) = v / l(c, c);
      }
  }
  /// Y·L = X for Y, in place: row by row, backward substitution.
  template <int B, class X, class L>
  static void solve_right(X& x, const L& l) {
    const int n = B == Eigen::Dynamic ? static_cast<int>(l.rows()) : B;
    for (int r = 0; r < x.rows(); ++r)
      for (int c = n - 1; c >= 0; --c) {
        double v = x(r, c);
        for (int k = c + 1; k < n; ++k) v -= x(r, k) * l(k, c);
        x(r, c) = v / l(c, c);
      }
  }

  template <int B>
  void solve_with(Eigen::MatrixXd* X) const {
    using ConstMap = Eigen::Map<const Mat<B>>;
    const int nb = sym_.nb;
    const int* cp = sym_.col_ptr.data();
    const int* rw = sym_.row.data();
    const double* v = values_.data();
    const int r = static_cast<int>(X->cols());
    for (int j = 0; j < nb; ++j) {  // L·Y = X
      const int nj = B == Eigen::Dynamic ? size_[j] : B;
      const ConstMap Ljj(v + off_[cp[j]], nj, nj);
      auto Xj = X->middleRows(start_[j], nj);
      for (int t = 0; t < r; ++t)
        for (int c = 0; c < nj; ++c) {
          double e = Xj(c, t);
          for (int k = 0; k < c; ++k) e -= Ljj(c, k) * Xj(k, t);
          Xj(c, t) = e / Ljj(c, c);
        }
      for (int p = cp[j] + 1; p < cp[j + 1]; ++p)
        X->middleRows(start_[rw[p]], size_[rw[p]]).noalias() -=
            ConstMap(v + off_[p], size_[rw[p]], nj) * Xj;
    }
    for (int j = nb - 1; j >= 0; --j) {  // Lᵀ·X = Y
      const int nj = B == Eigen::Dynamic ? size_[j] : B;
      auto Xj = X->middleRows(start_[j], nj);
      for (int p = cp[j] + 1; p < cp[j + 1]; ++p)
        Xj.noalias() -= ConstMap(v + off_[p], size_[rw[p]], nj).transpose() *
                        X->middleRows(start_[rw[p]], size_[rw[p]]);
      const ConstMap Ljj(v + off_[cp[j]], nj, nj);
      for (int t = 0; t < r; ++t)
        for (int c = nj - 1; c >= 0; --c) {
          double e = Xj(c, t);
          for (int k = c + 1; k < nj; ++k) e -= Ljj(k, c) * Xj(k, t);
          Xj(c, t) = e / Ljj(c, c);
        }
    }
  }

  template <int B>
  int factorize_with(const std::vector<double>& hdiag, double tol, double* min_ratio) {
    const int nb = sym_.nb;
    const int* cp = sym_.col_ptr.data();
    const int* rw = sym_.row.data();
    double* v = values_.data();
    *min_ratio = std::numeric_limits<double>::infinity();
    for (int j = 0; j < nb; ++j) {
      const int nj = size_[j];
      for (int p = cp[j]; p < cp[j + 1]; ++p) where_[rw[p]] = p;
      // Left-looking: column j −= L_{≥j,k}·L_jkᵀ for every k < j with L_jk in the pattern; the
      // rows of column k at or below j are all in column j's pattern (symbolic factorisation).
      for (int t = rptr_[j]; t < rptr_[j + 1]; ++t) {
        const int k = rcol_[t], pjk = rslot_[t], nk = size_[k];
        const auto Ljk = at<B>(v, off_[pjk], nj, nk);
        for (int q = pjk; q < cp[k + 1]; ++q) {
          const int i = rw[q];
          at<B>(v, off_[where_[i]], size_[i], nj).noalias() -=
              at<B>(v, off_[q], size_[i], nk) * Ljk.transpose();
        }
      }
      // Diagonal block: unblocked Cholesky with the pivot test on every scalar column.
      auto D = at<B>(v, off_[cp[j]], nj, nj);
      const int n = B == Eigen::Dynamic ? nj : B;
      for (int c = 0; c < n; ++c) {
        double d = D(c, c);
        for (int k = 0; k < c; ++k) d -= D(c, k) * D(c, k);
        const double h = hdiag[start_[j] + c];
        const double ratio = d / h;
        if (ratio < *min_ratio) *min_ratio = ratio;
        if (!std::isfinite(d) || !(h > 0.0) || !(d > tol * h)) return start_[j] + c;
        const double l = std::sqrt(d);
        D(c, c) = l;
        for (int i = c + 1; i < n; ++i) {
          double e = D(i, c);
          for (int k = 0; k < c; ++k) e -= D(i, k) * D(c, k);
          D(i, c) = e / l;
        }
        for (int i = 0; i < c; ++i) D(i, c) = 0.0;
      }
      // Below the diagonal: L_ij = (H_ij − …)·L_jj⁻ᵀ by substitution.
      for (int p = cp[j] + 1; p < cp[j + 1]; ++p) {
        auto X = at<B>(v, off_[p], size_[rw[p]], nj);
        solve_right_transpose<B>(X, D);
      }
    }
    return -1;
  }

  template <int B>
  void takahashi_with(int stop) {
    const int* cp = sym_.col_ptr.data();
    const int* rw = sym_.row.data();
    double* v = values_.data();
    for (int j = sym_.nb - 1; j >= stop; --j) {
      const int nj = size_[j], p0 = cp[j] + 1, p1 = cp[j + 1];
      // Scratch: A_t = L_{i_t j}·L_jj⁻¹ and S_t = Σ_{i_t j}, one block per row below j, laid out
      // as in L's column j (same offsets relative to its first off-diagonal slot).
      double* A = scratch_.data();
      double* S = A + scratch_.size() / 2;
      const std::size_t base = off_[p0];
      const auto Ljj = at<B>(v, off_[cp[j]], nj, nj);
      for (int p = p0; p < p1; ++p) {
        auto Ap = at<B>(A, off_[p] - base, size_[rw[p]], nj);
        Ap = at<B>(v, off_[p], size_[rw[p]], nj);
        solve_right<B>(Ap, Ljj);
      }
      for (int p = p0; p < p1; ++p) {
        const int i = rw[p];
        auto Sp = at<B>(S, off_[p] - base, size_[i], nj);
        Sp.setZero();
        for (int q = p0; q < p1; ++q) {
          const int k = rw[q];
          const auto Aq = at<B>(A, off_[q] - base, size_[k], nj);
          if (i >= k) {  // Σ_ik in column k (i = k: the diagonal block, slot cp[k])
            const int slot = i == k ? cp[k] : find(i, k);
            GEODRIFT_ASSERT(slot >= 0);
            Sp.noalias() -= at<B>(v, off_[slot], size_[i], size_[k]) * Aq;
          } else {  // Σ_ik = Σ_kiᵀ, in column i
            const int slot = find(k, i);
            GEODRIFT_ASSERT(slot >= 0);
            Sp.noalias() -= at<B>(v, off_[slot], size_[k], size_[i]).transpose() * Aq;
          }
        }
      }
      // Σ_jj = L_jj⁻ᵀ·L_jj⁻¹ − Σ_t S_tᵀ·A_t, symmetrised.
      Mat<B> Linv = Mat<B>::Identity(nj, nj);
      solve_right<B>(Linv, Ljj);
      Mat<B> Sjj = Linv.transpose() * Linv;
      for (int p = p0; p < p1; ++p)
        Sjj.noalias() -= at<B>(S, off_[p] - base, size_[rw[p]], nj).transpose() *
                         at<B>(A, off_[p] - base, size_[rw[p]], nj);
      at<B>(v, off_[cp[j]], nj, nj) = 0.5 * (Sjj + Sjj.transpose());
      for (int p = p0; p < p1; ++p)
        at<B>(v, off_[p], size_[rw[p]], nj) = at<B>(S, off_[p] - base, size_[rw[p]], nj);
    }
  }

  /// AMD on the symmetric block pattern (position -> block), as BlockCholeskySolver's.
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
    // Eigen's AMDOrdering yields indices()[new position] = old block.
    return std::vector<int>(P.indices().data(), P.indices().data() + nb);
  }

  BlockSymbolic sym_;
  int uniform_ = 0;                ///< common block size, 0 if the sizes differ
  std::vector<int> size_, start_;  ///< per position: block size, first scalar column
  std::vector<std::size_t> off_;   ///< per slot of L: offset of its block in values_
  std::vector<int> rptr_, rcol_;   ///< row lists of L below the diagonal (CSR) ...
  std::vector<int> rslot_;         ///< ... and the slot of each entry
  std::vector<int> where_;         ///< factorisation: slot of row i in the current column
  std::vector<double> values_;     ///< L's blocks (column-major, back to back), then Σ's
  std::vector<double> scratch_;    ///< takahashi(): A and S of one column
};

}  // namespace detail

/// Marginal covariances of parameter blocks of a Problem (see the file comment for conventions,
/// method, cost and failures). Holds the requested blocks of the last successful compute().
class Covariance {
 public:
  /// A pair of states whose cross-covariance Σ_ab (dof_a × dof_b) is wanted.
  using Pair = std::pair<const void*, const void*>;

  /// @throws InvalidArgument if the options are invalid (CovarianceOptions::validate).
  explicit Covariance(const CovarianceOptions& options = CovarianceOptions()) : options_(options) {
    std::string why;
    GEODRIFT_CHECK(options_.validate(&why), "CovarianceOptions: " << why);
  }

  /// Σ_kk of every state in `blocks` at the problem's current states (finalizes the problem if
  /// needed, with its current Schur-ordering choice; the states are not changed).
  /// @param blocks states (the pointers given to Problem::add_residual_block), non-constant;
  ///        duplicates allowed.
  /// @param why if given, the message on failure (also message()).
  /// @return true on success (status() == kSuccess); false with kRankDeficient or
  ///         kEvaluationFailed. Earlier results are dropped in any case.
  /// @throws InvalidArgument if a state is not a parameter of `problem` or is constant.
  bool compute(Problem& problem, const std::vector<const void*>& blocks,
               std::string* why = nullptr) {
    return compute(problem, blocks, {}, why);
  }

  /// As above, plus the cross-covariances Σ_ab of `pairs` (a ≠ b; a == b gives Σ_aa). Pairs on
  /// the factor's pattern (blocks sharing a residual, and fill-in) come from the recursion; the
  /// others cost one solve with the factor per distinct second state.
  bool compute(Problem& problem, const std::vector<const void*>& blocks,
               const std::vector<Pair>& pairs, std::string* why = nullptr) {
    using Clock = std::chrono::steady_clock;
    const auto seconds = [](Clock::time_point t0) {
      return std::chrono::duration<double>(Clock::now() - t0).count();
    };
    clear();
    if (!problem.is_finalized()) problem.finalize(problem.has_schur_ordering());
    // Validate every request before any work (throws on a bad one).
    const auto index_of = [&problem](const void* x) {
      const ParameterBlock& pb = problem.parameter_block(x);  // throws if unknown
      GEODRIFT_CHECK(!pb.constant, "Covariance: the state at "
                                       << x << " is constant (constant blocks have no covariance)");
      return pb.index;
    };
    std::vector<int> diag_idx;
    diag_idx.reserve(blocks.size());
    for (const void* x : blocks) diag_idx.push_back(index_of(x));
    std::vector<std::pair<int, int>> pair_idx;
    pair_idx.reserve(pairs.size());
    for (const Pair& pr : pairs) pair_idx.emplace_back(index_of(pr.first), index_of(pr.second));

    const BlockStructure& s = problem.structure();
    auto t0 = Clock::now();
    std::vector<double> hdiag;
    {
      BlockSparseMatrix H(&s);
      std::vector<double> g(static_cast<std::size_t>(s.num_cols()));
      double cost = 0.0;
      LinearizeTimes lt;
      EvaluationError err;
      const bool ok = problem.linearize(&H, g.data(), &cost, &lt, &err);
      times_.linearize = seconds(t0);
      if (!ok) return fail(CovarianceStatus::kEvaluationFailed, "Covariance: " + err.what, why);
      t0 = Clock::now();
      factor_.analyze(s);
      times_.analyze = seconds(t0);
      t0 = Clock::now();
      if (!factor_.load(H, &hdiag))
        return fail(CovarianceStatus::kEvaluationFailed,
                    "Covariance: the Gauss-Newton matrix H is not finite", why);
      const int bad = factor_.factorize(hdiag, options_.rank_tolerance, &min_pivot_ratio_);
      times_.factorize = seconds(t0);
      if (bad >= 0) return fail(CovarianceStatus::kRankDeficient, rank_message(problem, bad), why);
      t0 = Clock::now();
      min_eigenvalue_ = smallest_scaled_eigenvalue(H, hdiag);
      times_.rank_check = seconds(t0);
      if (!(min_eigenvalue_ > options_.rank_tolerance))
        return fail(CovarianceStatus::kRankDeficient, rank_message(problem, -1), why);
    }  // H freed: the factor has its own copy

    const detail::BlockSymbolic& sym = factor_.symbolic();
    // Pairs off L's pattern: Σ_{:,b} = H⁻¹·E_b by one solve per distinct b (before Σ overwrites L).
    t0 = Clock::now();
    std::vector<char> on_pattern(pairs.size(), 1);
    std::map<int, std::vector<std::size_t>> by_second;
    for (std::size_t t = 0; t < pairs.size(); ++t) {
      const int qa = sym.inv[pair_idx[t].first], qb = sym.inv[pair_idx[t].second];
      if (qa != qb && factor_.find(std::max(qa, qb), std::min(qa, qb)) < 0) {
        on_pattern[t] = 0;
        by_second[qb].push_back(t);
      }
    }
    for (const auto& [qb, list] : by_second) {
      Eigen::MatrixXd X = Eigen::MatrixXd::Zero(factor_.num_cols(), factor_.size(qb));
      X.middleRows(factor_.start(qb), factor_.size(qb)).setIdentity();
      factor_.solve(&X);
      for (const std::size_t t : list) {
        const int qa = sym.inv[pair_idx[t].first];
        pairs_[pairs[t]] = X.middleRows(factor_.start(qa), factor_.size(qa));
      }
    }
    times_.solve = seconds(t0);

    // Takahashi down to the earliest wanted position.
    t0 = Clock::now();
    int stop = factor_.num_positions();
    for (const int b : diag_idx) stop = std::min(stop, sym.inv[b]);
    for (std::size_t t = 0; t < pairs.size(); ++t)
      if (on_pattern[t])
        stop = std::min({stop, sym.inv[pair_idx[t].first], sym.inv[pair_idx[t].second]});
    factor_.takahashi(stop);
    for (std::size_t t = 0; t < blocks.size(); ++t) {
      const int q = sym.inv[diag_idx[t]];
      diagonal_[blocks[t]] = factor_.block(sym.col_ptr[q]);
    }
    for (std::size_t t = 0; t < pairs.size(); ++t) {
      if (!on_pattern[t]) continue;
      const int qa = sym.inv[pair_idx[t].first], qb = sym.inv[pair_idx[t].second];
      if (qa == qb) {
        pairs_[pairs[t]] = factor_.block(sym.col_ptr[qa]);
      } else if (qa > qb) {  // Σ_ab stored at (a, b)
        pairs_[pairs[t]] = factor_.block(factor_.find(qa, qb));
      } else {
        pairs_[pairs[t]] = factor_.block(factor_.find(qb, qa)).transpose();
      }
    }
    factor_.release();
    times_.inverse = seconds(t0);
    status_ = CovarianceStatus::kSuccess;
    return true;
  }

  CovarianceStatus status() const { return status_; }
  /// Why the last compute() failed (empty on success).
  const std::string& message() const { return message_; }
  const CovarianceTimes& times() const { return times_; }
  /// The smallest Cholesky pivot ratio d_c / H_cc of the last factorisation (+inf before one).
  /// See CovarianceOptions::rank_tolerance.
  double min_pivot_ratio() const { return min_pivot_ratio_; }
  /// Upper estimate of the smallest eigenvalue of the Jacobi-scaled H̃ (unit diagonal) from the
  /// rank test, a conditioning indicator: 1/cond(H̃) ≈ this / λ_max(H̃), λ_max(H̃) ∈ [1, max
  /// nonzeros per row]. NaN before a successful factorisation.
  double min_scaled_eigenvalue() const { return min_eigenvalue_; }
  /// After a kRankDeficient failure found by the factorisation: the state whose pivot failed
  /// (for the caller to name in its own terms; message() gives its address). nullptr otherwise,
  /// e.g. when the eigenvalue estimate found the deficiency.
  const void* rank_deficient_state() const { return deficient_state_; }

  /// Whether Σ_xx of state x is available (requested in the last successful compute()).
  bool has_block(const void* x) const { return diagonal_.count(x) > 0; }

  /// Σ_xx (dof × dof, tangent order of the block's manifold; see the file comment).
  /// @throws InvalidArgument unless x was in `blocks` of the last successful compute().
  Eigen::MatrixXd block(const void* x) const {
    const auto it = diagonal_.find(x);
    GEODRIFT_CHECK(it != diagonal_.end(), "Covariance::block: no covariance for the state at "
                                              << x
                                              << " (not requested, or compute() did not succeed: "
                                              << to_string(status_) << ")");
    return it->second;
  }

  /// Σ_ab (dof_a × dof_b). Available for a pair (a, b) or (b, a) requested in `pairs` (then
  /// transposed as needed), and for a == b requested in `blocks`.
  /// @throws InvalidArgument otherwise.
  Eigen::MatrixXd block(const void* a, const void* b) const {
    auto it = pairs_.find(Pair(a, b));
    if (it != pairs_.end()) return it->second;
    it = pairs_.find(Pair(b, a));
    if (it != pairs_.end()) return it->second.transpose();
    if (a == b && has_block(a)) return block(a);
    GEODRIFT_CHECK(false, "Covariance::block: no cross-covariance for the states at "
                              << a << " and " << b << " (not requested, or compute() did not "
                              << "succeed: " << to_string(status_) << ")");
    return Eigen::MatrixXd();
  }

 private:
  void clear() {
    status_ = CovarianceStatus::kNotComputed;
    message_.clear();
    times_ = CovarianceTimes();
    min_pivot_ratio_ = std::numeric_limits<double>::infinity();
    min_eigenvalue_ = std::numeric_limits<double>::quiet_NaN();
    deficient_state_ = nullptr;
    diagonal_.clear();
    pairs_.clear();
  }

  bool fail(CovarianceStatus status, const std::string& what, std::string* why) {
    status_ = status;
    message_ = what;
    diagonal_.clear();
    pairs_.clear();
    factor_.release();
    if (why) *why = what;
    return false;
  }

  /// The rank-deficiency message: the failing pivot's parameter block and tangent coordinate
  /// (scalar column `col`, elimination order), or with col < 0 the Rayleigh-quotient estimate.
  std::string rank_message(const Problem& problem, int col) {
    std::ostringstream os;
    os << "Covariance: the Gauss-Newton matrix is rank deficient (smallest eigenvalue of the "
          "Jacobi-scaled H <= rank_tolerance "
       << options_.rank_tolerance << "): ";
    if (col >= 0) {
      const detail::BlockSymbolic& sym = factor_.symbolic();
      int q = 0;
      while (factor_.start(q + 1) <= col) ++q;
      const int b = sym.perm[q];
      const void* state = nullptr;
      for (const ParameterBlock& pb : problem.parameter_blocks())
        if (pb.index == b) state = pb.state;
      deficient_state_ = state;
      os << "the Cholesky pivot of tangent coordinate " << col - factor_.start(q)
         << " of the state at " << state << " (free block " << b << " of " << sym.nb
         << ") keeps a fraction " << min_pivot_ratio_
         << " of its information once the blocks eliminated before it are known";
    } else {
      os << "inverse iteration found a direction with Rayleigh quotient " << min_eigenvalue_;
    }
    os << "; a free gauge (fix a pose with Problem::set_constant, or add priors) or an "
          "unobservable direction";
    return os.str();
  }

  /// Upper estimate of λ_min(D^-½·H·D^-½) (see CovarianceOptions::rank_tolerance): inverse
  /// iteration from a fixed pseudo-random start with the factor, then the Rayleigh quotient with
  /// H itself (its upper block storage). hdiag: H's diagonal in elimination order.
  double smallest_scaled_eigenvalue(const BlockSparseMatrix& H,
                                    const std::vector<double>& hdiag) const {
    const BlockStructure& s = H.structure();
    const detail::BlockSymbolic& sym = factor_.symbolic();
    const int n = s.num_cols();
    if (n == 0) return std::numeric_limits<double>::infinity();
    Eigen::VectorXd d(n);  // √H_cc, elimination order
    for (int c = 0; c < n; ++c) d[c] = std::sqrt(hdiag[static_cast<std::size_t>(c)]);
    Eigen::MatrixXd x(n, 1);
    std::mt19937 rng(0x5eed);
    std::normal_distribution<double> normal(0.0, 1.0);
    for (int c = 0; c < n; ++c) x(c, 0) = normal(rng);
    // Each step multiplies the components along H̃'s eigenvectors by 1/λ: a null direction of H
    // (λ ≈ rounding of the factor) outgrows the others by many orders per step.
    for (int it = 0; it < kInverseIterations; ++it) {
      x.col(0) = d.cwiseProduct(x.col(0)) / x.col(0).norm();
      factor_.solve(&x);
      x.col(0) = d.cwiseProduct(x.col(0));
      if (!x.allFinite()) return 0.0;
    }
    x /= x.norm();
    // u = D^-½·x in H's column order; xᵀH̃x = uᵀHu.
    Eigen::VectorXd u(n), y = Eigen::VectorXd::Zero(n);
    for (int b = 0; b < s.num_blocks(); ++b) {
      const int q = sym.inv[b];
      for (int c = 0; c < s.block_size(b); ++c)
        u[s.block_col(b) + c] = x(factor_.start(q) + c, 0) / d[factor_.start(q) + c];
    }
    const auto& bcp = s.block_col_ptr();
    const auto& brow = s.block_rows();
    const auto& boff = s.block_offsets();
    for (int b = 0; b < s.num_blocks(); ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) {
        const int a = brow[k];
        const BlockSparseMatrix::ConstBlockMap Hab(H.values() + boff[k], s.block_size(a),
                                                   s.block_size(b),
                                                   Eigen::OuterStride<>(s.column_height(b)));
        const auto ua = u.segment(s.block_col(a), s.block_size(a));
        const auto ub = u.segment(s.block_col(b), s.block_size(b));
        if (a == b) {
          y.segment(s.block_col(b), s.block_size(b)).noalias() +=
              Hab.selfadjointView<Eigen::Upper>() * ub;
        } else {
          y.segment(s.block_col(a), s.block_size(a)).noalias() += Hab * ub;
          y.segment(s.block_col(b), s.block_size(b)).noalias() += Hab.transpose() * ua;
        }
      }
    return u.dot(y);
  }

  static constexpr int kInverseIterations = 4;

  CovarianceOptions options_;
  CovarianceStatus status_ = CovarianceStatus::kNotComputed;
  std::string message_;
  CovarianceTimes times_;
  double min_pivot_ratio_ = std::numeric_limits<double>::infinity();
  double min_eigenvalue_ = std::numeric_limits<double>::quiet_NaN();
  const void* deficient_state_ = nullptr;
  detail::CovarianceFactor factor_;
  std::unordered_map<const void*, Eigen::MatrixXd> diagonal_;
  std::map<Pair, Eigen::MatrixXd> pairs_;
};

}  // namespace geodrift::solver
