#include "geodrift/geotag/database.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numeric>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "geodrift/error.hpp"
#include "geodrift/geotag/panorama.hpp"
#include "geotag_io.hpp"

namespace geodrift::geotag {

namespace {

constexpr char kMagic[10] = {'G', 'D', 'G', 'E', 'O', 'T', 'A', 'G', 'D', 'B'};
constexpr std::uint32_t kFormatVersion = 1;
constexpr std::uint32_t kByteOrderMark = 0x01020304u;
constexpr std::size_t kCacheSize = 8;

void write_camera(std::ostream& os, const map::Camera& c) {
  io::write_pod<std::int32_t>(os, c.id);
  for (double v : {c.fx, c.fy, c.cx, c.cy}) io::write_pod<double>(os, v);
  io::write_pod<std::int32_t>(os, c.width);
  io::write_pod<std::int32_t>(os, c.height);
}
map::Camera read_camera(std::istream& is) {
  map::Camera c;
  c.id = io::read_pod<std::int32_t>(is, "camera");
  c.fx = io::read_pod<double>(is, "camera");
  c.fy = io::read_pod<double>(is, "camera");
  c.cx = io::read_pod<double>(is, "camera");
  c.cy = io::read_pod<double>(is, "camera");
  c.width = io::read_pod<std::int32_t>(is, "camera");
  c.height = io::read_pod<std::int32_t>(is, "camera");
  return c;
}
void write_tag(std::ostream& os, const map::GeoTag& t) {
  io::write_pod<std::int32_t>(os, t.id);
  for (double v : {t.latitude_deg, t.longitude_deg, t.height, t.heading})
    io::write_pod<double>(os, v);
}
map::GeoTag read_tag(std::istream& is) {
  map::GeoTag t;
  t.id = io::read_pod<std::int32_t>(is, "geo-tag");
  t.latitude_deg = io::read_pod<double>(is, "geo-tag");
  t.longitude_deg = io::read_pod<double>(is, "geo-tag");
  t.height = io::read_pod<double>(is, "geo-tag");
  t.heading = io::read_pod<double>(is, "geo-tag");
  return t;
}

/// RootSIFT values lie in [0, 1]; 8 bits per value keep the database's descriptors at 128 B
/// (quantisation error 0.002, far below the spread of a vocabulary cell).
cv::Mat to_u8(const cv::Mat& f) {
  cv::Mat u;
  f.convertTo(u, CV_8U, 255.0);
  return u;
}

}  // namespace

Database Database::build(const std::vector<GeoSource>& sources, const BuildOptions& o) {
  GEODRIFT_CHECK(!sources.empty(), "geotag database: no geo-tagged sources given");
  GEODRIFT_CHECK(o.sift_features >= 10, "sift_features " << o.sift_features << " must be >= 10");
  GEODRIFT_CHECK(o.orb_features >= 10, "orb_features " << o.orb_features << " must be >= 10");
  Database db;
  db.video_camera_ = o.video_camera;
  db.sift_features_ = o.sift_features;
  db.orb_features_ = o.orb_features;
  db.sources_ = sources;
  db.views_ = make_views(sources, o.video_camera);
  db.orb_.resize(db.views_.size());
  std::vector<cv::Mat> sift(db.views_.size());  // CV_8U RootSIFT per view

  // Views are grouped by source (make_views() emits them in source order).
  std::size_t next_view = 0;
  for (std::size_t s = 0; s < sources.size(); ++s) {
    const cv::Mat gray = db.source_gray(static_cast<int>(s));
    while (next_view < db.views_.size() && db.views_[next_view].source == static_cast<int>(s)) {
      const GeoView& v = db.views_[next_view];
      const cv::Mat img =
          v.direction >= 0
              ? cut_panorama_view(gray, v.camera,
                                  v.direction * kViewStepDeg * 3.14159265358979323846 / 180.0)
              : gray;
      sift[next_view] = to_u8(detect_root_sift(img, o.sift_features).descriptors);
      db.orb_[next_view] = detect_orb(img, o.orb_features);
      ++next_view;
    }
    if (o.progress) o.progress("views", s + 1, sources.size());
  }
  db.cache_.clear();

  // Vocabulary training set: a seeded uniform subsample of all view descriptors.
  std::size_t total = 0;
  for (const cv::Mat& d : sift) total += d.rows;
  GEODRIFT_CHECK(total >= static_cast<std::size_t>(o.vocabulary.branching) * 2,
                 "geotag database: only " << total << " SIFT features in " << db.views_.size()
                                          << " views; too few to train a vocabulary");
  std::vector<std::pair<int, int>> all;  // (view, row)
  all.reserve(total);
  for (std::size_t v = 0; v < sift.size(); ++v)
    for (int r = 0; r < sift[v].rows; ++r) all.push_back({static_cast<int>(v), r});
  std::mt19937_64 rng(o.vocabulary.seed);
  const std::size_t n_train = std::min<std::size_t>(
      all.size(), static_cast<std::size_t>(o.vocabulary.max_training_descriptors));
  if (n_train < all.size()) {
    std::shuffle(all.begin(), all.end(), rng);
    all.resize(n_train);
  }
  cv::Mat train(static_cast<int>(all.size()), 128, CV_32F);
  for (std::size_t i = 0; i < all.size(); ++i)
    sift[all[i].first]
        .row(all[i].second)
        .convertTo(train.row(static_cast<int>(i)), CV_32F, 1.0 / 255.0);
  db.vocabulary_ = Vocabulary::train(train, o.vocabulary, [&](std::size_t d, std::size_t t) {
    if (o.progress) o.progress("vocabulary", d, t);
  });

  std::vector<std::vector<int>> words(sift.size());
  for (std::size_t v = 0; v < sift.size(); ++v) {
    cv::Mat f;
    sift[v].convertTo(f, CV_32F, 1.0 / 255.0);
    words[v] = db.vocabulary_.quantize(f);
    if (o.progress && (v % 16 == 15 || v + 1 == sift.size()))
      o.progress("index", v + 1, sift.size());
  }
  db.index_ = InvertedIndex(words, db.vocabulary_.num_words());
  return db;
}

cv::Mat Database::source_gray(int s) const {
  for (auto it = cache_.begin(); it != cache_.end(); ++it)
    if (it->first == s) {
      cache_.splice(cache_.begin(), cache_, it);
      return cache_.front().second;
    }
  const GeoSource& src = sources_.at(s);
  cv::Mat g = cv::imread(src.path, cv::IMREAD_GRAYSCALE);
  if (g.empty()) throw Error("cannot read geo-tagged image '" + src.path + "'");
  if (src.kind == SourceKind::kPanorama && g.cols != 2 * g.rows)
    throw Error("panorama '" + src.path + "' is " + std::to_string(g.cols) + "x" +
                std::to_string(g.rows) + ", not 2:1 equirectangular");
  if (src.kind == SourceKind::kPhoto &&
      (g.cols != src.photo_camera.width || g.rows != src.photo_camera.height))
    throw Error("photo '" + src.path + "' changed size since the database was built");
  cache_.push_front({s, g});
  if (cache_.size() > kCacheSize) cache_.pop_back();
  return g;
}

cv::Mat Database::view_image(int view) const {
  const GeoView& v = views_.at(view);
  const cv::Mat g = source_gray(v.source);
  if (v.direction < 0) return g;
  return cut_panorama_view(g, v.camera,
                           v.direction * kViewStepDeg * 3.14159265358979323846 / 180.0);
}

std::vector<Retrieved> Database::query(const cv::Mat& gray, const QueryOptions& o) const {
  return query_descriptors(
      detect_root_sift(gray, sift_features_ > 0 ? sift_features_ : 1000).descriptors, o);
}

std::vector<Retrieved> Database::query_descriptors(const cv::Mat& d, const QueryOptions& o) const {
  GEODRIFT_CHECK(o.top_k >= 1, "retrieval top_k " << o.top_k << " must be >= 1");
  GEODRIFT_CHECK(!o.gate_position_w || o.frame != nullptr,
                 "retrieval distance gate needs the world frame");
  GEODRIFT_CHECK(!o.gate_position_w || (o.gate_radius_m > 0 && o.gate_position_w->allFinite()),
                 "retrieval distance gate: radius " << o.gate_radius_m
                                                    << " m must be > 0 and the position finite");
  GEODRIFT_CHECK(!vocabulary_.empty(), "geotag database is empty");
  const std::vector<float> s = index_.scores(index_.vectorize(vocabulary_.quantize(d)));
  std::vector<Retrieved> cand;
  std::vector<Eigen::Vector3d> src_pos;
  if (o.gate_position_w) {
    src_pos.resize(sources_.size());
    for (std::size_t i = 0; i < sources_.size(); ++i)
      src_pos[i] = o.frame->to_world(sources_[i].tag.latitude_deg, sources_[i].tag.longitude_deg,
                                     sources_[i].tag.height);
  }
  for (std::size_t v = 0; v < s.size(); ++v) {
    if (!(s[v] > 0)) continue;
    if (o.gate_position_w) {
      const Eigen::Vector3d dp = src_pos[views_[v].source] - *o.gate_position_w;
      if (std::hypot(dp.x(), dp.y()) > o.gate_radius_m) continue;
    }
    cand.push_back({static_cast<int>(v), s[v]});
  }
  const std::size_t k = std::min<std::size_t>(cand.size(), static_cast<std::size_t>(o.top_k));
  std::partial_sort(cand.begin(), cand.begin() + k, cand.end(),
                    [](const Retrieved& a, const Retrieved& b) {
                      return a.score > b.score || (a.score == b.score && a.view < b.view);
                    });
  cand.resize(k);
  return cand;
}

void Database::save(const std::string& path) const {
  namespace fs = std::filesystem;
  const fs::path target(path);
  const fs::path tmp = target.string() + ".tmp-" + std::to_string(::getpid());
  {
    std::ofstream os(tmp, std::ios::binary | std::ios::trunc);
    if (!os) throw Error("cannot write geotag database '" + tmp.string() + "'");
    os.write(kMagic, sizeof kMagic);
    io::write_pod(os, kFormatVersion);
    io::write_pod(os, kByteOrderMark);
    io::write_pod<std::int32_t>(os, sift_features_);
    io::write_pod<std::int32_t>(os, orb_features_);
    write_camera(os, video_camera_);
    io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(sources_.size()));
    for (const GeoSource& s : sources_) {
      write_tag(os, s.tag);
      io::write_string(os, s.path);
      io::write_pod<std::int32_t>(os, s.kind == SourceKind::kPanorama ? 0 : 1);
      write_camera(os, s.photo_camera);
      io::write_pod<std::int32_t>(os, s.frame);
    }
    io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(views_.size()));
    for (const GeoView& v : views_) {
      io::write_pod<std::int32_t>(os, v.source);
      io::write_pod<double>(os, v.heading);
      io::write_pod<std::int32_t>(os, v.direction);
      write_camera(os, v.camera);
    }
    vocabulary_.write(os);
    index_.write(os);
    for (const Features& f : orb_) {
      io::write_pod<std::int32_t>(os, static_cast<std::int32_t>(f.keypoints.size()));
      for (const cv::KeyPoint& k : f.keypoints) {
        for (float x : {k.pt.x, k.pt.y, k.size, k.angle, k.response}) io::write_pod<float>(os, x);
        io::write_pod<std::int32_t>(os, k.octave);
      }
      io::write_mat(os, f.descriptors);
    }
    os.write(kMagic, sizeof kMagic);  // trailer: detects truncation at the very end
    os.flush();
    if (!os) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw Error("error while writing geotag database '" + tmp.string() + "'");
    }
  }
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw Error("cannot move the geotag database into place at '" + path + "'");
  }
}

Database Database::load(const std::string& path) {
  std::ifstream is(path, std::ios::binary);
  if (!is) throw Error("cannot open geotag database '" + path + "'");
  try {
    char magic[sizeof kMagic];
    is.read(magic, sizeof magic);
    if (is.gcount() != sizeof magic || std::memcmp(magic, kMagic, sizeof magic) != 0)
      throw Error("not a geodrift geotag database");
    const auto version = io::read_pod<std::uint32_t>(is, "version");
    if (version != kFormatVersion)
      throw Error("format version " + std::to_string(version) + ", this build reads " +
                  std::to_string(kFormatVersion));
    if (io::read_pod<std::uint32_t>(is, "byte order") != kByteOrderMark)
      throw Error("written on a machine of the other byte order");
    Database db;
    db.sift_features_ = io::read_pod<std::int32_t>(is, "settings");
    db.orb_features_ = io::read_pod<std::int32_t>(is, "settings");
    db.video_camera_ = read_camera(is);
    const int ns = io::read_pod<std::int32_t>(is, "source count");
    if (ns < 1 || ns > (1 << 24)) throw Error("corrupt source count");
    db.sources_.resize(ns);
    for (GeoSource& s : db.sources_) {
      s.tag = read_tag(is);
      s.path = io::read_string(is, "source path");
      s.kind = io::read_pod<std::int32_t>(is, "source kind") == 0 ? SourceKind::kPanorama
                                                                  : SourceKind::kPhoto;
      s.photo_camera = read_camera(is);
      s.frame = io::read_pod<std::int32_t>(is, "source frame");
    }
    const int nv = io::read_pod<std::int32_t>(is, "view count");
    if (nv < 1 || nv > (1 << 26)) throw Error("corrupt view count");
    db.views_.resize(nv);
    for (int i = 0; i < nv; ++i) {
      GeoView& v = db.views_[i];
      v.id = i;
      v.source = io::read_pod<std::int32_t>(is, "view");
      if (v.source < 0 || v.source >= ns) throw Error("view names unknown source");
      v.heading = io::read_pod<double>(is, "view");
      v.direction = io::read_pod<std::int32_t>(is, "view");
      v.camera = read_camera(is);
      v.tag = db.sources_[v.source].tag;
      v.frame = db.sources_[v.source].frame;
    }
    db.vocabulary_ = Vocabulary::read(is);
    db.index_ = InvertedIndex::read(is);
    if (db.index_.num_documents() != nv) throw Error("index and views disagree");
    db.orb_.resize(nv);
    for (Features& f : db.orb_) {
      const int n = io::read_pod<std::int32_t>(is, "keypoint count");
      if (n < 0 || n > (1 << 20)) throw Error("corrupt keypoint count");
      f.keypoints.resize(n);
      for (cv::KeyPoint& k : f.keypoints) {
        k.pt.x = io::read_pod<float>(is, "keypoint");
        k.pt.y = io::read_pod<float>(is, "keypoint");
        k.size = io::read_pod<float>(is, "keypoint");
        k.angle = io::read_pod<float>(is, "keypoint");
        k.response = io::read_pod<float>(is, "keypoint");
        k.octave = io::read_pod<std::int32_t>(is, "keypoint");
      }
      f.descriptors = io::read_mat(is, "ORB descriptors");
      if (f.descriptors.rows != n) throw Error("keypoints and descriptors disagree");
    }
    is.read(magic, sizeof magic);
    if (is.gcount() != sizeof magic || std::memcmp(magic, kMagic, sizeof magic) != 0)
      throw Error("file is truncated or has trailing garbage before the trailer");
    return db;
  } catch (const Error& e) {  // InvalidArgument included
    throw Error("geotag database '" + path + "': " + e.what());
  }
}

}  // namespace geodrift::geotag
