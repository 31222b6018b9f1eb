// Uses the installed core the way a downstream project would: a CHOLMOD session through the
// imported target, and geodrift's version and error types.
#include <geodrift/error.hpp>
#include <geodrift/version.hpp>

#include <cholmod.h>

#include <cstdio>
#include <cstring>

int main() {
  cholmod_common cc;
  cholmod_start(&cc);
  const bool ok = cholmod_finish(&cc) != 0;
  std::printf("geodrift %s consumer: cholmod %s\n", geodrift::kVersion, ok ? "ok" : "FAILED");
  return ok && std::strlen(geodrift::kVersion) > 0 ? 0 : 1;
}
