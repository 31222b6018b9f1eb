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

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/solver/linear_solver.hpp"

namespace geodrift::solver {

class SchurSolver final : public LinearSolver {
 public:
  /// @param reduced solver of the reduced camera system (CholmodSolver, or DenseSolver for tiny
  ///        problems); owned.
  explicit SchurSolver(std::unique_ptr<LinearSolver> reduced) : reduced_(std::move(reduced)) {}

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
    max_cams_ = 0;
    for (int q = 0; q < ne_; ++q) {
      max_cams_ = std::max(max_cams_, point_ptr_[q + 1] - point_ptr_[q]);
      for (int x = point_ptr_[q]; x < point_ptr_[q + 1]; ++x)
        for (int y = x; y < point_ptr_[q + 1]; ++y)
          pair_off_.push_back(reduced_structure_.block_offset(point_cam_[x], point_cam_[y]));
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
    E_.resize(max_e + 1);
    rhs_.resize(ncs_);
    xc_.resize(ncs_);
    const LinearSolverStatus st = reduced_->analyze(reduced_structure_);
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
    const LinearSolverStatus st =
        uniform6_ ? eliminate<6>(hv, sv) : eliminate<Eigen::Dynamic>(hv, sv);
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
      for (int x = point_ptr_[q]; x < point_ptr_[q + 1]; ++x) {
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
      for (int x2 = point_ptr_[q]; x2 < point_ptr_[q + 1]; ++x2) {
        const int c = point_cam_[x2], d = reduced_structure_.block_size(c);
        const double* B = hv + point_boff_[x2];
        for (int j = 0; j < 3; ++j) {
          double acc = 0.0;
          for (int i = 0; i < d; ++i) acc += B[j * h + i] * xc_[cam_col_[c] + i];
          v[j] -= acc;
        }
      }
      Eigen::Map<Eigen::Vector3d>(x + ncs_ + 3 * q) = cinv_[q] * v;
    }
    return LinearSolverStatus::kSuccess;
  }

  std::string name() const override { return "schur+" + reduced_->name(); }
  double factor_nnz() const override { return reduced_->factor_nnz(); }
  /// The reduced camera matrix S of the last factorize() (tests).
  const BlockSparseMatrix& reduced_matrix() const { return S_; }

 private:
  template <int D>
  LinearSolverStatus eliminate(const double* hv, double* sv) {
    using MatD3 = Eigen::Matrix<double, D, 3>;
    using BMap = Eigen::Map<const MatD3, 0, Eigen::OuterStride<>>;
    for (int q = 0; q < ne_; ++q) {
      const int h = point_height_[q];
      const double* Cv = hv + point_diag_[q];
      Eigen::Matrix3d C;
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i <= j; ++i) C(i, j) = C(j, i) = Cv[j * h + i];
      const Eigen::LLT<Eigen::Matrix3d> llt(C);
      if (llt.info() != Eigen::Success || !(C.diagonal().array() > 0.0).all()) {
        message_ = "Schur: point block " + std::to_string(q) + " not positive definite";
        return LinearSolverStatus::kNotPositiveDefinite;
      }
      cinv_[q] = llt.solve(Eigen::Matrix3d::Identity());
      const int x0 = point_ptr_[q], m = point_ptr_[q + 1] - x0;
      // E_x = B_x·C⁻¹ (d×3), stored contiguously column-major in E_.
      int eoff = 0;
      for (int x = 0; x < m; ++x) {
        const int d = D == Eigen::Dynamic ? reduced_structure_.block_size(point_cam_[x0 + x]) : D;
        const BMap B(hv + point_boff_[x0 + x], d, 3, Eigen::OuterStride<>(h));
        Eigen::Map<MatD3>(E_.data() + eoff, d, 3).noalias() = B * cinv_[q];
        eoff += 3 * d;
      }
      // S_xy −= E_x·B_yᵀ for x ≤ y.
      int k = pair_ptr_[q];
      int ex = 0;
      for (int x = 0; x < m; ++x) {
        const int cx = point_cam_[x0 + x];
        const int dx = D == Eigen::Dynamic ? reduced_structure_.block_size(cx) : D;
        const Eigen::Map<const MatD3> Ex(E_.data() + ex, dx, 3);
        for (int y = x; y < m; ++y, ++k) {
          const int cy = point_cam_[x0 + y];
          const int dy = D == Eigen::Dynamic ? reduced_structure_.block_size(cy) : D;
          const BMap By(hv + point_boff_[x0 + y], dy, 3, Eigen::OuterStride<>(h));
          Eigen::Map<Eigen::Matrix<double, D, D>, 0, Eigen::OuterStride<>> Sxy(
              sv + pair_off_[k], dx, dy,
              Eigen::OuterStride<>(reduced_structure_.column_height(cy)));
          Sxy.noalias() -= Ex * By.transpose();
        }
        ex += 3 * dx;
      }
    }
    return LinearSolverStatus::kSuccess;
  }

  std::unique_ptr<LinearSolver> reduced_;
  BlockStructure reduced_structure_;
  BlockSparseMatrix S_;
  const BlockSparseMatrix* H_ = nullptr;
  int ne_ = 0, nc_ = 0, ncs_ = 0, n_ = 0, max_cams_ = 0;
  bool uniform6_ = true;
  std::vector<int> point_ptr_, point_cam_, point_boff_, point_height_, point_diag_, cam_col_;
  std::vector<int> pair_ptr_, pair_off_, a_src_, a_dst_;
  std::vector<Eigen::Matrix3d> cinv_;
  std::vector<double> E_;
  Eigen::VectorXd rhs_, xc_;
};

}  // namespace geodrift::solver
