#include "geodrift/geotag/database.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <numeric>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <random>

#include "geodrift/error.hpp"
#include "geodrift/geotag/panorama.hpp"
#include "geotag_io.hpp"

namespace geodrift::geotag {

namespace {

constexpr char kMagic[10] = {'G', 'D', 'G', 'E', 'O', 'T', 'A', 'G', 'D', 'B'};
// 2: retrieval scale after the settings; ORB of all views in two aligned blocks (mapped)
constexpr std::uint32_t kFormatVersion = 2;
constexpr std::uint32_t kByteOrderMark = 0x01020304u;
constexpr std::size_t kCacheSize = 8;
constexpr double kPi = 3.14159265358979323846;
constexpr int kOrbBytes = 32;            // ORB descriptor width
constexpr std::int64_t kAlignment = 64;  // of the keypoint and descriptor blocks in the file

std::int64_t align_up(std::int64_t x) { return (x + kAlignment - 1) / kAlignment * kAlignment; }

void pad_to(std::ostream& os, std::int64_t offset) {
  static const char zeros[kAlignment] = {};
  const std::int64_t at = static_cast<std::int64_t>(os.tellp());
  if (at < offset) os.write(zeros, static_cast<std::streamsize>(offset - at));
}

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

/// The image retrieval extracts RootSIFT from: `gray` resized by `scale` (area averaging).
cv::Mat retrieval_image(const cv::Mat& gray, double scale) {
  if (scale == 1.0) return gray;
  cv::Mat small;
  const cv::Size size(std::max(1, static_cast<int>(std::lround(gray.cols * scale))),
                      std::max(1, static_cast<int>(std::lround(gray.rows * scale))));
  cv::resize(gray, small, size, 0, 0, cv::INTER_AREA);
  return small;
}

/// A source's grayscale image, checked against what the source says it is.
cv::Mat read_source_gray(const GeoSource& src) {
  cv::Mat g = cv::imread(src.path, cv::IMREAD_GRAYSCALE);
  if (g.empty()) throw Error("cannot read geo-tagged image '" + src.path + "'");
  if (src.kind == SourceKind::kPanorama && g.cols != 2 * g.rows)
    throw Error("panorama '" + src.path + "' is " + std::to_string(g.cols) + "x" +
                std::to_string(g.rows) + ", not 2:1 equirectangular");
  if (src.kind == SourceKind::kPhoto &&
      (g.cols != src.photo_camera.width || g.rows != src.photo_camera.height))
    throw Error("photo '" + src.path + "' changed size since the database was built");
  return g;
}

/// View `v` of its source's image: the photo itself, or the view cut from the panorama with
/// `*cutter`'s remap tables (made again when the panorama size or view camera changes).
cv::Mat cut_source_view(const cv::Mat& source_gray, const GeoView& v,
                        std::optional<PanoramaCutter>* cutter) {
  if (v.direction < 0) return source_gray;
  if (!*cutter || !(*cutter)->fits(source_gray.cols, source_gray.rows, v.camera))
    cutter->emplace(source_gray.cols, source_gray.rows, v.camera);
  return (*cutter)->cut(source_gray, v.direction * kViewStepDeg * kPi / 180.0);
}

}  // namespace

Database Database::build(const std::vector<GeoSource>& sources, const BuildOptions& o) {
  GEODRIFT_CHECK(!sources.empty(), "geotag database: no geo-tagged sources given");
  GEODRIFT_CHECK(o.sift_features >= 10, "sift_features " << o.sift_features << " must be >= 10");
  GEODRIFT_CHECK(o.orb_features >= 10, "orb_features " << o.orb_features << " must be >= 10");
  GEODRIFT_CHECK(o.retrieval_scale > 0 && o.retrieval_scale <= 1,
                 "retrieval_scale " << o.retrieval_scale << " outside (0, 1]");
  Database db;
  db.retrieval_scale_ = o.retrieval_scale;
  db.video_camera_ = o.video_camera;
  db.sift_features_ = o.sift_features;
  db.orb_features_ = o.orb_features;
  db.sources_ = sources;
  db.views_ = make_views(sources, o.video_camera);
  db.orb_begin_.assign(1, 0);
  std::vector<cv::Mat> sift(db.views_.size());  // CV_8U RootSIFT per view

  // Views are grouped by source (make_views() emits them in source order). Sources are spread
  // over OpenCV's worker threads, each worker running SIFT and ORB single-threaded (OpenCV
  // runs a parallel_for_ nested in another serially): per view this costs 20-25 % less CPU than
  // one view at a time with OpenCV's own threads inside SIFT and ORB. Finished sources are
  // appended in source order, so the database does not depend on the thread count.
  std::vector<std::size_t> first_view(sources.size() + 1, db.views_.size());
  for (std::size_t v = db.views_.size(); v-- > 0;)
    first_view[static_cast<std::size_t>(db.views_[v].source)] = v;
  for (std::size_t s = sources.size(); s-- > 0;)
    first_view[s] = std::min(first_view[s], first_view[s + 1]);
  std::vector<std::vector<StoredKeypoint>> orb_keypoints(db.views_.size());
  std::vector<cv::Mat> orb_descriptors(db.views_.size());
  std::vector<double> scale(db.views_.size());  // each view's retrieval scale
  std::atomic<std::size_t> next_source{0};
  std::mutex mutex;  // guards the database's arrays, done, finished, failure, the callback
  std::size_t done = 0, appended = 0;  // sources finished, sources appended to the database
  std::vector<char> finished(sources.size(), 0);
  // Reserved at the largest size (address space; pages are touched as they are written).
  db.orb_keypoints_.reserve(db.views_.size() * static_cast<std::size_t>(o.orb_features));
  db.orb_descriptors_.reserve(db.orb_keypoints_.capacity() * kOrbBytes);
  std::atomic<std::size_t> failed_source{sources.size()};  // the first that failed so far
  std::exception_ptr failure;
  const int workers = std::max(1, std::min(cv::getNumThreads(), static_cast<int>(sources.size())));
  cv::parallel_for_(
      cv::Range(0, workers),
      [&](const cv::Range& range) {
        for (int w = range.start; w < range.end; ++w) {
          std::optional<PanoramaCutter> cutter;  // this worker's remap tables
          for (std::size_t s = next_source++; s < sources.size(); s = next_source++) {
            if (s > failed_source) continue;  // a source before it failed: the build is over
            try {
              const cv::Mat gray = read_source_gray(sources[s]);
              for (std::size_t v = first_view[s]; v < first_view[s + 1]; ++v) {
                const GeoView& view = db.views_[v];
                const cv::Mat img = cut_source_view(gray, view, &cutter);
                // SIFT doubles its input for its first octave: a panorama view resized to half
                // its panorama's own resolution at the view's centre has that octave at the
                // panorama's pixels, the finest detail the view holds.
                scale[v] =
                    view.direction < 0
                        ? o.retrieval_scale
                        : std::min(o.retrieval_scale, 0.5 * gray.cols / (2 * kPi * view.camera.fx));
                sift[v] = to_u8(
                    detect_root_sift(retrieval_image(img, scale[v]), o.sift_features).descriptors);
                const Features f = detect_orb(img, o.orb_features);
                GEODRIFT_ASSERT(f.descriptors.cols == kOrbBytes && f.descriptors.isContinuous());
                orb_keypoints[v].reserve(f.keypoints.size());
                for (const cv::KeyPoint& k : f.keypoints)
                  orb_keypoints[v].push_back(
                      {k.pt.x, k.pt.y, k.size, k.angle, k.response, k.octave});
                orb_descriptors[v] = f.descriptors;
              }
            } catch (...) {
              const std::lock_guard<std::mutex> lock(mutex);
              if (s < failed_source) {  // report the first bad source, whatever the timing
                failed_source = s;
                failure = std::current_exception();
              }
              continue;
            }
            const std::lock_guard<std::mutex> lock(mutex);
            finished[s] = 1;
            ++done;
            if (o.progress) o.progress("views", done, sources.size());
            // Append the sources finished in order, so that only those done out of order wait.
            for (; appended < sources.size() && finished[appended]; ++appended)
              for (std::size_t v = first_view[appended]; v < first_view[appended + 1]; ++v) {
                db.orb_keypoints_.insert(db.orb_keypoints_.end(), orb_keypoints[v].begin(),
                                         orb_keypoints[v].end());
                db.orb_descriptors_.insert(db.orb_descriptors_.end(), orb_descriptors[v].data,
                                           orb_descriptors[v].data + orb_descriptors[v].total());
                db.orb_begin_.push_back(static_cast<std::int64_t>(db.orb_keypoints_.size()));
                std::vector<StoredKeypoint>().swap(orb_keypoints[v]);
                orb_descriptors[v].release();
              }
          }
        }
      },
      workers);
  if (failure) std::rethrow_exception(failure);
  GEODRIFT_ASSERT(appended == sources.size() && !scale.empty());
  // Queries are extracted at the finest scale a view was.
  db.retrieval_scale_ = *std::max_element(scale.begin(), scale.end());
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
  cv::Mat g = read_source_gray(sources_.at(s));
  cache_.push_front({s, g});
  if (cache_.size() > kCacheSize) cache_.pop_back();
  return g;
}

struct Database::Mapping {
  void* address = nullptr;
  std::size_t length = 0;
  const StoredKeypoint* keypoints = nullptr;
  const unsigned char* descriptors = nullptr;
  Mapping() = default;
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;
  ~Mapping() {
    if (address) ::munmap(address, length);
  }
};

std::vector<cv::KeyPoint> OrbFeatures::cv_keypoints() const {
  std::vector<cv::KeyPoint> out(static_cast<std::size_t>(size));
  for (int i = 0; i < size; ++i) {
    const StoredKeypoint& k = keypoints[i];
    out[i] = cv::KeyPoint(k.x, k.y, k.size, k.angle, k.response, k.octave);
  }
  return out;
}

OrbFeatures Database::orb(int view) const {
  if (view < 0 || view + 1 >= static_cast<int>(orb_begin_.size()))
    throw std::out_of_range("geotag database: no view " + std::to_string(view));
  const std::int64_t b = orb_begin_[view];
  const StoredKeypoint* kp = mapping_ ? mapping_->keypoints : orb_keypoints_.data();
  const unsigned char* d = mapping_ ? mapping_->descriptors : orb_descriptors_.data();
  OrbFeatures f;
  f.size = static_cast<int>(orb_begin_[view + 1] - b);
  f.keypoints = kp + b;
  // Read-only bytes (PROT_READ when mapped): the Mat header must not be written through.
  f.descriptors =
      f.size > 0 ? cv::Mat(f.size, kOrbBytes, CV_8U, const_cast<unsigned char*>(d + b * kOrbBytes))
                 : cv::Mat(0, kOrbBytes, CV_8U);
  return f;
}

cv::Mat Database::cut_view(const cv::Mat& source_gray, const GeoView& v) const {
  return cut_source_view(source_gray, v, &cutter_);
}

cv::Mat Database::view_image(int view) const {
  const GeoView& v = views_.at(view);
  return cut_view(source_gray(v.source), v);
}

std::vector<Retrieved> Database::query(const cv::Mat& gray, const QueryOptions& o) const {
  GEODRIFT_CHECK(!gray.empty(), "geotag query: the image is empty");
  return query_descriptors(detect_root_sift(retrieval_image(gray, retrieval_scale_),
                                            sift_features_ > 0 ? sift_features_ : 1000)
                               .descriptors,
                           o);
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
    io::write_pod<double>(os, retrieval_scale_);
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
    // ORB of all views: the per-view start table, then the keypoint and descriptor blocks at
    // 64-byte-aligned offsets (load() maps them).
    for (const std::int64_t b : orb_begin_) io::write_pod<std::int64_t>(os, b);
    const std::int64_t total = orb_begin_.back();
    const StoredKeypoint* kp = mapping_ ? mapping_->keypoints : orb_keypoints_.data();
    const unsigned char* desc = mapping_ ? mapping_->descriptors : orb_descriptors_.data();
    pad_to(os, align_up(static_cast<std::int64_t>(os.tellp())));
    os.write(reinterpret_cast<const char*>(kp),
             static_cast<std::streamsize>(total * sizeof(StoredKeypoint)));
    pad_to(os, align_up(static_cast<std::int64_t>(os.tellp())));
    os.write(reinterpret_cast<const char*>(desc), static_cast<std::streamsize>(total * kOrbBytes));
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
                  std::to_string(kFormatVersion) +
                  (version < kFormatVersion ? "; rebuild it with `geodrift geotags build`" : ""));
    if (io::read_pod<std::uint32_t>(is, "byte order") != kByteOrderMark)
      throw Error("written on a machine of the other byte order");
    Database db;
    db.sift_features_ = io::read_pod<std::int32_t>(is, "settings");
    db.orb_features_ = io::read_pod<std::int32_t>(is, "settings");
    db.retrieval_scale_ = io::read_pod<double>(is, "settings");
    if (!(db.retrieval_scale_ > 0 && db.retrieval_scale_ <= 1))
      throw Error("corrupt retrieval scale");
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
    db.orb_begin_.resize(static_cast<std::size_t>(nv) + 1);
    for (std::int64_t& b : db.orb_begin_) b = io::read_pod<std::int64_t>(is, "ORB view table");
    if (db.orb_begin_[0] != 0) throw Error("corrupt ORB view table");
    for (int v = 0; v < nv; ++v)
      if (db.orb_begin_[v + 1] < db.orb_begin_[v] ||
          db.orb_begin_[v + 1] - db.orb_begin_[v] > (1 << 20))
        throw Error("corrupt ORB view table");
    const std::int64_t total = db.orb_begin_.back();
    const std::int64_t kp_at = align_up(static_cast<std::int64_t>(is.tellg()));
    const std::int64_t desc_at =
        align_up(kp_at + total * static_cast<std::int64_t>(sizeof(StoredKeypoint)));
    const std::int64_t trailer_at = desc_at + total * kOrbBytes;
    is.seekg(0, std::ios::end);
    const std::int64_t file_size = static_cast<std::int64_t>(is.tellg());
    if (file_size != trailer_at + static_cast<std::int64_t>(sizeof kMagic))
      throw Error("file is " + std::to_string(file_size) + " bytes, its tables say " +
                  std::to_string(trailer_at + static_cast<std::int64_t>(sizeof kMagic)) +
                  " (truncated or trailing garbage)");
    is.seekg(trailer_at);
    is.read(magic, sizeof magic);
    if (is.gcount() != sizeof magic || std::memcmp(magic, kMagic, sizeof magic) != 0)
      throw Error("the trailer is missing (file truncated or overwritten)");
    // Map the file read-only: the keypoint and descriptor blocks (nearly all of it) are then
    // pages of the page cache that every process loading this file shares. Where mapping is
    // not possible, read the blocks instead.
    auto m = std::make_shared<Mapping>();
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd >= 0) {
      void* a = ::mmap(nullptr, static_cast<std::size_t>(file_size), PROT_READ, MAP_SHARED, fd, 0);
      ::close(fd);
      if (a != MAP_FAILED) {
        m->address = a;
        m->length = static_cast<std::size_t>(file_size);
        m->keypoints = reinterpret_cast<const StoredKeypoint*>(static_cast<char*>(a) + kp_at);
        m->descriptors = reinterpret_cast<const unsigned char*>(static_cast<char*>(a) + desc_at);
        db.mapping_ = std::move(m);
        return db;
      }
    }
    db.orb_keypoints_.resize(static_cast<std::size_t>(total));
    db.orb_descriptors_.resize(static_cast<std::size_t>(total) * kOrbBytes);
    is.clear();
    is.seekg(kp_at);
    is.read(reinterpret_cast<char*>(db.orb_keypoints_.data()),
            static_cast<std::streamsize>(total * sizeof(StoredKeypoint)));
    is.seekg(desc_at);
    is.read(reinterpret_cast<char*>(db.orb_descriptors_.data()),
            static_cast<std::streamsize>(total * kOrbBytes));
    if (!is) throw Error("cannot read the ORB blocks");
    return db;
  } catch (const Error& e) {  // InvalidArgument included
    throw Error("geotag database '" + path + "': " + e.what());
  }
}

}  // namespace geodrift::geotag
