// Replays the committed fuzz corpora (tests/fuzz/<target>/) through the libFuzzer entries of
// fuzz/fuzz_entries.hpp: a parser may reject an input only with geodrift::Error; any other
// exception escapes the entry and fails here (crashes and sanitizer reports fail the process).
#include <algorithm>
#include <catch2/catch.hpp>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "fuzz_entries.hpp"

namespace fs = std::filesystem;

namespace {

const fs::path kCorpusRoot = fs::path(GEODRIFT_SOURCE_DIR) / "tests" / "fuzz";

std::vector<fs::path> corpus_files(const std::string& target) {
  std::vector<fs::path> files;
  const fs::path dir = kCorpusRoot / target;
  if (!fs::is_directory(dir)) return files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::vector<std::uint8_t> read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

void replay(const geodrift::fuzz::Target& t) {
  const std::vector<fs::path> files = corpus_files(t.name);
  INFO("target " << t.name);
  // An empty or missing corpus would make the replay pass vacuously.
  REQUIRE(!files.empty());
  for (const fs::path& f : files) {
    const std::vector<std::uint8_t> bytes = read_bytes(f);
    INFO("corpus file " << f.string());
    CHECK_NOTHROW(t.entry(bytes.data(), bytes.size()));
  }
}

}  // namespace

TEST_CASE("Every fuzz target has a libFuzzer main and a committed corpus", "[fuzz]") {
  for (const auto& t : geodrift::fuzz::targets()) {
    INFO("target " << t.name);
    CHECK(fs::is_regular_file(fs::path(GEODRIFT_SOURCE_DIR) / "fuzz" /
                              (std::string("fuzz_") + t.name + ".cpp")));
    CHECK(!corpus_files(t.name).empty());
  }
}

TEST_CASE("Core parser fuzz corpora replay with only geodrift errors", "[fuzz][io]") {
  for (const auto& t : geodrift::fuzz::targets())
    if (!t.needs_frontends) replay(t);
}

TEST_CASE("Frontend parser fuzz corpora replay with only geodrift errors", "[fuzz][frontends]") {
#ifdef GEODRIFT_FUZZ_FRONTENDS
  for (const auto& t : geodrift::fuzz::targets())
    if (t.needs_frontends) replay(t);
#else
  WARN(
      "frontends not built (GEODRIFT_BUILD_FRONTENDS=OFF): geo-tag CSV, EXIF and calibration "
      "corpora not replayed");
#endif
}

TEST_CASE("A fuzz entry swallows a geodrift parse error but not other exceptions", "[fuzz]") {
  using geodrift::fuzz::detail::expect_clean;
  CHECK(expect_clean([] { throw geodrift::InvalidArgument("f.txt:3: bad"); }) == 0);
  CHECK_THROWS_AS(expect_clean([] { throw std::out_of_range("stoll"); }), std::out_of_range);
  // A malformed file reaches the real reader: the BAL header must be rejected, not crash.
  const std::string bad = "-1 2 3\n";
  CHECK(geodrift::fuzz::fuzz_bal(reinterpret_cast<const std::uint8_t*>(bad.data()), bad.size()) ==
        0);
  CHECK_THROWS_AS(geodrift::io::read_bal(geodrift::fuzz::detail::scratch_dir() + "/problem.txt"),
                  geodrift::InvalidArgument);
}

namespace {

/// Writes `text` through the entry's scratch folder and returns what `read` throws (empty if it
/// does not throw a geodrift::Error).
template <class Read>
std::string geodrift_error_of(const std::string& name, const std::string& text, Read read) {
  const std::string path = geodrift::fuzz::detail::write_file(name, text);
  try {
    read(path);
  } catch (const geodrift::Error& e) {
    return e.what();
  }
  return std::string();
}

}  // namespace

TEST_CASE("Fuzz finding: a COLMAP image line separated by form feeds is a parse error",
          "[fuzz][io]") {
  // Fields split on any isspace, the NAME search used " \t" only: substr(npos) threw
  // std::out_of_range.
  const std::string cameras = "1 PINHOLE 640 480 500 500 320 240\n";
  const std::string dir = geodrift::fuzz::detail::colmap_dir(
      "cameras.txt", reinterpret_cast<const std::uint8_t*>(cameras.data()), cameras.size());
  geodrift::fuzz::detail::write_file("colmap/images.txt", "1 1 0 0 0 0 0 0 1\f000000.png\n\n");
  const geodrift::io::ColmapModel m = geodrift::io::read_colmap_text(dir);
  REQUIRE(m.map.keyframes.size() == 1);
  CHECK(m.image_names.at(0) == "000000.png");
}

TEST_CASE("Fuzz finding: BAL header counts do not allocate before the values are read",
          "[fuzz][io]") {
  const std::string what =
      geodrift_error_of("huge.bal", "1 1 2000000000\n0 0 1 2\n",
                        [](const std::string& p) { geodrift::io::read_bal(p); });
  INFO(what);
  CHECK(what.find("huge.bal:2: unexpected end of file") != std::string::npos);
}

#ifdef GEODRIFT_FUZZ_FRONTENDS
TEST_CASE("Fuzz finding: calibration sizes and OpenCV matrices are checked, naming the file",
          "[fuzz][frontends]") {
  const auto load = [](const std::string& p) { geodrift::vo::load_calibration(p); };
  std::string what =
      geodrift_error_of("size.txt", "K: 500 0 320 0 500 240 0 0 1\nsize: 1e300 5\n", load);
  CHECK(what.find("size.txt:2: image size 1e+300 is not an integer") != std::string::npos);
  what = geodrift_error_of("scalar.yaml", "%YAML:1.0\n---\nK: 5\n", load);
  CHECK(what.find("scalar.yaml:3: 'K' is not a readable OpenCV matrix") != std::string::npos);
  what = geodrift_error_of("width.yaml",
                           "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n"
                           "   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\n"
                           "image_width: 1e300\n",
                           load);
  CHECK(what.find("width.yaml:8: image_width is not an integer") != std::string::npos);
  // OpenCV allocated rows x cols (85 GB here) before counting the data; geodrift checks them.
  what = geodrift_error_of("rows.yaml",
                           "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows:x\n"
                           "   rows: 99999\n   cols: 5\n   dt: d\n   data: [ 1, 2, 3, 4, 5 ]\n",
                           load);
  CHECK(what.find("rows.yaml:5: 'camera_matrix' rows is not an integer in [1, 16]") !=
        std::string::npos);
  // OpenCV's parser threw std::length_error for an unknown tag followed by ':dt d'.
  what = geodrift_error_of("tag.yaml",
                           "%YAML:1.0\n---\nK: !!oqencv-matrix\n   rows: 3\n   cols: 3\n"
                           "   :dt d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]\n",
                           load);
  CHECK(what.find("tag.yaml:3: 'K' has the tag '!!oqencv-matrix', expected !!opencv-matrix") !=
        std::string::npos);
  // OpenCV 4.6's FileStorage::open never returned on this file (a truncated '%YAML:1.' header
  // and indented fragments); geodrift's own YAML reader refuses it at once.
  what = geodrift_error_of("hang.yaml",
                           "%YAML:1.ows: 3\n   cols: 3\n   dt: f\n   data: [ 000., 0., 320., "
                           "0., 500., 240., 0., 0., 1. ]\n<: -\nK: !v-matrix\n   rows: 3\n"
                           "   cols: 3\n!!opencv-matrix\n   rows: 4\n",
                           load);
  CHECK(what.find("hang.yaml:") != std::string::npos);
}

TEST_CASE("Fuzz finding: geo-tag CSV ids and frames outside int are parse errors",
          "[fuzz][frontends]") {
  // fuzz_geotag_csv writes pano.png next to the CSV.
  const std::string ok = "id,file,latitude,longitude,height,heading_deg\n0,pano.png,55,13,60,90\n";
  geodrift::fuzz::fuzz_geotag_csv(reinterpret_cast<const std::uint8_t*>(ok.data()), ok.size());
  const std::string what = geodrift_error_of(
      "geotags.csv", "id,file,latitude,longitude,height,heading_deg\n1e300,pano.png,55,13,60,90\n",
      [](const std::string& p) { geodrift::geotag::read_geotag_csv(p); });
  CHECK(what.find("geotags.csv:2: id '1e300' is not an integer") != std::string::npos);
}
#endif
