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
/// out = M·Ad(S), all column-major (M, out 7×7 in (ω, σ, ν) order; R 3×3), with
///   Ad(S) = [ R  0  0 ; 0  1  0 ; [t]x·R  −t  s·R ]:
///   out_ω = M_ω·R + M_ν·([t]x·R),  out_σ = M_σ − M_ν·t,  out_ν = s·M_ν·R.
/// out must not alias M. Call only when geodrift::detail::avx2_fma_enabled().
__attribute__((target("avx2,fma"))) inline void sim3_times_adjoint_avx2(const double* M,
                                                                        const double* R,
                                                                        const double* t, double s,
                                                                        double* out) {
  // tR = [t]x·R: column c is t × R.col(c).
  double tR[9];
  for (int c = 0; c < 3; ++c) {
    const double* r = R + 3 * c;
    tR[3 * c + 0] = t[1] * r[2] - t[2] * r[1];
    tR[3 * c + 1] = t[2] * r[0] - t[0] * r[2];
    tR[3 * c + 2] = t[0] * r[1] - t[1] * r[0];
  }
  const __m256d w0l = _mm256_loadu_pd(M + 0), w0h = _mm256_loadu_pd(M + 3);
  const __m256d w1l = _mm256_loadu_pd(M + 7), w1h = _mm256_loadu_pd(M + 10);
  const __m256d w2l = _mm256_loadu_pd(M + 14), w2h = _mm256_loadu_pd(M + 17);
  const __m256d n0l = _mm256_loadu_pd(M + 28), n0h = _mm256_loadu_pd(M + 31);
  const __m256d n1l = _mm256_loadu_pd(M + 35), n1h = _mm256_loadu_pd(M + 38);
  const __m256d n2l = _mm256_loadu_pd(M + 42), n2h = _mm256_loadu_pd(M + 45);
#pragma GCC unroll 3
  for (int c = 0; c < 3; ++c) {
    const __m256d r0 = _mm256_set1_pd(R[3 * c]), r1 = _mm256_set1_pd(R[3 * c + 1]),
                  r2 = _mm256_set1_pd(R[3 * c + 2]);
    const __m256d q0 = _mm256_set1_pd(tR[3 * c]), q1 = _mm256_set1_pd(tR[3 * c + 1]),
                  q2 = _mm256_set1_pd(tR[3 * c + 2]);
    __m256d lo = _mm256_mul_pd(w0l, r0), hi = _mm256_mul_pd(w0h, r0);
    lo = _mm256_fmadd_pd(w1l, r1, lo);
    hi = _mm256_fmadd_pd(w1h, r1, hi);
    lo = _mm256_fmadd_pd(w2l, r2, lo);
    hi = _mm256_fmadd_pd(w2h, r2, hi);
    lo = _mm256_fmadd_pd(n0l, q0, lo);
    hi = _mm256_fmadd_pd(n0h, q0, hi);
    lo = _mm256_fmadd_pd(n1l, q1, lo);
    hi = _mm256_fmadd_pd(n1h, q1, hi);
    lo = _mm256_fmadd_pd(n2l, q2, lo);
    hi = _mm256_fmadd_pd(n2h, q2, hi);
    _mm256_storeu_pd(out + 7 * c + 3, hi);
    _mm256_storeu_pd(out + 7 * c, lo);
  }
  {
    const __m256d t0 = _mm256_set1_pd(t[0]), t1 = _mm256_set1_pd(t[1]), t2 = _mm256_set1_pd(t[2]);
    __m256d lo = _mm256_loadu_pd(M + 21), hi = _mm256_loadu_pd(M + 24);
    lo = _mm256_fnmadd_pd(n0l, t0, lo);
    hi = _mm256_fnmadd_pd(n0h, t0, hi);
    lo = _mm256_fnmadd_pd(n1l, t1, lo);
    hi = _mm256_fnmadd_pd(n1h, t1, hi);
    lo = _mm256_fnmadd_pd(n2l, t2, lo);
    hi = _mm256_fnmadd_pd(n2h, t2, hi);
    _mm256_storeu_pd(out + 24, hi);
    _mm256_storeu_pd(out + 21, lo);
  }
#pragma GCC unroll 3
  for (int c = 0; c < 3; ++c) {
    const __m256d r0 = _mm256_set1_pd(s * R[3 * c]), r1 = _mm256_set1_pd(s * R[3 * c + 1]),
                  r2 = _mm256_set1_pd(s * R[3 * c + 2]);
    __m256d lo = _mm256_mul_pd(n0l, r0), hi = _mm256_mul_pd(n0h, r0);
    lo = _mm256_fmadd_pd(n1l, r1, lo);
    hi = _mm256_fmadd_pd(n1h, r1, hi);
    lo = _mm256_fmadd_pd(n2l, r2, lo);
    hi = _mm256_fmadd_pd(n2h, r2, hi);
    _mm256_storeu_pd(out + 28 + 7 * c + 3, hi);
    _mm256_storeu_pd(out + 28 + 7 * c, lo);
  }
}
#endif

}  // namespace geodrift::lie::detail
