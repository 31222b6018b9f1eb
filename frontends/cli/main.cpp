// geodrift command line: dispatches to the subcommands. Library code throws geodrift::Error;
// this is the one place that turns an exception into a message and a non-zero exit.
#include <geodrift/error.hpp>
#include <geodrift/version.hpp>

#include <cstdio>
#include <exception>
#include <string>

namespace {
void print_usage(std::FILE* f) {
  std::fprintf(f,
               "geodrift %s: geo-localize a monocular reconstruction with sparse geo-tagged "
               "images\n\nusage: geodrift <subcommand> [options]\n       geodrift --version\n\n"
               "subcommands (geodrift <subcommand> --help for each):\n",
               geodrift::kVersion);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    print_usage(stderr);
    return 2;
  }
  const std::string cmd = argv[1];
  try {
    if (cmd == "--version" || cmd == "version") {
      std::printf("geodrift %s\n", geodrift::kVersion);
      return 0;
    }
    if (cmd == "--help" || cmd == "-h" || cmd == "help") {
      print_usage(stdout);
      return 0;
    }
    std::fprintf(stderr, "geodrift: unknown subcommand '%s'\n", cmd.c_str());
    print_usage(stderr);
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "geodrift %s: error: %s\n", cmd.c_str(), e.what());
    return 1;
  }
}
