#pragma once

/// @file
/// Allocator for the solver's large per-problem arrays (H values, the block Cholesky factor,
/// the geodesic-acceleration Jacobian store): arrays of at least kHugePageThreshold bytes are
/// aligned to 2 MiB and, on Linux, marked MADV_HUGEPAGE, so that first touching them costs one
/// page fault per 2 MiB instead of per 4 KiB (transparent huge pages in "madvise" mode, the
/// Debian default). A 10k-keyframe Sim(3) graph first-touches ~200 MB per solve; with 4 KiB
/// pages that is ~50k faults (BENCHMARKS.md). Smaller arrays use the ordinary aligned new.
/// Purely a performance hint: where huge pages are unavailable madvise fails silently and
/// nothing else changes.

#include <cstddef>
#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace geodrift::solver {

inline constexpr std::size_t kHugePageSize = std::size_t{2} << 20;
inline constexpr std::size_t kHugePageThreshold = std::size_t{4} << 20;

template <typename T>
struct HugePageAllocator {
  using value_type = T;
  static constexpr std::size_t kAlign = alignof(T) > 64 ? alignof(T) : 64;

  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kHugePageThreshold)
      return static_cast<T*>(::operator new(bytes, std::align_val_t(kAlign)));
    const std::size_t rounded = (bytes + kHugePageSize - 1) / kHugePageSize * kHugePageSize;
    void* p = std::aligned_alloc(kHugePageSize, rounded);
    if (!p) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    ::madvise(p, rounded, MADV_HUGEPAGE);  // a hint: failure changes nothing but speed
#endif
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (n * sizeof(T) < kHugePageThreshold)
      ::operator delete(p, std::align_val_t(kAlign));
    else
      std::free(p);
  }
  template <typename U>
  bool operator==(const HugePageAllocator<U>&) const noexcept {
    return true;
  }
  template <typename U>
  bool operator!=(const HugePageAllocator<U>&) const noexcept {
    return false;
  }
};

}  // namespace geodrift::solver
