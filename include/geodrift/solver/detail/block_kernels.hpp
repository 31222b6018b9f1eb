#pragma once

/// @file
/// B×B (B = 6, 7) column-major block products of the block Cholesky factorisation and of its
/// substitutions (block_cholesky_solver.hpp: C −= A·Bᵀ, A ← A·Mᵀ, the transposed gather of
/// H's blocks, y −= L·x, t −= Lᵀ·y), with an AVX2 + FMA variant chosen at run time, and the
/// substitutions with the diagonal triangles. BlockKernelsAvx2::gram also serves the residual
/// blocks' J̃ᵀJ̃ (residual_block.hpp).
///
/// Why. Debian's compiler flags (and the library's users' usual ones) target baseline x86-64,
/// where Eigen's fixed-size 7×7 products use 2-wide SSE2 packets without fused multiply-add;
/// the left-looking factorisation spends most of its time in C −= A·Bᵀ on such blocks. On a CPU
/// with AVX2 and FMA (checked once with __builtin_cpu_supports) the functions below compute each
/// column of C as two overlapping 4-wide vectors (rows 0..3 and B−4..B−1: the shared rows get
/// the same operations in the same order, so the same values) with one FMA per element of B,
/// the way BLAS libraries dispatch kernels. Results differ from the Eigen path only by the
/// rounding of the fused operations. GEODRIFT_NO_AVX2=1 in the environment keeps the Eigen path
/// (geodrift/detail/avx2.hpp).

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "geodrift/detail/avx2.hpp"

namespace geodrift::solver::detail {

/// Whether the AVX2 + FMA kernels are used (geodrift/detail/avx2.hpp).
inline bool block_kernels_avx2() { return ::geodrift::detail::avx2_fma_enabled(); }

/// Cholesky of the B×B column-major block D in place (its lower triangle is read; on return
/// D = L with zeros above the diagonal) and Li = L⁻¹ (lower triangular). False when D is not
/// positive definite, not finite, or L⁻¹ overflows. Plain loops with compile-time bounds:
/// Eigen's LLT is fixed-size, but L⁻¹ by LLT::matrixL().solveInPlace() goes through its
/// dynamic-size triangular solver.
template <int B>
inline bool cholesky_inverse(double* D, double* Li) {
  for (int i = 0; i < B * B; ++i)
    if (!std::isfinite(D[i])) return false;
  for (int j = 0; j < B; ++j) {
    double d = D[j + j * B];
    for (int k = 0; k < j; ++k) d -= D[j + k * B] * D[j + k * B];
    if (!(d > 0.0)) return false;
    const double ljj = std::sqrt(d), inv = 1.0 / ljj;
    D[j + j * B] = ljj;
    for (int i = j + 1; i < B; ++i) {
      double v = D[i + j * B];
      for (int k = 0; k < j; ++k) v -= D[i + k * B] * D[j + k * B];
      D[i + j * B] = v * inv;
    }
    for (int i = 0; i < j; ++i) D[i + j * B] = 0.0;
  }
  double inv_diag[B];  // 1/L_ii: the substitution multiplies (B(B−1)/2 divisions fewer)
  for (int i = 0; i < B; ++i) inv_diag[i] = 1.0 / D[i + i * B];
  for (int c = 0; c < B; ++c) {
    for (int i = 0; i < c; ++i) Li[i + c * B] = 0.0;
    Li[c + c * B] = inv_diag[c];
    for (int i = c + 1; i < B; ++i) {
      double v = 0.0;
      for (int k = c; k < i; ++k) v -= D[i + k * B] * Li[k + c * B];
      Li[i + c * B] = v * inv_diag[i];
    }
  }
  for (int i = 0; i < B * B; ++i)
    if (!std::isfinite(Li[i])) return false;
  return true;
}

/// y ← L⁻¹·y (lower_solve) and y ← L⁻ᵀ·y (lower_transpose_solve) by substitution with the B×B
/// lower triangle L of cholesky_inverse() and the diagonal of its Li (1/L_ii). The solves use
/// these rather than the products with Li: substitution is backward stable, while the product
/// with an explicit inverse loses accuracy with the block's condition number (on the
/// ill-conditioned reduced camera system of a 3-camera BAL subset it stopped LM 10× further
/// from the optimum by the gradient bound, solver_data tests).
/// `stride`: L's column stride (B for a contiguous block; the column height of H's panel for the
/// in-place factor).
template <int B>
inline void lower_solve(const double* L, const double* Li, double* y, int stride = B) {
  for (int i = 0; i < B; ++i) {
    double v = y[i];
    for (int k = 0; k < i; ++k) v -= L[i + k * stride] * y[k];
    y[i] = v * Li[i + i * B];
  }
}
template <int B>
inline void lower_transpose_solve(const double* L, const double* Li, double* y, int stride = B) {
  for (int i = B - 1; i >= 0; --i) {
    double v = y[i];
    for (int k = i + 1; k < B; ++k) v -= L[k + i * stride] * y[k];
    y[i] = v * Li[i + i * B];
  }
}

/// Portable kernels (Eigen fixed size). L points at B×B column-major blocks stored back to back.
template <int B>
struct BlockKernelsEigen {
  using Mat = Eigen::Matrix<double, B, B>;
  using Map = Eigen::Map<Mat>;
  using ConstMap = Eigen::Map<const Mat>;
  /// C_slot(q) −= L_q·L_pᵀ for q in [p, end): slot(q) = slot_of_row[row[q]].
  static void update(double* L, int p, int end, const int* row, const int* slot_of_row) {
    const Mat LpT = ConstMap(L + p * B * B).transpose();
    for (int q = p; q < end; ++q)
      Map(L + slot_of_row[row[q]] * B * B).noalias() -= ConstMap(L + q * B * B) * LpT;
  }
  /// L_q ← L_q·Mᵀ for q in [begin, end).
  static void scale(double* L, int begin, int end, const double* M) {
    const Mat MT = ConstMap(M).transpose();
    for (int q = begin; q < end; ++q) {
      const Mat t = ConstMap(L + q * B * B) * MT;
      Map(L + q * B * B) = t;
    }
  }

  /// dst = Aᵀ for a B×B block A of H (column-major with column stride `stride`).
  static void load_transposed(const double* A, int stride, double* dst) {
    Map out(dst);
    out = Eigen::Map<const Mat, 0, Eigen::OuterStride<>>(A, B, B, Eigen::OuterStride<>(stride))
              .transpose();
  }

  // The substitutions of the solves; y and t hold B-vectors back to back (block row r at y + r·B).
  using Vec = Eigen::Matrix<double, B, 1>;
  /// y_row(q) −= L_q·x for q in [begin, end) (forward substitution; x is not one of those y).
  static void lower_update(const double* L, int begin, int end, const int* row, const double* x,
                           double* y) {
    const Eigen::Map<const Vec> xv(x);
    for (int q = begin; q < end; ++q)
      Eigen::Map<Vec>(y + row[q] * B).noalias() -= ConstMap(L + q * B * B) * xv;
  }
  /// t −= Σ_q L_qᵀ·y_row(q) for q in [begin, end) (backward substitution).
  static void transpose_update(const double* L, int begin, int end, const int* row, const double* y,
                               double* t) {
    Eigen::Map<Vec> tv(t);
    for (int q = begin; q < end; ++q)
      tv.noalias() -= ConstMap(L + q * B * B).transpose() * Eigen::Map<const Vec>(y + row[q] * B);
  }

  // The in-place factor's kernels (BlockFactor::factorize_in_place): its blocks live in H's
  // panels, column-major with a run-time column stride; C and M are contiguous B×B blocks.
  using Strided = Eigen::Map<Mat, 0, Eigen::OuterStride<>>;
  using ConstStrided = Eigen::Map<const Mat, 0, Eigen::OuterStride<>>;
  /// C −= Σ_{q < count} A[q]·Bq[q]ᵀ (A[q] with column stride sa, Bq[q] with column stride sb).
  static void nt_sum(double* C, int count, const double* const* A, int sa, const double* const* Bq,
                     int sb) {
    Map c(C);
    for (int q = 0; q < count; ++q)
      c.noalias() -= ConstStrided(A[q], B, B, Eigen::OuterStride<>(sa)) *
                     ConstStrided(Bq[q], B, B, Eigen::OuterStride<>(sb)).transpose();
  }
  /// out (column stride so) = C·Mᵀ.
  static void scale_store(const double* C, const double* M, double* out, int so) {
    Strided(out, B, B, Eigen::OuterStride<>(so)).noalias() = ConstMap(C) * ConstMap(M).transpose();
  }
  /// t −= Σ_{q < count} L_q·y_blk[q], L_q at values + off[q] with column stride s.
  static void row_mat_vec_sub(const double* values, const int* off, int s, const int* blk,
                              int count, const double* y, double* t) {
    Eigen::Map<Vec> tv(t);
    for (int q = 0; q < count; ++q)
      tv.noalias() -= ConstStrided(values + off[q], B, B, Eigen::OuterStride<>(s)) *
                      Eigen::Map<const Vec>(y + B * blk[q]);
  }
  /// t −= Σ_{q < count} L_qᵀ·y_blk[q], L_q at values + off[q] with column stride stride[q].
  static void transpose_gather(const double* values, const int* off, const int* stride,
                               const int* blk, int count, const double* y, double* t) {
    Eigen::Map<Vec> tv(t);
    for (int q = 0; q < count; ++q)
      tv.noalias() -=
          ConstStrided(values + off[q], B, B, Eigen::OuterStride<>(stride[q])).transpose() *
          Eigen::Map<const Vec>(y + B * blk[q]);
  }
};

#ifdef GEODRIFT_AVX2_KERNELS
/// The same with AVX2 + FMA (call only when block_kernels_avx2()).
template <int B>
struct BlockKernelsAvx2 {
  static_assert(B >= 4 && B <= 8, "two overlapping 4-wide vectors per column");
  static constexpr int kHi = B - 4;  ///< first row of the second vector

  /// Column c of A·Bᵀ added to (kSub = false) or subtracted from (kSub = true) lo/hi.
  template <bool kSub>
  __attribute__((target("avx2,fma"), always_inline)) static inline void column(const double* A,
                                                                               const double* Bm,
                                                                               int c, __m256d* lo,
                                                                               __m256d* hi) {
#pragma GCC unroll 8
    for (int k = 0; k < B; ++k) {
      const __m256d b = _mm256_broadcast_sd(Bm + k * B + c);  // Bm(c, k)
      const __m256d a_lo = _mm256_loadu_pd(A + k * B);
      const __m256d a_hi = _mm256_loadu_pd(A + k * B + kHi);
      if (kSub) {
        *lo = _mm256_fnmadd_pd(a_lo, b, *lo);
        *hi = _mm256_fnmadd_pd(a_hi, b, *hi);
      } else {
        *lo = _mm256_fmadd_pd(a_lo, b, *lo);
        *hi = _mm256_fmadd_pd(a_hi, b, *hi);
      }
    }
  }

  __attribute__((target("avx2,fma"))) static void update(double* L, int p, int end, const int* row,
                                                         const int* slot_of_row) {
    const double* Lp = L + p * B * B;
    for (int q = p; q < end; ++q) {
      const double* A = L + q * B * B;
      double* C = L + slot_of_row[row[q]] * B * B;  // never A or Lp (a later block column)
#pragma GCC unroll 8
      for (int c = 0; c < B; ++c) {
        __m256d lo = _mm256_loadu_pd(C + c * B), hi = _mm256_loadu_pd(C + c * B + kHi);
        column<true>(A, Lp, c, &lo, &hi);
        _mm256_storeu_pd(C + c * B, lo);
        _mm256_storeu_pd(C + c * B + kHi, hi);
      }
    }
  }

  __attribute__((target("avx2,fma"))) static void scale(double* L, int begin, int end,
                                                        const double* M) {
    double t[B * B];
    for (int q = begin; q < end; ++q) {
      double* A = L + q * B * B;
#pragma GCC unroll 8
      for (int c = 0; c < B; ++c) {
        __m256d lo = _mm256_setzero_pd(), hi = _mm256_setzero_pd();
        column<false>(A, M, c, &lo, &hi);
        _mm256_storeu_pd(t + c * B, lo);
        _mm256_storeu_pd(t + c * B + kHi, hi);
      }
      std::memcpy(A, t, sizeof(t));
    }
  }

  /// dst = Aᵀ as four (overlapping) 4×4 transposes of rows/columns {0..3, B−4..B−1}: the
  /// overlaps copy the same elements twice.
  __attribute__((target("avx2,fma"))) static void load_transposed(const double* A, int stride,
                                                                  double* dst) {
    constexpr int kStart[2] = {0, kHi};
#pragma GCC unroll 2
    for (int rb = 0; rb < 2; ++rb) {
#pragma GCC unroll 2
      for (int cb = 0; cb < 2; ++cb) {
        const int r0 = kStart[rb], c0 = kStart[cb];
        const double* a = A + static_cast<std::ptrdiff_t>(c0) * stride + r0;
        const __m256d a0 = _mm256_loadu_pd(a), a1 = _mm256_loadu_pd(a + stride),
                      a2 = _mm256_loadu_pd(a + 2 * stride), a3 = _mm256_loadu_pd(a + 3 * stride);
        const __m256d t0 = _mm256_unpacklo_pd(a0, a1), t1 = _mm256_unpackhi_pd(a0, a1);
        const __m256d t2 = _mm256_unpacklo_pd(a2, a3), t3 = _mm256_unpackhi_pd(a2, a3);
        double* d = dst + r0 * B + c0;  // dst column r0 + i holds row r0 + i of A
        _mm256_storeu_pd(d, _mm256_permute2f128_pd(t0, t2, 0x20));
        _mm256_storeu_pd(d + B, _mm256_permute2f128_pd(t1, t3, 0x20));
        _mm256_storeu_pd(d + 2 * B, _mm256_permute2f128_pd(t0, t2, 0x31));
        _mm256_storeu_pd(d + 3 * B, _mm256_permute2f128_pd(t1, t3, 0x31));
      }
    }
  }

  /// Lanes of the second vector that repeat rows of the first (0 there, all ones elsewhere): a
  /// dot product over both vectors counts every row once with the second one masked by it.
  __attribute__((target("avx2,fma"), always_inline)) static inline __m256d hi_mask() {
    alignas(32) static constexpr std::int64_t m[4] = {kHi >= 4 ? -1 : 0, kHi + 1 >= 4 ? -1 : 0,
                                                      kHi + 2 >= 4 ? -1 : 0, kHi + 3 >= 4 ? -1 : 0};
    return _mm256_load_pd(reinterpret_cast<const double*>(m));
  }
  __attribute__((target("avx2,fma"), always_inline)) static inline double hsum(__m256d a) {
    __m128d s = _mm_add_pd(_mm256_castpd256_pd128(a), _mm256_extractf128_pd(a, 1));
    return _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)));
  }

  /// M = JᵀJ (full, symmetric to the bit) for a B×B column-major J: with Jt = Jᵀ (one
  /// load_transposed), column c of M is Σ_k Jt(:, k)·Jt(c, k), the update's column kernel. For
  /// the residual blocks' H_ii = J̃ᵀJ̃ (residual_block.hpp, detail::gram).
  __attribute__((target("avx2,fma"))) static void gram(const double* J, double* M) {
    double Jt[B * B];
    load_transposed(J, B, Jt);
#pragma GCC unroll 8
    for (int c = 0; c < B; ++c) {
      __m256d lo = _mm256_setzero_pd(), hi = _mm256_setzero_pd();
      column<false>(Jt, Jt, c, &lo, &hi);
      _mm256_storeu_pd(M + c * B + kHi, hi);  // the shared rows hold the same values in both
      _mm256_storeu_pd(M + c * B, lo);
    }
  }

  __attribute__((target("avx2,fma"))) static void lower_update(const double* L, int begin, int end,
                                                               const int* row, const double* x,
                                                               double* y) {
    __m256d xb[B];
#pragma GCC unroll 8
    for (int k = 0; k < B; ++k) xb[k] = _mm256_broadcast_sd(x + k);
    for (int q = begin; q < end; ++q) {
      const double* A = L + q * B * B;
      double* yr = y + row[q] * B;
      __m256d lo = _mm256_loadu_pd(yr), hi = _mm256_loadu_pd(yr + kHi);
#pragma GCC unroll 8
      for (int k = 0; k < B; ++k) {
        lo = _mm256_fnmadd_pd(_mm256_loadu_pd(A + k * B), xb[k], lo);
        hi = _mm256_fnmadd_pd(_mm256_loadu_pd(A + k * B + kHi), xb[k], hi);
      }
      _mm256_storeu_pd(yr + kHi, hi);  // the shared rows hold the same values in both
      _mm256_storeu_pd(yr, lo);
    }
  }

  /// t −= Σ_{q < count} A_qᵀ·y_q with one accumulator per column of A_q (the repeated rows of
  /// y_q masked) and one horizontal sum per column at the end; pair(q, &A, &s, &y) names the
  /// q-th block (column stride s) and vector.
  template <class Pair>
  __attribute__((target("avx2,fma"), always_inline)) static inline void transpose_sum(
      int count, const Pair& pair, double* t) {
    if (count <= 0) return;
    const __m256d mask = hi_mask();
    __m256d acc[B];
#pragma GCC unroll 8
    for (int c = 0; c < B; ++c) acc[c] = _mm256_setzero_pd();
    for (int q = 0; q < count; ++q) {
      const double* A;
      const double* yr;
      int s;
      pair(q, &A, &s, &yr);
      const __m256d lo = _mm256_loadu_pd(yr), hi = _mm256_and_pd(_mm256_loadu_pd(yr + kHi), mask);
#pragma GCC unroll 8
      for (int c = 0; c < B; ++c) {
        acc[c] = _mm256_fmadd_pd(_mm256_loadu_pd(A + c * s), lo, acc[c]);
        acc[c] = _mm256_fmadd_pd(_mm256_loadu_pd(A + c * s + kHi), hi, acc[c]);
      }
    }
#pragma GCC unroll 8
    for (int c = 0; c < B; ++c) t[c] -= hsum(acc[c]);
  }
  __attribute__((target("avx2,fma"))) static void transpose_update(const double* L, int begin,
                                                                   int end, const int* row,
                                                                   const double* y, double* t) {
    transpose_sum(
        end - begin,
        [&](int q, const double** A, int* s, const double** yr) {
          *A = L + (begin + q) * B * B;
          *s = B;
          *yr = y + row[begin + q] * B;
        },
        t);
  }

  // The in-place factor's kernels (see BlockKernelsEigen).
  /// Columns [C0, C1) of C −= Σ_q A[q]·Bq[q]ᵀ, kept in registers over all q: per column t of
  /// A[q] two loads and, per column of C, one broadcast and two FMAs (the per-block update()
  /// loads and stores C once per block).
  template <int C0, int C1>
  __attribute__((target("avx2,fma"), always_inline)) static inline void nt_columns(
      double* C, int count, const double* const* A, int sa, const double* const* Bq, int sb) {
    constexpr int kN = C1 - C0;
    __m256d lo[kN], hi[kN];
#pragma GCC unroll 4
    for (int c = 0; c < kN; ++c) {
      lo[c] = _mm256_loadu_pd(C + (C0 + c) * B);
      hi[c] = _mm256_loadu_pd(C + (C0 + c) * B + kHi);
    }
    for (int q = 0; q < count; ++q) {
      const double* a = A[q];
      const double* b = Bq[q];
#pragma GCC unroll 8
      for (int t = 0; t < B; ++t) {
        const __m256d a_lo = _mm256_loadu_pd(a + t * sa), a_hi = _mm256_loadu_pd(a + t * sa + kHi);
#pragma GCC unroll 4
        for (int c = 0; c < kN; ++c) {
          const __m256d bb = _mm256_broadcast_sd(b + t * sb + C0 + c);  // Bq(C0 + c, t)
          lo[c] = _mm256_fnmadd_pd(a_lo, bb, lo[c]);
          hi[c] = _mm256_fnmadd_pd(a_hi, bb, hi[c]);
        }
      }
    }
#pragma GCC unroll 4
    for (int c = 0; c < kN; ++c) {
      _mm256_storeu_pd(C + (C0 + c) * B + kHi, hi[c]);  // the shared rows hold the same values
      _mm256_storeu_pd(C + (C0 + c) * B, lo[c]);
    }
  }
  __attribute__((target("avx2,fma"))) static void nt_sum(double* C, int count,
                                                         const double* const* A, int sa,
                                                         const double* const* Bq, int sb) {
    constexpr int kHalf = (B + 1) / 2;  // 8 + 2 + 1 registers at most
    nt_columns<0, kHalf>(C, count, A, sa, Bq, sb);
    nt_columns<kHalf, B>(C, count, A, sa, Bq, sb);
  }
  __attribute__((target("avx2,fma"))) static void scale_store(const double* C, const double* M,
                                                              double* out, int so) {
#pragma GCC unroll 8
    for (int c = 0; c < B; ++c) {
      __m256d lo = _mm256_setzero_pd(), hi = _mm256_setzero_pd();
      column<false>(C, M, c, &lo, &hi);
      _mm256_storeu_pd(out + c * so + kHi, hi);
      _mm256_storeu_pd(out + c * so, lo);
    }
  }
  /// t kept in registers over all q (a load of t after the previous block's two overlapping
  /// stores would not be store-forwarded), in four accumulator pairs (column k of each block
  /// into pair k mod 4) so that the FMAs do not wait on each other's latency.
  __attribute__((target("avx2,fma"))) static void row_mat_vec_sub(const double* values,
                                                                  const int* off, int s,
                                                                  const int* blk, int count,
                                                                  const double* y, double* t) {
    __m256d lo[4] = {_mm256_loadu_pd(t), _mm256_setzero_pd(), _mm256_setzero_pd(),
                     _mm256_setzero_pd()};
    __m256d hi[4] = {_mm256_loadu_pd(t + kHi), _mm256_setzero_pd(), _mm256_setzero_pd(),
                     _mm256_setzero_pd()};
    for (int q = 0; q < count; ++q) {
      const double* L = values + off[q];
      const double* x = y + B * blk[q];
#pragma GCC unroll 8
      for (int k = 0; k < B; ++k) {
        const __m256d xb = _mm256_broadcast_sd(x + k);
        lo[k % 4] = _mm256_fnmadd_pd(_mm256_loadu_pd(L + k * s), xb, lo[k % 4]);
        hi[k % 4] = _mm256_fnmadd_pd(_mm256_loadu_pd(L + k * s + kHi), xb, hi[k % 4]);
      }
    }
    const __m256d l = _mm256_add_pd(_mm256_add_pd(lo[0], lo[1]), _mm256_add_pd(lo[2], lo[3]));
    const __m256d h = _mm256_add_pd(_mm256_add_pd(hi[0], hi[1]), _mm256_add_pd(hi[2], hi[3]));
    _mm256_storeu_pd(t + kHi, h);  // the shared row: the same operations in lo and hi
    _mm256_storeu_pd(t, l);
  }
  __attribute__((target("avx2,fma"))) static void transpose_gather(const double* values,
                                                                   const int* off,
                                                                   const int* stride,
                                                                   const int* blk, int count,
                                                                   const double* y, double* t) {
    transpose_sum(
        count,
        [&](int q, const double** A, int* s, const double** yr) {
          *A = values + off[q];
          *s = stride[q];
          *yr = y + blk[q] * B;
        },
        t);
  }
};
#endif

}  // namespace geodrift::solver::detail
