// The retrieval database on real geo-tagged photos (Lund street, OpenSfM/Mapillary) and its
// file format.
#include <catch2/catch.hpp>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <geodrift/geotag/database.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "support/kitti.hpp"
#include "support/test_files.hpp"

using namespace geodrift;

namespace {
const std::string kLund = std::string(GEODRIFT_DATA_DIR) + "/opensfm_lund/lund_exif_gps.csv";

bool have_lund() {
  if (std::filesystem::exists(kLund)) return true;
  WARN("Lund data not found at " << kLund);
  return false;
}

geotag::Database::BuildOptions small_options() {
  geotag::Database::BuildOptions o;
  o.sift_features = 800;
  o.orb_features = 500;
  o.vocabulary.branching = 12;
  o.vocabulary.depth = 3;
  return o;
}
}  // namespace

TEST_CASE("Database on the Lund photos: build, retrieve, gate, save and load",
          "[geotag][database][data]") {
  if (!have_lund()) return;
  geotag::GeoSourceOptions so;
  so.photo_hfov_deg = 60.0;
  const std::vector<geotag::GeoSource> sources = geotag::read_geotag_csv(kLund, so);
  REQUIRE(sources.size() == 29);
  CHECK(sources[0].kind == geotag::SourceKind::kPhoto);
  CHECK(sources[0].photo_camera.width == 1024);
  CHECK(sources[0].tag.latitude_deg == Approx(55.698167));
  CHECK(sources[0].tag.heading == Approx(179.2156 * M_PI / 180.0));

  std::size_t last_done = 0;
  int calls = 0;
  geotag::Database::BuildOptions o = small_options();
  o.progress = [&](const char*, std::size_t done, std::size_t) {
    last_done = done;
    ++calls;
  };
  const geotag::Database db = geotag::Database::build(sources, o);
  REQUIRE(db.views().size() == 29);
  CHECK(calls > 29);
  CHECK(last_done == 29);  // the index stage ends at its last view
  CHECK(db.vocabulary().num_words() > 1000);
  CHECK(db.vocabulary().num_words() <= 1728);

  // Each photo, altered (75 % size, darker, blurred), retrieves itself or a neighbour first.
  int self_top1 = 0, self_top3 = 0;
  double max_top1_dist = 0;
  for (int i = 0; i < 29; ++i) {
    cv::Mat g = cv::imread(sources[i].path, cv::IMREAD_GRAYSCALE);
    REQUIRE(!g.empty());
    cv::resize(g, g, cv::Size(), 0.75, 0.75, cv::INTER_AREA);
    g.convertTo(g, CV_8U, 0.8, 10.0);
    cv::GaussianBlur(g, g, cv::Size(3, 3), 0.8);
    geotag::QueryOptions q;
    q.top_k = 3;
    const std::vector<geotag::Retrieved> r = db.query(g, q);
    REQUIRE(!r.empty());
    self_top1 += r[0].view == i ? 1 : 0;
    for (const geotag::Retrieved& x : r) self_top3 += x.view == i ? 1 : 0;
    const geo::LocalFrame f0 = geo::LocalFrame::from_geodetic(
        sources[i].tag.latitude_deg, sources[i].tag.longitude_deg, sources[i].tag.height);
    const Eigen::Vector3d d = geotag::view_position_world(db.views()[r[0].view], f0);
    max_top1_dist = std::max(max_top1_dist, std::hypot(d.x(), d.y()));
    CHECK(r[0].score <= 1.0f + 1e-5f);
  }
  INFO(self_top1 << " of 29 first, " << self_top3 << " in the top 3; worst first hit at "
                 << max_top1_dist << " m");
  // The photos are 6 m apart along one street; neighbours share most of the scene, so a
  // neighbour may outrank the photo itself, but never anything farther than ~2 photos away.
  CHECK(self_top1 >= 27);
  CHECK(self_top3 >= 28);
  CHECK(max_top1_dist < 15.0);

  // Distance gate: around photo 0, only views within the radius come back.
  const geo::LocalFrame frame = geo::LocalFrame::from_geodetic(
      sources[0].tag.latitude_deg, sources[0].tag.longitude_deg, sources[0].tag.height);
  geotag::QueryOptions gate;
  gate.top_k = 29;
  gate.frame = &frame;
  gate.gate_position_w = Eigen::Vector3d::Zero();
  gate.gate_radius_m = 40.0;
  const cv::Mat q0 = db.view_image(5);
  const std::vector<geotag::Retrieved> all = db.query(q0, [] {
    geotag::QueryOptions a;
    a.top_k = 29;
    return a;
  }());
  const std::vector<geotag::Retrieved> near = db.query(q0, gate);
  CHECK(!near.empty());
  CHECK(near.size() < all.size());
  for (const geotag::Retrieved& r : near) {
    const Eigen::Vector3d p = geotag::view_position_world(db.views()[r.view], frame);
    CHECK(std::hypot(p.x(), p.y()) <= 40.0);
  }

  // Save, load: same views, same answers.
  test::TempDir tmp;
  const std::string path = tmp.file("lund.gdb");
  db.save(path);
  CHECK(tmp.num_entries() == 1);  // no temporary left behind
  const geotag::Database back = geotag::Database::load(path);
  REQUIRE(back.views().size() == db.views().size());
  CHECK(back.vocabulary().num_words() == db.vocabulary().num_words());
  for (std::size_t v = 0; v < db.views().size(); ++v) {
    CHECK(back.views()[v].heading == db.views()[v].heading);
    CHECK(back.views()[v].tag.latitude_deg == db.views()[v].tag.latitude_deg);
    const geotag::OrbFeatures a = db.orb(static_cast<int>(v)), b = back.orb(static_cast<int>(v));
    REQUIRE(b.size == a.size);
    CHECK(a.size > 100);
    CHECK(cv::norm(b.descriptors, a.descriptors, cv::NORM_HAMMING) == 0);
    CHECK(std::memcmp(a.keypoints, b.keypoints, sizeof(geotag::StoredKeypoint) * a.size) == 0);
  }
  CHECK(back.memory_mapped());
  CHECK_FALSE(db.memory_mapped());
  CHECK(back.retrieval_scale() == db.retrieval_scale());
  CHECK(db.retrieval_scale() == 0.5);  // photos are resized by BuildOptions::retrieval_scale
  CHECK_THROWS_AS(back.orb(static_cast<int>(db.views().size())), std::out_of_range);
  // A copy shares the mapping and outlives the original.
  std::optional<geotag::Database> copy;
  {
    const geotag::Database tmp_db = geotag::Database::load(path);
    copy = tmp_db;
  }
  CHECK(cv::norm(copy->orb(3).descriptors, db.orb(3).descriptors, cv::NORM_HAMMING) == 0);
  // Saving a loaded (mapped) database writes the same bytes.
  copy->save(tmp.file("again.gdb"));
  CHECK(test::read_text(tmp.file("again.gdb")) == test::read_text(path));
  std::filesystem::remove(tmp.file("again.gdb"));
  const std::vector<geotag::Retrieved> again = back.query(q0, gate);
  REQUIRE(again.size() == near.size());
  for (std::size_t i = 0; i < near.size(); ++i) {
    CHECK(again[i].view == near[i].view);
    CHECK(again[i].score == near[i].score);
  }

  // Views are spread over threads; the database does not depend on how many.
  {
    const int threads = cv::getNumThreads();
    cv::setNumThreads(1);
    const geotag::Database serial = geotag::Database::build(sources, small_options());
    cv::setNumThreads(threads);
    serial.save(tmp.file("serial.gdb"));
    CHECK(test::read_text(tmp.file("serial.gdb")) == test::read_text(path));
    std::filesystem::remove(tmp.file("serial.gdb"));
  }
  // Two unreadable images: the error names the first in the list, whichever thread met it.
  {
    std::vector<geotag::GeoSource> bad = sources;
    bad[21].path = tmp.file("gone_21.jpg");
    bad[4].path = tmp.file("gone_4.jpg");
    try {
      geotag::Database::build(bad, small_options());
      FAIL("a missing image was accepted");
    } catch (const Error& e) {
      CHECK(std::string(e.what()).find("gone_4.jpg") != std::string::npos);
    }
  }

  // A truncated copy and a foreign file are refused with the path in the message.
  const std::string bytes = test::read_text(path);
  test::write_text(tmp.file("cut.gdb"), bytes.substr(0, bytes.size() / 2));
  test::require_io_error([&] { geotag::Database::load(tmp.file("cut.gdb")); }, tmp.file("cut.gdb"));
  // Cut anywhere in the mapped blocks, a byte appended, an older format version: all refused
  // before anything is mapped (a mapped file shorter than its tables would fault on access).
  for (const std::size_t keep : {bytes.size() - 1, bytes.size() - 11, bytes.size() - 5000}) {
    test::write_text(tmp.file("short.gdb"), bytes.substr(0, keep));
    test::require_io_error([&] { geotag::Database::load(tmp.file("short.gdb")); },
                           tmp.file("short.gdb"));
  }
  test::write_text(tmp.file("long.gdb"), bytes + "x");
  test::require_io_error([&] { geotag::Database::load(tmp.file("long.gdb")); },
                         tmp.file("long.gdb"));
  std::string v1 = bytes;
  v1[10] = 1;  // the format version follows the 10-byte magic
  test::write_text(tmp.file("v1.gdb"), v1);
  try {
    geotag::Database::load(tmp.file("v1.gdb"));
    FAIL("a format-1 database was accepted");
  } catch (const Error& e) {
    CHECK(std::string(e.what()).find("rebuild") != std::string::npos);
  }
  test::write_text(tmp.file("other.gdb"), "hello, world, this is not a database at all");
  test::require_io_error([&] { geotag::Database::load(tmp.file("other.gdb")); },
                         tmp.file("other.gdb"));
  test::require_io_error([&] { geotag::Database::load(tmp.file("missing.gdb")); },
                         tmp.file("missing.gdb"));
}

TEST_CASE("Geo-tag CSVs with bad rows are refused naming the line", "[geotag][database][errors]") {
  test::TempDir tmp;
  // A tiny 2:1 image (a panorama) and a 4:3 one (a photo).
  cv::imwrite(tmp.file("p.png"), cv::Mat(32, 64, CV_8U, cv::Scalar(9)));
  cv::imwrite(tmp.file("q.png"), cv::Mat(30, 40, CV_8U, cv::Scalar(9)));
  const std::string h = "id,file,latitude,longitude,height,heading_deg\n";
  const auto csv = [&](const std::string& name, const std::string& body) {
    test::write_text(tmp.file(name), body);
    return tmp.file(name);
  };
  {
    const auto s = geotag::read_geotag_csv(csv("ok.csv", h + "3,p.png,49.0,8.4,160,90\n"));
    REQUIRE(s.size() == 1);
    CHECK(s[0].kind == geotag::SourceKind::kPanorama);
    CHECK(s[0].tag.id == 3);
  }
  std::string p = csv("nan.csv", h + "0,p.png,nan,8.4,160,90\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "latitude");
  p = csv("range.csv", h + "0,p.png,95,8.4,160,90\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "outside");
  p = csv("short.csv", h + "0,p.png,49,8.4\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "fields");
  p = csv("missing.csv", h + "0,none.png,49,8.4,160,90\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "does not exist");
  p = csv("nocol.csv", "id,file,latitude,longitude,height\n0,p.png,49,8.4,160\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 1, "heading_deg");
  p = csv("photo.csv", h + "0,q.png,49,8.4,160,90\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "intrinsics");
  p = csv("kind.csv", "file,latitude,longitude,height,heading_deg,kind\nq.png,49,8,1,0,panorama\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "not 2:1");
  test::write_text(tmp.file("garbage.png"), "not an image");
  p = csv("garbage.csv", h + "0,garbage.png,49,8.4,160,90\n");
  test::require_parse_error([&] { geotag::read_geotag_csv(p); }, p, 2, "cannot be read");
  p = csv("empty.csv", h);
  test::require_io_error([&] { geotag::read_geotag_csv(p); }, p);
  test::require_io_error([&] { geotag::read_geotag_csv(tmp.file("nope.csv")); },
                         tmp.file("nope.csv"));
  CHECK_THROWS_AS(geotag::Database::build({}, geotag::Database::BuildOptions{}), InvalidArgument);
  // Black images: no features, so no vocabulary; a clear error, no crash.
  cv::imwrite(tmp.file("black.png"), cv::Mat(300, 400, CV_8U, cv::Scalar(0)));
  geotag::GeoSourceOptions so;
  so.photo_hfov_deg = 60;
  const auto black =
      geotag::read_geotag_csv(csv("black.csv", h + "0,black.png,49,8.4,160,90\n"), so);
  CHECK_THROWS_AS(geotag::Database::build(black, small_options()), Error);
}

TEST_CASE("Panorama views are resized for retrieval to half their panorama's own resolution",
          "[geotag][database]") {
  // Two 1024 x 512 panoramas of smoothed noise: 2.85 px/deg, against 12.5 px/deg at the centre
  // of a KITTI view (fx 718.856), so views and queries are resized by half of 1024 / (2 pi fx):
  // SIFT's doubled first octave then sits at the panorama's own pixels.
  test::TempDir tmp;
  cv::RNG rng(7);
  std::vector<geotag::GeoSource> sources;
  for (int i = 0; i < 2; ++i) {
    cv::Mat pano(512, 1024, CV_8U);
    rng.fill(pano, cv::RNG::UNIFORM, 0, 256);
    cv::GaussianBlur(pano, pano, cv::Size(0, 0), 2.0);
    const std::string path = tmp.file("pano_" + std::to_string(i) + ".png");
    REQUIRE(cv::imwrite(path, pano));
    geotag::GeoSource s;
    s.tag.id = i;
    s.tag.latitude_deg = 49.011 + 1e-4 * i;
    s.tag.longitude_deg = 8.417;
    s.tag.height = 160;
    s.tag.heading = 0;
    s.path = path;
    s.kind = geotag::SourceKind::kPanorama;
    sources.push_back(s);
  }
  geotag::Database::BuildOptions o = small_options();
  o.video_camera = test::kitti_camera();
  const geotag::Database db = geotag::Database::build(sources, o);
  REQUIRE(db.views().size() == 16);
  const double native = 1024.0 / (2.0 * 3.14159265358979323846 * o.video_camera.fx);
  CHECK(native == Approx(0.2267).margin(1e-4));
  CHECK(db.retrieval_scale() == Approx(0.5 * native).epsilon(1e-12));
  // Each view retrieves itself first when queried with its own image.
  for (int v : {0, 5, 11}) {
    geotag::QueryOptions q;
    q.top_k = 1;
    const std::vector<geotag::Retrieved> r = db.query(db.view_image(v), q);
    REQUIRE(r.size() == 1);
    CHECK(r[0].view == v);
  }
  // A smaller BuildOptions::retrieval_scale caps it.
  o.retrieval_scale = 0.1;
  CHECK(geotag::Database::build(sources, o).retrieval_scale() == 0.1);
}

TEST_CASE("The inverted file's idf: shared-by-all words carry no weight and are counted",
          "[geotag][database]") {
  // Three views over 4 words: word 0 in all of them, 1 in two, 2 in one, 3 in none.
  const geotag::InvertedIndex ix({{0, 1, 2, 2}, {0, 1}, {0}}, 4);
  CHECK(ix.idf(0) == 0.0);
  CHECK(ix.idf(1) == Approx(std::log(3.0 / 2.0)));
  CHECK(ix.idf(2) == Approx(std::log(3.0)));
  CHECK(ix.idf(3) == 0.0);
  CHECK(ix.num_informative_words() == 2);
  // A query made of view 0's words scores view 0 highest; view 2 (only word 0) scores 0.
  const std::vector<float> s = ix.scores(ix.vectorize({0, 1, 2, 2}));
  REQUIRE(s.size() == 3);
  CHECK(s[0] == Approx(1.0f));
  CHECK(s[1] > 0.0f);
  CHECK(s[1] < s[0]);
  CHECK(s[2] == 0.0f);
  // A vocabulary so coarse that every word is in every view cannot rank anything.
  const geotag::InvertedIndex coarse({{0, 1}, {1, 0, 0}}, 2);
  CHECK(coarse.num_informative_words() == 0);
  for (float x : coarse.scores(coarse.vectorize({0, 1}))) CHECK(x == 0.0f);
}
