// first_touch: what first touching fresh anonymous memory costs on this machine, with 4 KiB
// pages and with transparent huge pages (MADV_HUGEPAGE), in ms per MB. A diagnostic for the
// page-size choice of solver/large_array_allocator.hpp (round 7 of BENCHMARKS.md's history,
// `git show 3d5878d:BENCHMARKS.md`), not a Google Benchmark: the interesting number is the
// first touch after the memory went back to the host, which repetitions inside one process do
// not see (their second pass reuses backed pages).
//
// usage: first_touch [MB = 256] [passes = 3]
//   each pass maps MB, touches one byte per 4 KiB, unmaps; per page size, huge pages first.
//   Run it twice with a pause of a few seconds to see the cold first pass again.
#include <sys/mman.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <initializer_list>

namespace {
double touch_ms(std::size_t bytes, bool huge) {
  constexpr std::size_t k2M = std::size_t{2} << 20;
  const auto t0 = std::chrono::steady_clock::now();
  void* raw =
      ::mmap(nullptr, bytes + k2M, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (raw == MAP_FAILED) {
    std::perror("first_touch: mmap");
    std::exit(1);
  }
  char* a = reinterpret_cast<char*>((reinterpret_cast<std::uintptr_t>(raw) + k2M - 1) / k2M * k2M);
  if (huge) ::madvise(a, bytes, MADV_HUGEPAGE);
  for (std::size_t i = 0; i < bytes; i += 4096) a[i] = 1;
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ::munmap(raw, bytes + k2M);
  return ms;
}
}  // namespace

int main(int argc, char** argv) {
  const long mb = argc > 1 ? std::atol(argv[1]) : 256;
  const long passes = argc > 2 ? std::atol(argv[2]) : 3;
  if (mb <= 0 || mb > 16384 || passes <= 0 || passes > 100) {
    std::fprintf(stderr, "usage: first_touch [MB in 1..16384] [passes in 1..100]\n");
    return 2;
  }
  const std::size_t bytes = static_cast<std::size_t>(mb) << 20;
  for (const bool huge : {true, false}) {
    for (long p = 0; p < passes; ++p) {
      const double ms = touch_ms(bytes, huge);
      std::printf("%s pages, pass %ld: %ld MB in %.1f ms = %.2f ms/MB\n",
                  huge ? "huge (MADV_HUGEPAGE)" : "4 KiB", p + 1, mb, ms, ms / mb);
    }
  }
  return 0;
}
