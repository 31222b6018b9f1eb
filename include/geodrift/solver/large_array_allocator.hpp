#pragma once

/// @file
/// LargeArrayAllocator: the allocator of the solver's big per-problem arrays (the values of H
/// and of its speculative twin, the geodesic-acceleration store; not the block Cholesky factor,
/// whose factorisation ran 25-30 % slower on these mappings, BENCHMARKS.md round 6).
///
/// Why: a solve first-touches all of these. With 4 KiB pages that is one page fault per 4 KiB,
/// and on a virtual machine a fault is expensive: 11 µs per 4 KiB page measured on the
/// project's 2-core VM (BENCHMARKS.md, round 6), ≈ 2.7 ms per MB, so the ≈ 160 MB that a
/// 10k-keyframe Sim(3) solve touches cost ≈ 0.4 s before its first step. So:
/// - Huge pages: arrays of at least kLargeArrayThreshold bytes get their own anonymous mapping,
///   2 MiB aligned and marked MADV_HUGEPAGE, which the kernel backs with transparent huge pages
///   (THP "madvise" mode, Debian's default): one fault per 2 MiB.
/// - Reuse: a freed mapping is kept (up to kLargeArrayCacheBytes in kLargeArrayCacheCount
///   mappings, oldest unmapped first) and handed to the next large array that fits, so repeated
///   solves (LM on the same problem again, the Corrector's windows, a benchmark's repetitions)
///   touch no new memory, as glibc's heap does for arrays under its 32 MB mmap threshold.
///   release_large_array_cache() unmaps what is kept.
/// - Cache colouring: mappings are 2 MiB aligned, so arrays walked side by side would start in
///   the same cache sets; each mapping's data starts at a rotating multiple of 33 cache lines.
///
/// Purely a performance measure: where THP is off (or not Linux) the mappings use ordinary
/// pages. If mmap fails: std::bad_alloc, as from operator new. Smaller arrays use the ordinary
/// aligned operator new. Thread-safe.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <new>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace geodrift::solver {

/// Arrays of at least this many bytes get their own huge-page mapping.
inline constexpr std::size_t kLargeArrayThreshold = std::size_t{4} << 20;
inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;
/// At most this many bytes / mappings are kept for reuse after their arrays are freed.
inline constexpr std::size_t kLargeArrayCacheBytes = std::size_t{1} << 30;
inline constexpr std::size_t kLargeArrayCacheCount = 32;

namespace detail {

inline std::size_t round_up(std::size_t n, std::size_t to) { return (n + to - 1) / to * to; }

#if defined(__linux__)
/// Start of every mapping: its length and where its data starts (the colour, ≥ 64 bytes).
struct LargeArrayHeader {
  std::size_t length;
  std::size_t colour;
};

/// The kept mappings (process-wide; never destroyed, so arrays freed during static
/// destruction still find it).
class LargeArrayCache {
 public:
  static LargeArrayCache& instance() {
    static LargeArrayCache* cache = new LargeArrayCache;
    return *cache;
  }

  /// A kept mapping whose data area holds `bytes` and that wastes at most half of itself,
  /// else a new one; returns its data pointer.
  void* acquire(std::size_t bytes) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::size_t best = kept_.size();
      for (std::size_t k = 0; k < kept_.size(); ++k) {
        const LargeArrayHeader* h = kept_[k];
        if (h->length - h->colour >= bytes && h->length <= 2 * (bytes + h->colour) &&
            (best == kept_.size() || h->length < kept_[best]->length))
          best = k;
      }
      if (best < kept_.size()) {
        LargeArrayHeader* h = kept_[best];
        kept_.erase(kept_.begin() + static_cast<std::ptrdiff_t>(best));
        kept_bytes_ -= h->length;
        return reinterpret_cast<char*>(h) + h->colour;
      }
    }
    return map(bytes);
  }

  /// Keeps the mapping of data pointer p for reuse, unmapping the oldest kept ones past the
  /// limits.
  void release(void* p) noexcept {
    LargeArrayHeader* h = header_of(p);
    std::lock_guard<std::mutex> lock(mutex_);
    kept_.push_back(h);  // within the capacity reserved by the constructor: no allocation
    kept_bytes_ += h->length;
    while (kept_bytes_ > kLargeArrayCacheBytes || kept_.size() > kLargeArrayCacheCount) {
      kept_bytes_ -= kept_.front()->length;
      ::munmap(kept_.front(), kept_.front()->length);
      kept_.erase(kept_.begin());
    }
  }

  /// Unmaps every kept mapping.
  void clear() noexcept {
    std::lock_guard<std::mutex> lock(mutex_);
    for (LargeArrayHeader* h : kept_) ::munmap(h, h->length);
    kept_.clear();
    kept_bytes_ = 0;
  }

  std::size_t kept_bytes() {
    std::lock_guard<std::mutex> lock(mutex_);
    return kept_bytes_;
  }

  static LargeArrayHeader* header_of(void* p) {
    // The colour is < 2 MiB, so the mapping starts at p's 2 MiB boundary.
    const auto q = reinterpret_cast<std::uintptr_t>(p);
    return reinterpret_cast<LargeArrayHeader*>(q / kHugePageBytes * kHugePageBytes);
  }

 private:
  LargeArrayCache() { kept_.reserve(kLargeArrayCacheCount + 1); }

  /// A new mapping for `bytes` at a 2 MiB boundary, data at the next colour.
  void* map(std::size_t bytes) {
    const std::size_t colour =
        64 + (next_colour_.fetch_add(1, std::memory_order_relaxed) % 16u) * std::size_t{33 * 64};
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
    auto* h = reinterpret_cast<LargeArrayHeader*>(base);
    h->length = len;
    h->colour = colour;
    return reinterpret_cast<char*>(base) + colour;
  }

  std::mutex mutex_;
  std::vector<LargeArrayHeader*> kept_;  ///< oldest first
  std::size_t kept_bytes_ = 0;
  std::atomic<unsigned> next_colour_{0};
};
#endif

inline void* allocate_large_array(std::size_t bytes) {
#if defined(__linux__)
  return LargeArrayCache::instance().acquire(bytes);
#else
  return ::operator new(bytes, std::align_val_t(64));
#endif
}

inline void free_large_array(void* p) noexcept {
#if defined(__linux__)
  LargeArrayCache::instance().release(p);
#else
  ::operator delete(p, std::align_val_t(64));
#endif
}

}  // namespace detail

/// Unmaps the large-array mappings kept for reuse (see the file comment); arrays in use are not
/// affected. Call it to give the memory back after the last solve.
inline void release_large_array_cache() noexcept {
#if defined(__linux__)
  detail::LargeArrayCache::instance().clear();
#endif
}

/// Bytes of large-array mappings currently kept for reuse.
inline std::size_t large_array_cache_bytes() {
#if defined(__linux__)
  return detail::LargeArrayCache::instance().kept_bytes();
#else
  return 0;
#endif
}

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
    return static_cast<T*>(detail::allocate_large_array(bytes));
  }
  void deallocate(T* p, std::size_t n) noexcept {
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kLargeArrayThreshold)
      ::operator delete(p, std::align_val_t(kAlign));
    else
      detail::free_large_array(p);
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
