#pragma once

/// @file
/// AVX2 + FMA kernel of Sim3<double>::times_adjoint (M·Ad(S) without forming Ad(S)), the product
/// a Sim(3) pose-graph edge computes three times per linearisation (its Jacobian Jl⁻¹·Ad(dS) and
/// the linked blocks H·Ad(G), Ad(G)ᵀ·H·Ad(G); solver/residual_block.hpp). Each 7-row column of
/// the result is two overlapping 4-wide vectors (rows 0..3 and 3..6, the shared row computed
/// the same way in both), as in solver/detail/block_kernels.hpp; selected at run time by
/// geodrift/detail/avx2.hpp.

#include "geodrift/detail/avx2.hpp"

namespace geodrift::lie::detail {

#ifdef GEODRIFT_AVX2_KERNELS
/// (alo, ahi) (+)= Σ_{k<3} (lo[k], hi[k])·coef[k]: one FMA per 4-wide half and coefficient.
template <bool kInit>
__attribute__((target("avx2,fma"), always_inline)) inline void madd3(const __m256d* lo,
                                                                     const __m256d* hi,
                                                                     const double* coef,
                                                                     __m256d* alo, __m256d* ahi) {
#pragma GCC unroll 3
  for (int k = 0; k < 3; ++k) {
    const __m256d b = _mm256_set1_pd(coef[k]);
    if (kInit && k == 0) {
      *alo = _mm256_mul_pd(lo[0], b);
      *ahi = _mm256_mul_pd(hi[0], b);
    } else {
      *alo = _mm256_fmadd_pd(lo[k], b, *alo);
      *ahi = _mm256_fmadd_pd(hi[k], b, *ahi);
    }
  }
}

/// A 7-row column from its rows 0..3 and 3..6 (the shared row holds the same value in both).
__attribute__((target("avx2,fma"), always_inline)) inline void store_column(double* col,
                                                                            __m256d a_lo,
                                                                            __m256d a_hi) {
  _mm256_storeu_pd(col + 3, a_hi);
  _mm256_storeu_pd(col, a_lo);
}

/// out = M·Ad(S), all column-major (M, out 7×7 in (ω, σ, ν) order; R 3×3), with
///   Ad(S) = [ R  0  0 ; 0  1  0 ; [t]x·R  −t  s·R ]:
///   out_ω = M_ω·R + M_ν·([t]x·R),  out_σ = M_σ − M_ν·t,  out_ν = M_ν·(s·R).
/// out must not alias M. Call only when geodrift::detail::avx2_fma_enabled().
__attribute__((target("avx2,fma"))) inline void sim3_times_adjoint_avx2(const double* M,
                                                                        const double* R,
                                                                        const double* t, double s,
                                                                        double* out) {
  // The coefficients: tR = [t]x·R (column c is t × R.col(c)), −t and s·R.
  double tR[9], sR[9];
  for (int c = 0; c < 3; ++c) {
    const double* r = R + 3 * c;
    tR[3 * c + 0] = t[1] * r[2] - t[2] * r[1];
    tR[3 * c + 1] = t[2] * r[0] - t[0] * r[2];
    tR[3 * c + 2] = t[0] * r[1] - t[1] * r[0];
    for (int k = 0; k < 3; ++k) sR[3 * c + k] = s * r[k];
  }
  const double neg_t[3] = {-t[0], -t[1], -t[2]};
  // Columns of M as rows 0..3 and 3..6.
  __m256d lo[7], hi[7];
#pragma GCC unroll 7
  for (int k = 0; k < 7; ++k) {
    lo[k] = _mm256_loadu_pd(M + 7 * k);
    hi[k] = _mm256_loadu_pd(M + 7 * k + 3);
  }
  __m256d alo, ahi;
#pragma GCC unroll 3
  for (int c = 0; c < 3; ++c) {
    madd3<true>(lo, hi, R + 3 * c, &alo, &ahi);
    madd3<false>(lo + 4, hi + 4, tR + 3 * c, &alo, &ahi);
    store_column(out + 7 * c, alo, ahi);
  }
  alo = lo[3];
  ahi = hi[3];
  madd3<false>(lo + 4, hi + 4, neg_t, &alo, &ahi);
  store_column(out + 21, alo, ahi);
#pragma GCC unroll 3
  for (int c = 0; c < 3; ++c) {
    madd3<true>(lo + 4, hi + 4, sR + 3 * c, &alo, &ahi);
    store_column(out + 28 + 7 * c, alo, ahi);
  }
}
#endif

}  // namespace geodrift::lie::detail
