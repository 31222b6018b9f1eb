#pragma once

/// @file
/// BlockSparseMatrix: the values of a symmetric matrix on a BlockStructure (see
/// block_structure.hpp for the layout and a worked example).

#include <Eigen/Core>
#include <algorithm>
#include <vector>

#include "geodrift/solver/block_structure.hpp"
#include "geodrift/solver/large_array_allocator.hpp"

namespace geodrift::solver {

/// Symmetric block-sparse matrix (normal equations H): a pointer to its (shared, immutable)
/// pattern and one value array, allocated once in reset().
class BlockSparseMatrix {
 public:
  using BlockMap = Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  using ConstBlockMap = Eigen::Map<const Eigen::MatrixXd, 0, Eigen::OuterStride<>>;
  /// The value array (huge pages when large, see large_array_allocator.hpp).
  using ValueVector = std::vector<double, LargeArrayAllocator<double>>;

  BlockSparseMatrix() = default;
  explicit BlockSparseMatrix(const BlockStructure* s) { reset(s); }

  /// Points at pattern `s` (which must outlive this matrix) and sizes the values (zeroed).
  void reset(const BlockStructure* s) {
    structure_ = s;
    values_.assign(static_cast<std::size_t>(s->num_values()), 0.0);
  }

  const BlockStructure& structure() const { return *structure_; }
  int rows() const { return structure_->num_cols(); }
  double* values() { return values_.data(); }
  const double* values() const { return values_.data(); }
  ValueVector& value_vector() { return values_; }

  void set_zero() { std::fill(values_.begin(), values_.end(), 0.0); }

  /// Block H_ab (a ≤ b, in the pattern) as a column-major view with stride h_b.
  BlockMap block(int a, int b) {
    const int off = structure_->block_offset(a, b);
    GEODRIFT_ASSERT(off >= 0);
    return BlockMap(values_.data() + off, structure_->block_size(a), structure_->block_size(b),
                    Eigen::OuterStride<>(structure_->column_height(b)));
  }
  ConstBlockMap block(int a, int b) const {
    const int off = structure_->block_offset(a, b);
    GEODRIFT_ASSERT(off >= 0);
    return ConstBlockMap(values_.data() + off, structure_->block_size(a), structure_->block_size(b),
                         Eigen::OuterStride<>(structure_->column_height(b)));
  }

  /// The full symmetric dense matrix (tests, tiny problems): upper blocks mirrored.
  Eigen::MatrixXd to_dense() const {
    const BlockStructure& s = *structure_;
    Eigen::MatrixXd D = Eigen::MatrixXd::Zero(s.num_cols(), s.num_cols());
    for (int b = 0; b < s.num_blocks(); ++b) {
      for (int k = s.block_col_ptr()[b]; k < s.block_col_ptr()[b + 1]; ++k) {
        const int a = s.block_rows()[k];
        const ConstBlockMap B(values_.data() + s.block_offsets()[k], s.block_size(a),
                              s.block_size(b), Eigen::OuterStride<>(s.column_height(b)));
        if (a == b) {
          // upper triangle is authoritative (what CHOLMOD reads)
          for (int j = 0; j < B.cols(); ++j)
            for (int i = 0; i <= j; ++i)
              D(s.block_col(a) + i, s.block_col(b) + j) =
                  D(s.block_col(b) + j, s.block_col(a) + i) = B(i, j);
        } else {
          D.block(s.block_col(a), s.block_col(b), B.rows(), B.cols()) = B;
          D.block(s.block_col(b), s.block_col(a), B.cols(), B.rows()) = B.transpose();
        }
      }
    }
    return D;
  }

 private:
  const BlockStructure* structure_ = nullptr;
  ValueVector values_;
};

}  // namespace geodrift::solver
