#pragma once

/// @file
/// SchurSolver: solves the BA normal equations by eliminating the 3-dof point blocks.
///
/// With blocks ordered cameras first, points last (BlockStructure::num_eliminated()),
///     H = [ A  B ]      b = [ b_c ]
///         [ Bᵀ C ]          [ b_p ]
/// where C is block-diagonal (no residual couples two points). Then
///     S = A − B·C⁻¹·Bᵀ                 (reduced camera system, factorised by `reduced`)
///     S·x_c = b_c − B·C⁻¹·b_p
///     x_p = C⁻¹·(b_p − Bᵀ·x_c)          (back-substitution, per point)
/// The pattern of S (cameras sharing a point, plus A's own couplings) and every value offset
/// are computed once in analyze(); factorize() only writes values.
///
/// Elimination kernel (per point p, cameras x, y seeing it): C_p = L_p·L_pᵀ (3×3 Cholesky),
/// F_x = B_x·L_p⁻ᵀ (d×3, gathered contiguously), then S_xy −= F_x·F_yᵀ for x ≤ y with
/// compile-time 6×3 / 6×6 kernels when every camera block is 6 wide (SE(3) cameras): the
/// same A − B·C⁻¹·Bᵀ as forming E = B·C⁻¹ first, with one symmetric factor instead of an
/// inverse. C_p⁻¹ = L_p⁻ᵀ·L_p⁻¹ is kept for the right-hand side and the back-substitution.
/// Every buffer is sized in analyze(); factorize() and solve() allocate nothing.
///
/// Reduced camera system. `SchurSolver(ReducedSolver::kAuto)` (what LinearSolverType::kSchur
/// uses) chooses at each analyze(): the BlockCholeskySolver (fixed-size 6×6 / 7×7 kernels, no
/// BLAS call, no per-supernode bookkeeping) when every camera block is 6 or 7 wide and its
/// factor of S has at most kAutoMaxBlocksPerColumn blocks per column on average (the kAuto rule
/// of the full-H solvers), otherwise CHOLMOD (the general path: wide cameras with
/// intrinsics, large dense reduced systems where BLAS-3 supernodes win). The Corrector's
/// sliding-window BA (≈ 30 cameras, S nearly dense: ≤ 16 blocks per column), KITTI 00 (77
/// cameras) and the synthetic 500-camera benchmark all take the block Cholesky; the
/// measurements are round 3 of BENCHMARKS.md's history (`git show 3d5878d:BENCHMARKS.md`),
/// today's BA numbers BENCHMARKS.md "Bundle adjustment".

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/solver/block_cholesky_solver.hpp"
#include "geodrift/solver/cholmod_solver.hpp"
#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

class SchurSolver final : public LinearSolver {
 public:
  /// Which solver factorises the reduced camera system.
  enum class ReducedSolver {
    kAuto,           ///< block Cholesky when thin (see the file comment), else CHOLMOD
    kCholmod,        ///< always CHOLMOD
    kBlockCholesky,  ///< always the block Cholesky (analyze() fails unless cameras are 6 or 7)
  };

  /// @param reduced solver of the reduced camera system (CholmodSolver, BlockCholeskySolver, or
  ///        DenseSolver for tiny problems); owned, used as given.
  explicit SchurSolver(std::unique_ptr<LinearSolver> reduced)
      : mode_(ReducedSolver::kAuto), fixed_(true), reduced_(std::move(reduced)) {}
  /// The reduced solver is chosen by `mode` at each analyze().
  explicit SchurSolver(ReducedSolver mode = ReducedSolver::kAuto) : mode_(mode), fixed_(false) {}

  LinearSolverStatus analyze(const BlockStructure& s) override {
    message_.clear();
    const int nb = s.num_blocks();
    ne_ = s.num_eliminated();
    nc_ = nb - ne_;
    ncs_ = nc_ > 0 ? s.block_col(nc_ - 1) + s.block_size(nc_ - 1) : 0;
    n_ = s.num_cols();
    const auto& bcp = s.block_col_ptr();
    const auto& br = s.block_rows();
    const auto& bo = s.block_offsets();
    uniform6_ = true;
    std::vector<int> sizes(nc_);
    for (int c = 0; c < nc_; ++c) {
      sizes[c] = s.block_size(c);
      uniform6_ = uniform6_ && sizes[c] == 6;
    }
    // Couplings of S.
    std::vector<std::pair<int, int>> couplings;
    for (int b = 0; b < nc_; ++b)
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) couplings.emplace_back(br[k], b);
    point_ptr_.assign(ne_ + 1, 0);
    point_cam_.clear();
    point_boff_.clear();
    for (int q = 0; q < ne_; ++q) {
      const int p = nc_ + q;
      if (s.block_size(p) != 3) {
        message_ = "Schur: eliminated block " + std::to_string(p) + " has size " +
                   std::to_string(s.block_size(p)) + " (must be 3)";
        return LinearSolverStatus::kFatal;
      }
      for (int k = bcp[p]; k < bcp[p + 1] - 1; ++k) {
        if (br[k] >= nc_) {
          message_ = "Schur: points " + std::to_string(br[k]) + " and " + std::to_string(p) +
                     " share a residual; cannot eliminate";
          return LinearSolverStatus::kFatal;
        }
        point_cam_.push_back(br[k]);
        point_boff_.push_back(bo[k]);
      }
      point_ptr_[q + 1] = static_cast<int>(point_cam_.size());
      for (int x = point_ptr_[q]; x < point_ptr_[q + 1]; ++x)
        for (int y = x + 1; y < point_ptr_[q + 1]; ++y)
          couplings.emplace_back(point_cam_[x], point_cam_[y]);
    }
    reduced_structure_.build(sizes, std::move(couplings), 0);
    S_.reset(&reduced_structure_);
    // Offsets: A blocks → S, point pairs → S.
    a_src_.clear();
    a_dst_.clear();
    for (int b = 0; b < nc_; ++b) {
      for (int k = bcp[b]; k < bcp[b + 1]; ++k) {
        a_src_.push_back(bo[k]);
        a_dst_.push_back(reduced_structure_.block_offset(br[k], b));
      }
    }
    pair_ptr_.assign(ne_ + 1, 0);
    pair_off_.clear();
    pair_ld_.clear();
    max_cams_ = 0;
    for (int q = 0; q < ne_; ++q) {
      max_cams_ = std::max(max_cams_, point_ptr_[q + 1] - point_ptr_[q]);
      for (int x = point_ptr_[q]; x < point_ptr_[q + 1]; ++x)
        for (int y = x; y < point_ptr_[q + 1]; ++y) {
          pair_off_.push_back(reduced_structure_.block_offset(point_cam_[x], point_cam_[y]));
          pair_ld_.push_back(reduced_structure_.column_height(point_cam_[y]));
        }
      pair_ptr_[q + 1] = static_cast<int>(pair_off_.size());
    }
    cinv_.resize(ne_);
    point_height_.resize(ne_);
    for (int q = 0; q < ne_; ++q) point_height_[q] = s.column_height(nc_ + q);
    point_diag_.resize(ne_);
    for (int q = 0; q < ne_; ++q) point_diag_[q] = bo[bcp[nc_ + q + 1] - 1];
    cam_col_.resize(nc_);
    for (int c = 0; c < nc_; ++c) cam_col_[c] = s.block_col(c);
    std::size_t max_e = 0;
    for (int q = 0; q < ne_; ++q) {
      std::size_t e = 0;
      for (int x = point_ptr_[q]; x < point_ptr_[q + 1]; ++x) e += 3 * sizes[point_cam_[x]];
      max_e = std::max(max_e, e);
    }
    F_.resize(static_cast<std::size_t>(max_e) + 1);
    rhs_.resize(ncs_);
    xc_.resize(ncs_);
    const LinearSolverStatus st = analyze_reduced();
    if (st != LinearSolverStatus::kSuccess) message_ = "Schur: " + reduced_->message();
    return st;
  }

  LinearSolverStatus factorize(const BlockSparseMatrix& H) override {
    message_.clear();
    H_ = &H;
    S_.set_zero();
    double* sv = S_.values();
    const double* hv = H.values();
    // A → S (whole blocks: same shape in both, different strides).
    {
      const BlockStructure& hs = H.structure();
      std::size_t k = 0;
      for (int b = 0; b < nc_; ++b) {
        const int hb = hs.column_height(b), sb = reduced_structure_.column_height(b);
        for (int kk = hs.block_col_ptr()[b]; kk < hs.block_col_ptr()[b + 1]; ++kk, ++k) {
          const int a = hs.block_rows()[kk];
          for (int j = 0; j < hs.block_size(b); ++j)
            for (int i = 0; i < hs.block_size(a); ++i)
              sv[a_dst_[k] + j * sb + i] = hv[a_src_[k] + j * hb + i];
        }
      }
    }
    const LinearSolverStatus st = uniform6_ ? eliminate6(hv, sv) : eliminate_dynamic(hv, sv);
    if (st != LinearSolverStatus::kSuccess) return st;
    const LinearSolverStatus r = reduced_->factorize(S_);
    if (r != LinearSolverStatus::kSuccess) message_ = "Schur: " + reduced_->message();
    return r;
  }

  LinearSolverStatus solve(const double* b, double* x) override {
    message_.clear();
    const double* hv = H_->values();
    for (int i = 0; i < ncs_; ++i) rhs_[i] = b[i];
    // rhs_c = b_c − Σ_p B_p·C_p⁻¹·b_p
    for (int q = 0; q < ne_; ++q) {
      const Eigen::Vector3d w = cinv_[q] * Eigen::Map<const Eigen::Vector3d>(b + ncs_ + 3 * q);
      const int h = point_height_[q];
      const int x0 = point_ptr_[q], x1 = point_ptr_[q + 1];
      if (uniform6_) {
        const double* B = hv + point_boff_[x0];
        for (int x = x0; x < x1; ++x, B += 6) {
          const Eigen::Map<const Eigen::Matrix<double, 6, 3>, 0, Eigen::OuterStride<>> Bx(
              B, Eigen::OuterStride<>(h));
          Eigen::Map<Eigen::Matrix<double, 6, 1>>(rhs_.data() + cam_col_[point_cam_[x]])
              .noalias() -= Bx * w;
        }
        continue;
      }
      for (int x = x0; x < x1; ++x) {
        const int c = point_cam_[x], d = reduced_structure_.block_size(c);
        const double* B = hv + point_boff_[x];
        for (int j = 0; j < 3; ++j)
          for (int i = 0; i < d; ++i) rhs_[cam_col_[c] + i] -= B[j * h + i] * w[j];
      }
    }
    const LinearSolverStatus st = reduced_->solve(rhs_.data(), xc_.data());
    if (st != LinearSolverStatus::kSuccess) {
      message_ = "Schur: " + reduced_->message();
      return st;
    }
    for (int i = 0; i < ncs_; ++i) x[i] = xc_[i];
    // x_p = C⁻¹·(b_p − Bᵀ·x_c)
    for (int q = 0; q < ne_; ++q) {
      Eigen::Vector3d v = Eigen::Map<const Eigen::Vector3d>(b + ncs_ + 3 * q);
      const int h = point_height_[q];
      const int x0 = point_ptr_[q], x1 = point_ptr_[q + 1];
      if (uniform6_) {
        const double* B = hv + point_boff_[x0];
        for (int x2 = x0; x2 < x1; ++x2, B += 6) {
          const Eigen::Map<const Eigen::Matrix<double, 6, 3>, 0, Eigen::OuterStride<>> Bx(
              B, Eigen::OuterStride<>(h));
          v.noalias() -= Bx.transpose() * Eigen::Map<const Eigen::Matrix<double, 6, 1>>(
                                              xc_.data() + cam_col_[point_cam_[x2]]);
        }
      } else {
        for (int x2 = x0; x2 < x1; ++x2) {
          const int c = point_cam_[x2], d = reduced_structure_.block_size(c);
          const double* B = hv + point_boff_[x2];
          for (int j = 0; j < 3; ++j) {
            double acc = 0.0;
            for (int i = 0; i < d; ++i) acc += B[j * h + i] * xc_[cam_col_[c] + i];
            v[j] -= acc;
          }
        }
      }
      Eigen::Map<Eigen::Vector3d>(x + ncs_ + 3 * q) = cinv_[q] * v;
    }
    return LinearSolverStatus::kSuccess;
  }

  std::string name() const override {
    return "schur+" + (reduced_ ? reduced_->name() : std::string("?"));
  }
  double factor_nnz() const override { return reduced_ ? reduced_->factor_nnz() : 0.0; }
  /// The reduced camera matrix S of the last factorize() (tests).
  const BlockSparseMatrix& reduced_matrix() const { return S_; }
  /// The pattern of S (after analyze()).
  const BlockStructure& reduced_structure() const { return reduced_structure_; }

 private:
  /// Picks (mode_) and analyses the reduced solver.
  LinearSolverStatus analyze_reduced() {
    if (fixed_) return reduced_->analyze(reduced_structure_);
    if (mode_ != ReducedSolver::kCholmod &&
        (mode_ == ReducedSolver::kBlockCholesky ||
         BlockCholeskySolver::supported_block_size(reduced_structure_) != 0)) {
      auto block = std::make_unique<BlockCholeskySolver>();
      const LinearSolverStatus st = block->analyze(reduced_structure_);
      if (mode_ == ReducedSolver::kBlockCholesky ||
          (st == LinearSolverStatus::kSuccess &&
           block->blocks_per_column() <= kAutoMaxBlocksPerColumn)) {
        reduced_ = std::move(block);
        return st;
      }
    }
    if (!reduced_ || reduced_->name() != "cholmod") reduced_ = std::make_unique<CholmodSolver>();
    return reduced_->analyze(reduced_structure_);
  }

  /// Cholesky of the 3×3 point block (upper part of H_pp at Cv, stride h): writes L⁻¹ (lower)
  /// and C⁻¹ = L⁻ᵀL⁻¹; false unless positive definite with finite entries.
  static bool point_inverse(const double* Cv, int h, Eigen::Matrix3d* Linv, Eigen::Matrix3d* Cinv) {
    const double c00 = Cv[0], c01 = Cv[h], c11 = Cv[h + 1], c02 = Cv[2 * h], c12 = Cv[2 * h + 1],
                 c22 = Cv[2 * h + 2];
    if (!(c00 > 0.0)) return false;
    const double l00 = std::sqrt(c00);
    const double l10 = c01 / l00, l20 = c02 / l00;
    const double d1 = c11 - l10 * l10;
    if (!(d1 > 0.0)) return false;
    const double l11 = std::sqrt(d1);
    const double l21 = (c12 - l20 * l10) / l11;
    const double d2 = c22 - l20 * l20 - l21 * l21;
    if (!(d2 > 0.0) || !std::isfinite(d2)) return false;
    const double l22 = std::sqrt(d2);
    // Inverse of the lower triangle.
    const double i00 = 1.0 / l00, i11 = 1.0 / l11, i22 = 1.0 / l22;
    const double i10 = -l10 * i00 * i11;
    const double i21 = -l21 * i11 * i22;
    const double i20 = -(l20 * i00 + l21 * i10) * i22;
    *Linv << i00, 0.0, 0.0, i10, i11, 0.0, i20, i21, i22;
    Cinv->noalias() = Linv->transpose() * (*Linv);
    return Linv->allFinite() && Cinv->allFinite();
  }

  /// Uniform 6-wide cameras: fixed-size kernels, F_x = B_x·L⁻ᵀ gathered in F_ (6×3 blocks,
  /// column-major, contiguous), S_xy −= F_x·F_yᵀ column by column.
  LinearSolverStatus eliminate6(const double* hv, double* sv) {
    using Mat63 = Eigen::Matrix<double, 6, 3>;
    using Vec6 = Eigen::Matrix<double, 6, 1>;
    Mat63* F = reinterpret_cast<Mat63*>(F_.data());
    for (int q = 0; q < ne_; ++q) {
      const int h = point_height_[q];
      Eigen::Matrix3d Linv;
      if (!point_inverse(hv + point_diag_[q], h, &Linv, &cinv_[q])) {
        message_ = "Schur: point block " + std::to_string(q) + " not positive definite";
        return LinearSolverStatus::kNotPositiveDefinite;
      }
      const int x0 = point_ptr_[q], m = point_ptr_[q + 1] - x0;
      // B_x rows are consecutive in the point's column: B_x = rows [6x, 6x + 6) of that column.
      const double* B = hv + point_boff_[x0];
      const Eigen::Matrix3d LinvT = Linv.transpose();
      for (int x = 0; x < m; ++x) {
        const Eigen::Map<const Mat63, 0, Eigen::OuterStride<>> Bx(B + 6 * x,
                                                                  Eigen::OuterStride<>(h));
        F[x].noalias() = Bx * LinvT;
      }
      const int* off = pair_off_.data() + pair_ptr_[q];
      const int* ld = pair_ld_.data() + pair_ptr_[q];
      for (int x = 0; x < m; ++x) {
        const Mat63& Fx = F[x];
        for (int y = x; y < m; ++y, ++off, ++ld) {
          const Mat63& Fy = F[y];
          double* s = sv + *off;
          const int l = *ld;
          for (int j = 0; j < 6; ++j) {
            Eigen::Map<Vec6> col(s + j * l);
            col.noalias() -= Fx.col(0) * Fy(j, 0) + Fx.col(1) * Fy(j, 1) + Fx.col(2) * Fy(j, 2);
          }
        }
      }
    }
    return LinearSolverStatus::kSuccess;
  }

  /// Any camera block sizes (dynamic kernels), same algorithm as eliminate6.
  LinearSolverStatus eliminate_dynamic(const double* hv, double* sv) {
    using BMap = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
    using FMap = Eigen::Map<Eigen::MatrixXd>;
    for (int q = 0; q < ne_; ++q) {
      const int h = point_height_[q];
      Eigen::Matrix3d Linv;
      if (!point_inverse(hv + point_diag_[q], h, &Linv, &cinv_[q])) {
        message_ = "Schur: point block " + std::to_string(q) + " not positive definite";
        return LinearSolverStatus::kNotPositiveDefinite;
      }
      const int x0 = point_ptr_[q], m = point_ptr_[q + 1] - x0;
      const Eigen::Matrix3d LinvT = Linv.transpose();
      int eoff = 0;
      for (int x = 0; x < m; ++x) {
        const int d = reduced_structure_.block_size(point_cam_[x0 + x]);
        const BMap Bx(hv + point_boff_[x0 + x], d, 3, Eigen::OuterStride<>(h));
        FMap(F_.data() + eoff, d, 3).noalias() = Bx * LinvT;
        eoff += 3 * d;
      }
      int k = pair_ptr_[q];
      int ex = 0;
      for (int x = 0; x < m; ++x) {
        const int dx = reduced_structure_.block_size(point_cam_[x0 + x]);
        const FMap Fx(F_.data() + ex, dx, 3);
        int ey = ex;
        for (int y = x; y < m; ++y, ++k) {
          const int dy = reduced_structure_.block_size(point_cam_[x0 + y]);
          const FMap Fy(F_.data() + ey, dy, 3);
          Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> Sxy(
              sv + pair_off_[k], dx, dy, Eigen::OuterStride<>(pair_ld_[k]));
          Sxy.noalias() -= Fx * Fy.transpose();
          ey += 3 * dy;
        }
        ex += 3 * dx;
      }
    }
    return LinearSolverStatus::kSuccess;
  }

  ReducedSolver mode_;
  bool fixed_;
  std::unique_ptr<LinearSolver> reduced_;
  BlockStructure reduced_structure_;
  BlockSparseMatrix S_;
  const BlockSparseMatrix* H_ = nullptr;
  int ne_ = 0, nc_ = 0, ncs_ = 0, n_ = 0, max_cams_ = 0;
  bool uniform6_ = true;
  std::vector<int> point_ptr_, point_cam_, point_boff_, point_height_, point_diag_, cam_col_;
  std::vector<int> pair_ptr_, pair_off_, a_src_, a_dst_;
  std::vector<int> pair_ld_;
  std::vector<Eigen::Matrix3d> cinv_;
  /// F = B·L⁻ᵀ of the current point (Eigen::Matrix<double, 6, 3> blocks in the uniform case).
  std::vector<double, Eigen::aligned_allocator<double>> F_;
  Eigen::VectorXd rhs_, xc_;
};

}  // namespace geodrift::solver
