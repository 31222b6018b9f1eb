// libFuzzer target "trajectory_tum": the entry in fuzz_entries.hpp (shared with tests/fuzz/).
#include "fuzz_entries.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return geodrift::fuzz::fuzz_trajectory_tum(data, size);
}
