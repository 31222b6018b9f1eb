#pragma once

/// @file
/// The run-time switch of geodrift's AVX2 + FMA kernels (solver/detail/block_kernels.hpp,
/// lie/detail/sim3_avx2.hpp). They are compiled with __attribute__((target("avx2,fma"))) into
/// code built for baseline x86-64 and used only when the CPU reports both extensions, checked
/// once; GEODRIFT_NO_AVX2=1 in the environment (read once) keeps the portable Eigen code, for
/// A/B measurements. Elsewhere (not x86-64, or a compiler without the attribute) only the
/// portable code exists.

#include <cstdlib>

#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__)
#include <immintrin.h>
#define GEODRIFT_AVX2_KERNELS 1
#endif

namespace geodrift::detail {

/// Whether the AVX2 + FMA kernels are used (CPU support, GEODRIFT_NO_AVX2 unset).
inline bool avx2_fma_enabled() {
#ifdef GEODRIFT_AVX2_KERNELS
  static const bool on = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
                         std::getenv("GEODRIFT_NO_AVX2") == nullptr;
  return on;
#else
  return false;
#endif
}

}  // namespace geodrift::detail
