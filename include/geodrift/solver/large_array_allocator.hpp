#pragma once

/// @file
/// LargeArrayAllocator: the allocator of the solver's big per-problem arrays (the values of H
/// and of its speculative twin, the block Cholesky factor, the geodesic-acceleration store).
///
/// Why: a solve first-touches all of these once. With 4 KiB pages that is one page fault per
/// 4 KiB, and on a virtual machine a fault is expensive: 11 µs per 4 KiB page measured on the
/// project's 2-core VM (BENCHMARKS.md, round 6), i.e. ≈ 2.7 ms per MB, so the ≈ 160 MB that a
/// 10k-keyframe Sim(3) solve first-touches cost ≈ 0.4 s before the first step. Arrays of at
/// least kLargeArrayThreshold bytes are therefore mapped on their own (mmap), aligned to
/// 2 MiB and marked MADV_HUGEPAGE, so that the kernel backs them with transparent huge pages
/// (THP "madvise" mode, Debian's default): one fault per 2 MiB (0.25 µs per 4 KiB equivalent
/// on the same VM once the memory is warm). Freeing unmaps them, so the memory goes back to
/// the system at once.
///
/// Cache colouring: every mapping is 2 MiB aligned, so arrays walked side by side would start
/// in the same cache sets; each allocation is shifted by a rotating multiple of 33 cache lines
/// within its first huge page.
///
/// Purely a performance hint: where THP is off (or not Linux) the mapping is an ordinary
/// anonymous mapping; if mmap fails, std::bad_alloc as from operator new. Smaller arrays use
/// the ordinary aligned operator new.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace geodrift::solver {

/// Arrays of at least this many bytes get their own huge-page mapping.
inline constexpr std::size_t kLargeArrayThreshold = std::size_t{4} << 20;
inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;

namespace detail {

/// Colour (byte offset into the first huge page) of the next large array: 0, 33, 66, ... 495
/// cache lines, so that 16 consecutive arrays start in distinct L1/L2 sets.
inline std::size_t next_large_array_colour() {
  static std::atomic<unsigned> counter{0};
  return static_cast<std::size_t>(counter.fetch_add(1, std::memory_order_relaxed) % 16u) * 33u *
         64u;
}

inline std::size_t round_up(std::size_t n, std::size_t to) { return (n + to - 1) / to * to; }

/// Maps `bytes` (≥ kLargeArrayThreshold) at a 2 MiB boundary + colour; returns the usable
/// pointer. The mapping is [p − colour, p − colour + round_up(bytes + colour, 2 MiB)).
inline void* map_large_array(std::size_t bytes, std::size_t colour) {
#if defined(__linux__)
  const std::size_t len = round_up(bytes + colour, kHugePageBytes);
  // Over-map by one huge page and trim, so the kept range starts at a 2 MiB boundary.
  void* raw = ::mmap(nullptr, len + kHugePageBytes, PROT_READ | PROT_WRITE,
                     MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) throw std::bad_alloc();
  const auto r = reinterpret_cast<std::uintptr_t>(raw);
  const std::uintptr_t base = round_up(r, kHugePageBytes);
  if (base > r) ::munmap(raw, base - r);
  const std::uintptr_t tail = base + len, end = r + len + kHugePageBytes;
  if (end > tail) ::munmap(reinterpret_cast<void*>(tail), end - tail);
#if defined(MADV_HUGEPAGE)
  ::madvise(reinterpret_cast<void*>(base), len, MADV_HUGEPAGE);  // a hint: may fail, harmless
#endif
  return reinterpret_cast<void*>(base + colour);
#else
  (void)colour;
  return ::operator new(bytes, std::align_val_t(64));
#endif
}

inline void unmap_large_array(void* p, std::size_t bytes) noexcept {
#if defined(__linux__)
  const auto q = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t base = q / kHugePageBytes * kHugePageBytes;  // colour < 2 MiB
  ::munmap(reinterpret_cast<void*>(base), round_up(bytes + (q - base), kHugePageBytes));
#else
  (void)bytes;
  ::operator delete(p, std::align_val_t(64));
#endif
}

}  // namespace detail

/// std::allocator replacement for the solver's large arrays (see the file comment). Aligned to
/// at least 64 bytes (Eigen's fixed-size types need 16 or 32).
template <typename T>
struct LargeArrayAllocator {
  using value_type = T;
  static constexpr std::size_t kAlign = alignof(T) > 64 ? alignof(T) : 64;
  static_assert(kAlign <= 64, "LargeArrayAllocator aligns to 64 bytes at most");

  LargeArrayAllocator() = default;
  template <typename U>
  LargeArrayAllocator(const LargeArrayAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T) / 2) throw std::bad_alloc();
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kLargeArrayThreshold)
      return static_cast<T*>(::operator new(bytes, std::align_val_t(kAlign)));
    return static_cast<T*>(detail::map_large_array(bytes, detail::next_large_array_colour()));
  }
  void deallocate(T* p, std::size_t n) noexcept {
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kLargeArrayThreshold)
      ::operator delete(p, std::align_val_t(kAlign));
    else
      detail::unmap_large_array(p, bytes);
  }
  template <typename U>
  bool operator==(const LargeArrayAllocator<U>&) const noexcept {
    return true;
  }
  template <typename U>
  bool operator!=(const LargeArrayAllocator<U>&) const noexcept {
    return false;
  }
};

}  // namespace geodrift::solver
