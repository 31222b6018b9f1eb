#pragma once

/// @file
/// LargeArrayAllocator: the allocator of the solver's big per-problem arrays (the values of H
/// and of its speculative twin, the geodesic-acceleration store; not the block Cholesky factor,
/// whose factorisation ran 25-30 % slower on these mappings: BENCHMARKS.md "Tried and not
/// kept"). Rounds N below are those of BENCHMARKS.md's history, `git show 3d5878d:BENCHMARKS.md`.
///
/// Why: a solve first-touches all of these, and on a virtual machine a first touch can cost far
/// more than the arithmetic that follows. How much, and which page size is cheaper, depends on
/// the host (rounds 6 and 7), so:
/// - Page size: a choice, off by default. With set_large_array_huge_pages(true) (or the
///   environment variable GEODRIFT_HUGE_PAGES=1, read once) new mappings are marked
///   MADV_HUGEPAGE, which the kernel backs with transparent huge pages (THP "madvise" mode,
///   Debian's default): one fault per 2 MiB and fewer TLB misses afterwards. Measured on two of
///   the project's 2-core VMs, first touch of fresh memory:
///     round 6's VM:   4 KiB pages 2.7 ms/MB (11 µs per fault), huge pages ≈ 1.5 ms/MB;
///     round 7's VM:   4 KiB pages 0.4-0.66 ms/MB, huge pages 2.9-3.6 ms/MB (the host backs
///                     each fresh 2 MiB page first), 0.05 ms/MB when reused in the process.
///   On round 7's VM, in a fresh process, a 10k / 50k-keyframe accelerated Sim(3) drift solve
///   spends 0.19-0.53 s / 2.0-2.6 s before its first step with huge pages and 0.19-0.22 s /
///   0.65 s without; its steps are 5-15 % slower without (TLB misses). Huge pages pay where
///   faults are expensive, where the arrays are reused, or right after another process freed
///   as much memory (the 10k benchmark row after Ceres' rows).
/// - Prefaulting: ordinary-page mappings are populated when made (MADV_POPULATE_WRITE, Linux
///   5.14+; ignored where unknown): one system call instead of a page fault per 4 KiB page when
///   the array is first written. Measured on round 9's VM, 256 MB: 0.39-0.45 ms/MB populated
///   against 0.53-0.57 ms/MB faulted page by page; a fresh-process 10k drift solve 8-10 ms
///   (2 %) sooner at its third step, four alternating runs each.
/// - Reuse: a freed mapping is kept (up to kLargeArrayCacheBytes in kLargeArrayCacheCount
///   mappings, oldest unmapped first) and handed to the next large array that fits, so repeated
///   solves (LM on the same problem again, the Corrector's windows, a benchmark's repetitions)
///   touch no new memory, as glibc's heap does for arrays under its 32 MB mmap threshold.
///   release_large_array_cache() unmaps what is kept.
/// - Cache colouring: mappings are 2 MiB aligned, so arrays walked side by side would start in
///   the same cache sets; each mapping's data starts at a rotating multiple of 33 cache lines.
///
/// Purely a performance measure: where THP is off (or not Linux) the mappings use ordinary
/// pages whatever the setting. If mmap fails: std::bad_alloc, as from operator new. Smaller arrays
/// use the ordinary aligned operator new. Thread-safe.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <new>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace geodrift::solver {

/// Arrays of at least this many bytes get their own 2 MiB-aligned mapping.
inline constexpr std::size_t kLargeArrayThreshold = std::size_t{4} << 20;
inline constexpr std::size_t kHugePageBytes = std::size_t{2} << 20;
/// At most this many bytes / mappings are kept for reuse after their arrays are freed.
inline constexpr std::size_t kLargeArrayCacheBytes = std::size_t{1} << 30;
inline constexpr std::size_t kLargeArrayCacheCount = 32;

namespace detail {
/// The page-size choice (see the file comment): -1 until first read, then 0 or 1.
inline std::atomic<int>& huge_pages_setting() {
  static std::atomic<int> setting{-1};
  return setting;
}
}  // namespace detail

/// Whether new large-array mappings ask for transparent huge pages (see the file comment).
/// Until set_large_array_huge_pages() is called: true if the environment variable
/// GEODRIFT_HUGE_PAGES is "1" when first asked, else false.
inline bool large_array_huge_pages_enabled() noexcept {
  std::atomic<int>& s = detail::huge_pages_setting();
  int v = s.load(std::memory_order_relaxed);
  if (v < 0) {
    const char* e = std::getenv("GEODRIFT_HUGE_PAGES");
    v = e && e[0] == '1' && e[1] == '\0' ? 1 : 0;
    int expected = -1;
    if (!s.compare_exchange_strong(expected, v)) v = expected;  // another thread decided first
  }
  return v == 1;
}

/// Marks (true) or stops marking (false) new large-array mappings MADV_HUGEPAGE. Mappings
/// already made, including the kept ones, keep the page size they were made with.
inline void set_large_array_huge_pages(bool on) noexcept {
  detail::huge_pages_setting().store(on ? 1 : 0, std::memory_order_relaxed);
}

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
    if (large_array_huge_pages_enabled())
      ::madvise(reinterpret_cast<void*>(base), len, MADV_HUGEPAGE);  // a hint: may fail, harmless
#endif
#if defined(MADV_POPULATE_WRITE)
    if (!large_array_huge_pages_enabled())  // ordinary pages: fault them in in one call
      ::madvise(reinterpret_cast<void*>(base), len, MADV_POPULATE_WRITE);  // may fail, harmless
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
