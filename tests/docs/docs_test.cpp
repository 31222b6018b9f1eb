// docs/library.md is executable documentation: each of its ```cpp blocks is a whole program,
// compiled here (one translation unit: library_md_blocks.inc, generated from the Markdown by
// extract_code_blocks.cmake) and run by one TEST_CASE that requires main() to return 0. Each
// program checks its own numbers against the known answer the text states. Each ```cmake block
// must match the consumer project that the package_consumer test builds.
#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "library_md_blocks.inc"

namespace {

/// A CMake line without its comment and surrounding blanks.
std::string cmake_code(const std::string& line) {
  std::string s = line.substr(0, line.find('#'));
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t\r") - b + 1);
}

std::vector<std::string> code_lines(std::istream& in) {
  std::vector<std::string> out;
  for (std::string line; std::getline(in, line);)
    if (const std::string c = cmake_code(line); !c.empty()) out.push_back(c);
  return out;
}

}  // namespace

TEST_CASE("docs/library.md has its code blocks", "[docs]") {
  // The guide's sections each end in a program: Lie types, own residual, Corrector stream, W.
  CHECK(doc_blocks::kNumCppBlocks >= 4);
}

TEST_CASE("docs/library.md cmake blocks are what the package consumer test builds", "[docs]") {
  std::ifstream f(std::string(GEODRIFT_SOURCE_DIR) + "/tests/package/CMakeLists.txt");
  REQUIRE(f.good());
  const std::vector<std::string> consumer = code_lines(f);
  int blocks = 0;
  for (const doc_blocks::CmakeBlock* b = doc_blocks::kCmakeBlocks; b->text; ++b, ++blocks) {
    std::istringstream in(b->text);
    for (const std::string& line : code_lines(in)) {
      INFO("docs/library.md block at line " << b->line << ": '" << line << "'");
      CHECK(std::find(consumer.begin(), consumer.end(), line) != consumer.end());
    }
  }
  CHECK(blocks >= 1);
}
