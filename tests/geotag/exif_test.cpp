// EXIF geo-tags (frontends/geotag exif.hpp): the real Lund photos against the values copied
// out of them, a JPEG with an APP1 block assembled byte by byte, every truncation and random
// corruptions of real blocks read next to a guard page (an out-of-bounds read faults), and the
// geo-tag CSV / JPEG folder readers that take their missing cells from EXIF.
#include "geodrift/geotag/exif.hpp"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/geotag/views.hpp"
#include "support/test_files.hpp"

using namespace geodrift;
using geotag::ExifGeotag;

namespace {

const std::string kLundDir = std::string(GEODRIFT_DATA_DIR) + "/opensfm_lund";
const std::string kLundImages = kLundDir + "/images/";

bool have_lund() {
  if (std::filesystem::exists(kLundDir + "/lund_exif_gps.csv")) return true;
  WARN("Lund data not found at " << kLundDir);
  return false;
}

std::vector<std::uint8_t> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  REQUIRE(in.good());
  return std::vector<std::uint8_t>(std::istreambuf_iterator<char>(in), {});
}

void write_bytes(const std::string& path, const std::vector<std::uint8_t>& b) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  REQUIRE(out.good());
}

/// The payload of the first APP1 segment starting with "Exif\0\0" (independent walker).
std::vector<std::uint8_t> exif_payload(const std::vector<std::uint8_t>& jpg) {
  std::size_t i = 2;
  while (i + 4 <= jpg.size() && jpg[i] == 0xFF) {
    const std::size_t len = (std::size_t(jpg[i + 2]) << 8) | jpg[i + 3];
    if (jpg[i + 1] == 0xE1 && std::memcmp(&jpg[i + 4], "Exif\0\0", 6) == 0)
      return std::vector<std::uint8_t>(jpg.begin() + i + 4, jpg.begin() + i + 2 + len);
    i += 2 + len;
  }
  FAIL("no Exif APP1 segment");
  return {};
}

/// Copies bytes so that they end exactly where a PROT_NONE page begins: reading one byte past
/// the end faults (the test build has no sanitizer; this makes out-of-bounds reads visible).
class GuardedBuffer {
 public:
  explicit GuardedBuffer(std::size_t capacity) {
    page_ = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
    pages_ = (capacity + page_ - 1) / page_ + 1;
    void* m =
        ::mmap(nullptr, pages_ * page_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    REQUIRE(m != MAP_FAILED);
    base_ = static_cast<std::uint8_t*>(m);
    REQUIRE(::mprotect(base_ + (pages_ - 1) * page_, page_, PROT_NONE) == 0);
  }
  ~GuardedBuffer() { ::munmap(base_, pages_ * page_); }
  GuardedBuffer(const GuardedBuffer&) = delete;
  GuardedBuffer& operator=(const GuardedBuffer&) = delete;
  /// The first n bytes of src, placed against the guard page.
  const std::uint8_t* place(const std::uint8_t* src, std::size_t n) {
    std::uint8_t* at = base_ + (pages_ - 1) * page_ - n;
    if (n) std::memcpy(at, src, n);
    return at;
  }

 private:
  std::size_t page_ = 4096, pages_ = 0;
  std::uint8_t* base_ = nullptr;
};

/// Field `got` is unknown, or equal to the field read from the complete block.
bool nan_or_equal(double got, double full) { return std::isnan(got) || got == full; }

void check_subset_of(const ExifGeotag& g, const ExifGeotag& full) {
  CHECK(nan_or_equal(g.latitude_deg, full.latitude_deg));
  CHECK(nan_or_equal(g.longitude_deg, full.longitude_deg));
  CHECK(nan_or_equal(g.altitude_m, full.altitude_m));
  CHECK(nan_or_equal(g.true_heading_deg, full.true_heading_deg));
  CHECK(nan_or_equal(g.magnetic_heading_deg, full.magnetic_heading_deg));
  CHECK(nan_or_equal(g.focal_length_mm, full.focal_length_mm));
  CHECK(nan_or_equal(g.focal_length_35mm, full.focal_length_35mm));
  CHECK(nan_or_equal(g.pixel_width, full.pixel_width));
  CHECK(nan_or_equal(g.pixel_height, full.pixel_height));
  CHECK((g.orientation == 0 || g.orientation == full.orientation));
}

/// Any value read is in its documented range.
void check_in_range(const ExifGeotag& g) {
  CHECK((std::isnan(g.latitude_deg) || std::abs(g.latitude_deg) <= 90.0));
  CHECK((std::isnan(g.longitude_deg) || std::abs(g.longitude_deg) <= 180.0));
  CHECK(!std::isinf(g.altitude_m));
  for (double h : {g.true_heading_deg, g.magnetic_heading_deg})
    CHECK((std::isnan(h) || (h >= 0.0 && h < 360.0)));
  for (double v : {g.focal_length_mm, g.focal_length_35mm, g.pixel_width, g.pixel_height})
    CHECK((std::isnan(v) || (v > 0.0 && std::isfinite(v))));
  CHECK((g.orientation >= 0 && g.orientation <= 8));
}

/// A TIFF/EXIF block writer (either byte order) for the synthetic test.
class TiffWriter {
 public:
  explicit TiffWriter(bool little) : little_(little) {}
  std::vector<std::uint8_t> bytes;
  void u8(std::uint32_t v) { bytes.push_back(static_cast<std::uint8_t>(v)); }
  void u16(std::uint32_t v) {
    if (little_) {
      u8(v & 0xFF), u8(v >> 8);
    } else {
      u8(v >> 8), u8(v & 0xFF);
    }
  }
  void u32(std::uint32_t v) {
    if (little_) {
      u16(v & 0xFFFF), u16(v >> 16);
    } else {
      u16(v >> 16), u16(v & 0xFFFF);
    }
  }
  void put_u32(std::size_t at, std::uint32_t v) {
    std::vector<std::uint8_t> keep;
    keep.swap(bytes);
    u32(v);
    std::memcpy(&keep[at], bytes.data(), 4);
    bytes.swap(keep);
  }

 private:
  bool little_;
};

struct Tag {
  std::uint16_t tag, type;
  std::uint32_t count;
  std::vector<std::uint32_t> values;  // SHORT/LONG values, ASCII bytes, or rational num,den pairs
};

/// Writes an IFD at the end of w (entries, next-IFD 0, then out-of-line values); returns the
/// offsets (in w) of each entry's value field, for patching IFD pointers.
std::vector<std::size_t> write_ifd(TiffWriter& w, const std::vector<Tag>& tags) {
  const std::size_t start = w.bytes.size();
  std::size_t data = start + 2 + 12 * tags.size() + 4;
  std::vector<std::size_t> value_at;
  std::vector<std::uint8_t> out_of_line;
  TiffWriter extra = w;  // same byte order, for the values
  extra.bytes.clear();
  w.u16(static_cast<std::uint32_t>(tags.size()));
  for (const Tag& t : tags) {
    w.u16(t.tag);
    w.u16(t.type);
    w.u32(t.count);
    TiffWriter v = w;
    v.bytes.clear();
    for (std::uint32_t x : t.values) {
      if (t.type == 2 || t.type == 1)
        v.u8(x);
      else if (t.type == 3)
        v.u16(x);
      else
        v.u32(x);
    }
    value_at.push_back(w.bytes.size());
    if (v.bytes.size() <= 4) {
      v.bytes.resize(4, 0);
      w.bytes.insert(w.bytes.end(), v.bytes.begin(), v.bytes.end());
    } else {
      w.u32(static_cast<std::uint32_t>(data + extra.bytes.size()));
      extra.bytes.insert(extra.bytes.end(), v.bytes.begin(), v.bytes.end());
    }
  }
  w.u32(0);  // no next IFD
  w.bytes.insert(w.bytes.end(), extra.bytes.begin(), extra.bytes.end());
  return value_at;
}

/// "Exif\0\0" + TIFF: IFD0 (Orientation, GPS and Exif pointers), GPS IFD, Exif IFD.
std::vector<std::uint8_t> synthetic_app1(bool little, char dir_ref, int orientation = 1) {
  TiffWriter w(little);
  w.u8(little ? 'I' : 'M'), w.u8(little ? 'I' : 'M');
  w.u16(42);
  w.u32(8);
  const std::vector<std::size_t> ifd0 =
      write_ifd(w, {{0x0112, 3, 1, {static_cast<std::uint32_t>(orientation)}},
                    {0x8769, 4, 1, {0}},
                    {0x8825, 4, 1, {0}}});
  w.put_u32(ifd0[2], static_cast<std::uint32_t>(w.bytes.size()));
  write_ifd(w, {{0x0000, 1, 4, {2, 3, 0, 0}},
                {0x0001, 2, 2, {'S', 0}},
                {0x0002, 5, 3, {33, 1, 52, 1, 75, 10}},
                {0x0003, 2, 2, {'W', 0}},
                {0x0004, 5, 3, {151, 1, 12, 1, 3456, 100}},
                {0x0005, 1, 1, {1}},
                {0x0006, 5, 1, {1234, 10}},
                {0x0010, 2, 2, {static_cast<std::uint32_t>(dir_ref), 0}},
                {0x0011, 5, 1, {2701, 10}}});
  w.put_u32(ifd0[1], static_cast<std::uint32_t>(w.bytes.size()));
  write_ifd(
      w,
      {{0x920A, 5, 1, {17, 4}}, {0xA002, 4, 1, {64}}, {0xA003, 3, 1, {48}}, {0xA405, 3, 1, {28}}});
  std::vector<std::uint8_t> app1 = {'E', 'x', 'i', 'f', 0, 0};
  app1.insert(app1.end(), w.bytes.begin(), w.bytes.end());
  return app1;
}

/// A 64 x rows JPEG written by OpenCV with `app1` (after an XMP APP1 if xmp_first) spliced
/// after SOI.
std::vector<std::uint8_t> jpeg_with_app1(const std::vector<std::uint8_t>& app1, int rows = 48,
                                         bool xmp_first = true) {
  cv::Mat img(rows, 64, CV_8UC3);
  cv::randu(img, 0, 255);
  std::vector<std::uint8_t> jpg;
  REQUIRE(cv::imencode(".jpg", img, jpg));
  REQUIRE(jpg.size() > 4);
  const auto segment = [](const std::vector<std::uint8_t>& payload) {
    const std::size_t len = payload.size() + 2;
    std::vector<std::uint8_t> s = {0xFF, 0xE1, std::uint8_t(len >> 8), std::uint8_t(len & 0xFF)};
    s.insert(s.end(), payload.begin(), payload.end());
    return s;
  };
  const std::string xmp_id = "http://ns.adobe.com/xap/1.0/";
  std::vector<std::uint8_t> xmp(xmp_id.begin(), xmp_id.end());
  xmp.push_back(0);
  const std::string body = "<x:xmpmeta/>";
  xmp.insert(xmp.end(), body.begin(), body.end());
  std::vector<std::uint8_t> out(jpg.begin(), jpg.begin() + 2);
  for (const auto& s : xmp_first
                           ? std::vector<std::vector<std::uint8_t>>{segment(xmp), segment(app1)}
                           : std::vector<std::vector<std::uint8_t>>{segment(app1)})
    out.insert(out.end(), s.begin(), s.end());
  out.insert(out.end(), jpg.begin() + 2, jpg.end());
  return out;
}

struct LundRow {
  std::string image;
  double lat, lon, alt;
};

std::vector<LundRow> lund_rows() {
  std::ifstream in(kLundDir + "/lund_exif_gps.csv");
  std::string line;
  std::getline(in, line);  // header: image,latitude_deg,longitude_deg,altitude_m,...
  std::vector<LundRow> rows;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string f[4];
    for (std::string& x : f) std::getline(ss, x, ',');
    rows.push_back({f[0], std::stod(f[1]), std::stod(f[2]), std::stod(f[3])});
  }
  return rows;
}

}  // namespace

TEST_CASE("EXIF of the Lund photos equals the values copied out of them", "[geotag][exif][data]") {
  if (!have_lund()) return;
  const std::vector<LundRow> rows = lund_rows();
  REQUIRE(rows.size() == 29);
  int big_endian = 0, little_endian = 0;
  double max_dlat = 0;
  for (const LundRow& r : rows) {
    const std::string path = kLundImages + r.image;
    const ExifGeotag g = geotag::read_exif(path);
    INFO(r.image);
    REQUIRE(g.has_exif);
    // lund_exif_gps.csv is NOT the EXIF GPS: it copies Mapillary's JSON (MAPLatitude, ...; see
    // its README) at 6 decimals, while the phone's EXIF stores seconds as rationals rounded to
    // 1/100" or coarser (2.8e-6 deg). The two differ by up to 2.9e-6 deg (0.32 m, 11.jpg) in
    // latitude and 2.0e-6 deg in longitude on these files, so they agree to 3e-6 deg, not to
    // the CSV's 6 decimals; the exact EXIF values are checked below from the raw rationals.
    CHECK(std::abs(g.latitude_deg - r.lat) <= 3e-6);
    CHECK(std::abs(g.longitude_deg - r.lon) <= 3e-6);
    max_dlat = std::max(max_dlat, std::abs(g.latitude_deg - r.lat));
    CHECK(g.altitude_m == r.alt);  // whole metres in both
    CHECK(g.focal_length_35mm == 35.0);
    CHECK(g.focal_length_mm == Approx(4.3).epsilon(1e-12));  // 43/10
    CHECK(g.pixel_width == 1024.0);
    CHECK(g.pixel_height == 768.0);
    CHECK(g.orientation == 1);
    // These files carry no GPSImgDirection (the compass heading is in a Mapillary JSON).
    CHECK(std::isnan(g.true_heading_deg));
    CHECK(std::isnan(g.magnetic_heading_deg));
    const std::vector<std::uint8_t> app1 = exif_payload(read_bytes(path));
    (app1[6] == 'M' ? big_endian : little_endian)++;
  }
  CHECK(big_endian > 0);  // both byte orders occur in this set
  CHECK(little_endian > 0);
  CHECK(max_dlat > 1e-6);  // the CSV is indeed a different rounding, not a copy of the EXIF
  // Exact values from the GPS IFD's rationals (deg/1, min/1, sec num/den), dumped by an
  // independent reader: 01.jpg (big-endian), 11.jpg, 27.jpg (little-endian).
  struct Raw {
    const char* file;
    double lat_s_num, lat_s_den, lon_s_num, lon_s_den, alt;
  };
  for (const Raw& x : {Raw{"01.jpg", 267, 5, 217, 5, 37}, Raw{"11.jpg", 55, 1, 841, 20, 33},
                       Raw{"27.jpg", 1179, 20, 1007, 25, 35}}) {
    INFO(x.file);
    const ExifGeotag g = geotag::read_exif(kLundImages + x.file);
    CHECK(g.latitude_deg == 55.0 + 41.0 / 60.0 + (x.lat_s_num / x.lat_s_den) / 3600.0);
    CHECK(g.longitude_deg == 13.0 + 11.0 / 60.0 + (x.lon_s_num / x.lon_s_den) / 3600.0);
    CHECK(g.altitude_m == x.alt);
  }
}

TEST_CASE("EXIF assembled byte by byte reads back exactly, in both byte orders", "[geotag][exif]") {
  test::TempDir tmp;
  for (const bool little : {true, false}) {
    INFO((little ? "little-endian" : "big-endian"));
    const std::string path = tmp.file(little ? "ii.jpg" : "mm.jpg");
    write_bytes(path, jpeg_with_app1(synthetic_app1(little, 'T')));
    const cv::Mat decoded = cv::imread(path, cv::IMREAD_GRAYSCALE);
    REQUIRE(decoded.cols == 64);  // still a valid JPEG
    const ExifGeotag g = geotag::read_exif(path);
    REQUIRE(g.has_exif);
    CHECK(g.latitude_deg == -(33.0 + 52.0 / 60.0 + 7.5 / 3600.0));
    CHECK(g.longitude_deg == -(151.0 + 12.0 / 60.0 + 34.56 / 3600.0));
    CHECK(g.altitude_m == -123.4);  // GPSAltitudeRef 1: below sea level
    CHECK(g.true_heading_deg == 270.1);
    CHECK(std::isnan(g.magnetic_heading_deg));
    CHECK(g.focal_length_mm == 4.25);
    CHECK(g.focal_length_35mm == 28.0);
    CHECK(g.pixel_width == 64.0);
    CHECK(g.pixel_height == 48.0);
    CHECK(g.orientation == 1);
  }
  // A magnetic image direction is reported apart; the true heading stays unknown.
  write_bytes(tmp.file("mag.jpg"), jpeg_with_app1(synthetic_app1(true, 'M')));
  const ExifGeotag m = geotag::read_exif(tmp.file("mag.jpg"));
  CHECK(m.magnetic_heading_deg == 270.1);
  CHECK(std::isnan(m.true_heading_deg));
  CHECK(m.latitude_deg < -33.0);
  // An unknown reference letter: neither.
  write_bytes(tmp.file("bad_ref.jpg"), jpeg_with_app1(synthetic_app1(true, 'X')));
  const ExifGeotag x = geotag::read_exif(tmp.file("bad_ref.jpg"));
  CHECK(std::isnan(x.magnetic_heading_deg));
  CHECK(std::isnan(x.true_heading_deg));
  CHECK(x.altitude_m == -123.4);

  // 35 mm-equivalent focal in pixels: f35 * diagonal / 43.27 mm.
  CHECK(geotag::focal_px_from_35mm(28.0, 64, 48) == Approx(28.0 * 80.0 / 43.2666).epsilon(1e-5));
  CHECK(std::isnan(geotag::focal_px_from_35mm(std::nan(""), 64, 48)));
}

TEST_CASE("EXIF: no EXIF, not a JPEG, missing file", "[geotag][exif][errors]") {
  test::TempDir tmp;
  cv::imwrite(tmp.file("plain.jpg"), cv::Mat(20, 30, CV_8U, cv::Scalar(7)));
  cv::imwrite(tmp.file("plain.png"), cv::Mat(20, 30, CV_8U, cv::Scalar(7)));
  tmp.write("empty.jpg", "");
  tmp.write("text.jpg", "hello");
  for (const char* f : {"plain.jpg", "plain.png", "empty.jpg", "text.jpg"}) {
    INFO(f);
    const ExifGeotag g = geotag::read_exif(tmp.file(f));
    CHECK(!g.has_exif);
    CHECK(!g.has_gps_position());
    CHECK(std::isnan(g.altitude_m));
    CHECK(std::isnan(g.true_heading_deg));
    CHECK(std::isnan(g.focal_length_35mm));
    CHECK(g.orientation == 0);
  }
  test::require_io_error([&] { geotag::read_exif(tmp.file("none.jpg")); }, tmp.file("none.jpg"));
  test::require_io_error([&] { geotag::read_exif(tmp.path().string()); }, tmp.path().string());
}

TEST_CASE("EXIF: every truncation and random corruptions of real blocks stay in bounds",
          "[geotag][exif][data]") {
  std::vector<std::vector<std::uint8_t>> blocks = {synthetic_app1(true, 'T'),
                                                   synthetic_app1(false, 'M')};
  if (have_lund())
    for (const char* f : {"01.jpg", "27.jpg"})  // big- and little-endian
      blocks.push_back(exif_payload(read_bytes(kLundImages + f)));
  std::mt19937 rng(20261201);
  int with_gps = 0;
  for (const std::vector<std::uint8_t>& full_bytes : blocks) {
    GuardedBuffer buf(full_bytes.size());
    const ExifGeotag full = geotag::parse_exif_app1(full_bytes.data(), full_bytes.size());
    REQUIRE(full.has_gps_position());
    for (std::size_t n = 0; n <= full_bytes.size(); ++n) {
      const ExifGeotag g = geotag::parse_exif_app1(buf.place(full_bytes.data(), n), n);
      check_subset_of(g, full);
      with_gps += g.has_gps_position() ? 1 : 0;
      if (n < 14) CHECK(!g.has_exif);  // "Exif\0\0" + 8-byte TIFF header
    }
    const ExifGeotag whole =
        geotag::parse_exif_app1(buf.place(full_bytes.data(), full_bytes.size()), full_bytes.size());
    CHECK(whole.latitude_deg == full.latitude_deg);
    // Random corruptions: 1..8 flipped bytes anywhere (offsets, counts, types, values).
    std::vector<std::uint8_t> c;
    for (int trial = 0; trial < 3000; ++trial) {
      c = full_bytes;
      const int flips = 1 + static_cast<int>(rng() % 8);
      for (int k = 0; k < flips; ++k)
        c[6 + rng() % (c.size() - 6)] ^= static_cast<std::uint8_t>(1 + rng() % 255);
      check_in_range(geotag::parse_exif_app1(buf.place(c.data(), c.size()), c.size()));
    }
  }
  CHECK(with_gps > 0);
  CHECK(geotag::parse_exif_app1(nullptr, 0).has_exif == false);
}

TEST_CASE("EXIF: truncated JPEG files read what is there", "[geotag][exif][data]") {
  if (!have_lund()) return;
  test::TempDir tmp;
  const std::vector<std::uint8_t> jpg = read_bytes(kLundImages + "01.jpg");
  const ExifGeotag full = geotag::read_exif(kLundImages + "01.jpg");
  const std::string path = tmp.file("cut.jpg");
  int n_gps = 0;
  for (std::size_t n = 0; n < 6000 && n < jpg.size(); n += 37) {
    write_bytes(path, std::vector<std::uint8_t>(jpg.begin(), jpg.begin() + n));
    const ExifGeotag g = geotag::read_exif(path);
    check_subset_of(g, full);
    n_gps += g.has_gps_position() ? 1 : 0;
  }
  CHECK(n_gps > 0);  // the GPS IFD lies inside the first 6000 bytes
  // A segment length that points past the end of the file.
  std::vector<std::uint8_t> bad(jpg.begin(), jpg.begin() + 40);
  bad[4] = 0xFF, bad[5] = 0xFF;
  write_bytes(path, bad);
  CHECK(!geotag::read_exif(path).has_exif);
}

TEST_CASE("Geo-tag CSV: empty cells are taken from EXIF; JPEG folders without a CSV",
          "[geotag][exif][data]") {
  if (!have_lund()) return;
  test::TempDir tmp;
  namespace fs = std::filesystem;
  const std::vector<std::string> names = {"01.jpg", "05.jpg", "10.jpg",
                                          "15.jpg", "20.jpg", "27.jpg"};
  fs::create_directories(tmp.path() / "photos");
  std::string csv = "file,latitude,longitude,height,heading_deg\n";
  for (const std::string& n : names) {
    fs::copy_file(kLundImages + n, tmp.path() / "photos" / n);
    csv += "photos/" + n + ",,,,\n";
  }
  const std::string csv_path = tmp.write("geotags_exif.csv", csv);
  const std::vector<geotag::GeoSource> from_csv = geotag::read_geotag_csv(csv_path);
  std::vector<std::string> skipped;
  const std::vector<geotag::GeoSource> from_dir =
      geotag::read_geotag_sources((tmp.path() / "photos").string(), {}, &skipped);
  CHECK(skipped.empty());
  REQUIRE(from_csv.size() == names.size());
  REQUIRE(from_dir.size() == names.size());
  const double f_px = 35.0 * 1280.0 / std::hypot(36.0, 24.0);  // 1035.4 px
  for (std::size_t i = 0; i < names.size(); ++i) {
    INFO(names[i]);
    const ExifGeotag x = geotag::read_exif(kLundImages + names[i]);
    for (const geotag::GeoSource* s : {&from_csv[i], &from_dir[i]}) {
      CHECK(fs::path(s->path).filename() == names[i]);
      CHECK(s->kind == geotag::SourceKind::kPhoto);
      CHECK(s->tag.id == static_cast<int>(i));
      CHECK(s->tag.latitude_deg == x.latitude_deg);
      CHECK(s->tag.longitude_deg == x.longitude_deg);
      CHECK(s->tag.height == x.altitude_m);
      CHECK(std::isnan(s->tag.heading));
      CHECK(s->photo_camera.fx == Approx(f_px).epsilon(1e-12));
      CHECK(s->photo_camera.fy == s->photo_camera.fx);
      CHECK(s->photo_camera.cx == 511.5);
      CHECK(s->photo_camera.cy == 383.5);
      CHECK(s->photo_camera.width == 1024);
      CHECK(s->photo_camera.height == 768);
    }
  }
  // Given cells win over EXIF; --photo-hfov-deg wins over FocalLengthIn35mmFilm.
  const std::string mixed = tmp.write(
      "mixed.csv", "file,latitude,longitude,height,heading_deg\nphotos/01.jpg,55.5,,12,90\n");
  geotag::GeoSourceOptions hfov;
  hfov.photo_hfov_deg = 90;
  const auto m = geotag::read_geotag_csv(mixed, hfov);
  CHECK(m[0].tag.latitude_deg == 55.5);
  CHECK(m[0].tag.longitude_deg == from_csv[0].tag.longitude_deg);
  CHECK(m[0].tag.height == 12.0);
  CHECK(m[0].tag.heading == Approx(0.5 * 3.14159265358979323846).epsilon(1e-15));
  CHECK(m[0].photo_camera.fx == Approx(512.0).epsilon(1e-12));

  // Views of a photo without heading: NaN heading, refused by view_pose_world().
  const std::vector<geotag::GeoView> views = geotag::make_views(from_dir, map::Camera{});
  REQUIRE(views.size() == names.size());
  CHECK(std::isnan(views[0].heading));
  CHECK_THROWS_AS(geotag::view_pose_world(views[0], geo::LocalFrame::from_geodetic(55.7, 13.2, 0)),
                  InvalidArgument);

  // Needed but absent in EXIF: errors naming the line.
  cv::imwrite(tmp.file("noexif.png"), cv::Mat(30, 40, CV_8U, cv::Scalar(9)));
  cv::imwrite(tmp.file("pano.jpg"), cv::Mat(32, 64, CV_8U, cv::Scalar(9)));
  std::string p = tmp.write("bad1.csv",
                            "file,latitude,longitude,height,heading_deg\n"
                            "photos/01.jpg,55,13,10,0\nnoexif.png,,13,10,0\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p, hfov); }, p, 3, "has no EXIF GPS");
  p = tmp.write("bad2.csv", "file,latitude,longitude,height,heading_deg\nnoexif.png,55,13,,0\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p, hfov); }, p, 2,
                            "has no EXIF GPS altitude");
  p = tmp.write("bad3.csv", "file,latitude,longitude,height,heading_deg\npano.jpg,55,13,10,\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "needs a heading");
  p = tmp.write("bad4.csv", "file,latitude,longitude,height,heading_deg\nnoexif.png,55,13,10,\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "FocalLengthIn35mmFilm");

  // A folder with a JPEG without GPS: skipped and listed; only such files: an error.
  cv::imwrite((tmp.path() / "photos" / "nogps.jpg").string(),
              cv::Mat(30, 40, CV_8U, cv::Scalar(9)));
  const auto with_bad = geotag::read_geotag_sources((tmp.path() / "photos").string(), {}, &skipped);
  CHECK(with_bad.size() == names.size());
  REQUIRE(skipped.size() == 1);
  CHECK(skipped[0].find("nogps.jpg: no EXIF") != std::string::npos);
  fs::create_directories(tmp.path() / "bad");
  fs::copy_file(tmp.path() / "photos" / "nogps.jpg", tmp.path() / "bad" / "a.jpg");
  bool thrown = false;
  try {
    geotag::read_geotag_sources((tmp.path() / "bad").string());
  } catch (const InvalidArgument& e) {
    thrown = true;
    CHECK(std::string(e.what()).find("a.jpg: no EXIF") != std::string::npos);
  }
  CHECK(thrown);
  // EXIF orientation 6 (rotated 90 deg): OpenCV decodes it upright (48 x 64) when the Exif
  // block is the first APP1 (it reads no other), not behind an XMP APP1; the photo's camera
  // follows the decoded image either way. A 2:1 JPEG with a true image direction is a panorama.
  fs::create_directories(tmp.path() / "synthetic");
  write_bytes((tmp.path() / "synthetic" / "a_rotated.jpg").string(),
              jpeg_with_app1(synthetic_app1(true, 'T', 6), 48, false));
  write_bytes((tmp.path() / "synthetic" / "b_rotated_after_xmp.jpg").string(),
              jpeg_with_app1(synthetic_app1(true, 'T', 6), 48, true));
  write_bytes((tmp.path() / "synthetic" / "c_pano.jpg").string(),
              jpeg_with_app1(synthetic_app1(false, 'T'), 32));
  write_bytes((tmp.path() / "synthetic" / "d_pano_magnetic.jpg").string(),
              jpeg_with_app1(synthetic_app1(true, 'M'), 32));
  const auto syn = geotag::read_geotag_sources((tmp.path() / "synthetic").string(), {}, &skipped);
  REQUIRE(syn.size() == 3);
  CHECK(syn[0].photo_camera.width == 48);
  CHECK(syn[0].photo_camera.height == 64);
  for (int k : {0, 1}) {
    const cv::Mat decoded = cv::imread(syn[k].path, cv::IMREAD_GRAYSCALE);
    CHECK(syn[k].kind == geotag::SourceKind::kPhoto);
    CHECK(syn[k].photo_camera.width == decoded.cols);
    CHECK(syn[k].photo_camera.height == decoded.rows);
    CHECK(syn[k].photo_camera.fx == Approx(28.0 * 80.0 / std::hypot(36.0, 24.0)).epsilon(1e-12));
    CHECK(syn[k].tag.heading == Approx(270.1 * 3.14159265358979323846 / 180).epsilon(1e-14));
    CHECK(syn[k].tag.height == -123.4);
  }
  CHECK(syn[2].kind == geotag::SourceKind::kPanorama);
  CHECK(syn[2].tag.heading == Approx(270.1 * 3.14159265358979323846 / 180).epsilon(1e-14));
  REQUIRE(skipped.size() == 1);
  CHECK(skipped[0].find("d_pano_magnetic.jpg: 2:1 panorama without an EXIF true "
                        "GPSImgDirection (only a magnetic one)") != std::string::npos);

  fs::create_directories(tmp.path() / "empty");
  test::require_io_error([&] { geotag::read_geotag_sources((tmp.path() / "empty").string()); },
                         (tmp.path() / "empty").string());
}
