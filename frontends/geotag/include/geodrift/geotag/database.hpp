#pragma once

/// @file
/// The geo-tagged image database: views (panorama cuts and photos) with their geo-tags, a SIFT
/// bag-of-words vocabulary and tf-idf inverted file for retrieval, and every view's ORB
/// features for matching. Built once (Database::build, minutes for thousands of views),
/// saved to one binary file, loaded in well under a second per thousand views.
///
/// File format (Database::save): "GDGEOTAGDB" magic, format version, byte-order mark, the build
/// settings (version 2 adds the retrieval scale; version 1 files are refused: rebuild them), the
/// video camera, sources (paths, geo-tags, kinds, photo intrinsics), views, the vocabulary tree,
/// the inverted file and the ORB keypoints + descriptors of every view (version 2: one
/// 64-byte-aligned block of 24-byte keypoint records and one of 32-byte descriptors for all views,
/// which load() maps read-only instead of reading, so several processes using one database share
/// those pages: nearly all of its size). Images are NOT copied: views are re-cut from their source
/// files on demand (view_image()), so the sources must stay where they were at build time (their
/// absolute paths are stored).

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/geotag/features.hpp"
#include "geodrift/geotag/panorama.hpp"
#include "geodrift/geotag/views.hpp"
#include "geodrift/geotag/vocabulary.hpp"
#include "geodrift/map/camera.hpp"

namespace geodrift::geotag {

/// Progress report: stage name, items done, items in this stage.
using ProgressFn = std::function<void(const char* stage, std::size_t done, std::size_t total)>;

/// A keypoint as the database stores it (24 bytes, the file's record): pixels of the view,
/// OpenCV's conventions (x right, y down, angle in degrees, octave = pyramid level).
struct StoredKeypoint {
  float x, y, size, angle, response;
  std::int32_t octave;
};
static_assert(sizeof(StoredKeypoint) == 24, "StoredKeypoint is the file's 24-byte record");

/// One view's ORB features without a copy: pointers into the database's memory (the
/// read-only memory-mapped file of a loaded database), valid while the Database lives.
struct OrbFeatures {
  const StoredKeypoint* keypoints = nullptr;
  int size = 0;
  cv::Mat descriptors;  ///< CV_8U x 32, size rows; a header over the database's bytes
  /// The keypoints as cv::KeyPoint (a copy).
  std::vector<cv::KeyPoint> cv_keypoints() const;
};

/// One retrieval result.
struct Retrieved {
  int view = -1;    ///< GeoView::id
  float score = 0;  ///< cosine similarity of tf-idf vectors, in [0, 1]
};

/// Retrieval settings.
struct QueryOptions {
  int top_k = 5;  ///< views returned per query (the paper's top-k)
  /// Optional distance gate: only views whose geo-tag lies within `gate_radius_m` (horizontal,
  /// in W) of `gate_position_w` are candidates. Needs `frame`.
  std::optional<Eigen::Vector3d> gate_position_w;
  double gate_radius_m = 50.0;
  const geo::LocalFrame* frame = nullptr;
};

class Database {
 public:
  struct BuildOptions {
    /// Intrinsics and size of the video; panorama views are cut with them ("the same field of
    /// view as the input video").
    map::Camera video_camera;
    int sift_features = 1000;  ///< RootSIFT features per view (retrieval)
    /// Retrieval runs RootSIFT on images resized by at most this factor. SIFT doubles its
    /// input for its first octave, so 0.5 puts that octave at the image's own resolution
    /// instead of at twice it. A panorama view is resized further, by half its panorama's own
    /// resolution at the view's centre, W / (4 pi fx): a 2048-px panorama holds 5.7 px/deg, a
    /// KITTI view (fx 718) 12.5 px/deg, so that view is the panorama upsampled 2.2x and is
    /// resized by 0.23, which puts SIFT's first octave at the panorama's pixels; more pixels
    /// would add SIFT's cost but no detail (measured: BENCHMARKS.md, "Geo-tag database").
    /// Queries are resized by the largest factor any view was (Database::retrieval_scale(),
    /// stored), so that query and views see the scene at the same scale. In (0, 1]; 1 = full
    /// resolution (format 1 databases).
    double retrieval_scale = 0.5;
    int orb_features = 2000;  ///< ORB features per view (matching)
    Vocabulary::Options vocabulary;
    ProgressFn progress;  ///< may be empty
  };

  Database() = default;

  /// Builds from geo-tagged sources (read_geotag_csv()). Stages reported: "views" (per source:
  /// load, cut, SIFT + ORB), "vocabulary" (descriptors assigned to leaves), "index".
  /// @throws InvalidArgument if there are no sources, a source cannot be read, or options are
  ///         invalid; Error if the views have too few SIFT features to train a vocabulary.
  static Database build(const std::vector<GeoSource>& sources, const BuildOptions& options);

  /// Writes the database atomically (temporary file + rename). @throws Error naming the path.
  void save(const std::string& path) const;
  /// @throws Error naming the path for a missing, truncated or foreign file.
  static Database load(const std::string& path);

  const std::vector<GeoSource>& sources() const { return sources_; }
  const std::vector<GeoView>& views() const { return views_; }
  const map::Camera& video_camera() const { return video_camera_; }
  const Vocabulary& vocabulary() const { return vocabulary_; }
  const InvertedIndex& index() const { return index_; }
  /// The factor queries are resized by for retrieval: the largest any view was resized by
  /// (BuildOptions::retrieval_scale, or less when every view is cut from a coarser panorama).
  double retrieval_scale() const { return retrieval_scale_; }
  /// The view's precomputed ORB features (keypoints in view pixels), without a copy.
  /// @throws std::out_of_range for a view that does not exist.
  OrbFeatures orb(int view) const;
  /// True when the ORB features are read from the file through a read-only memory map (a
  /// loaded database): processes that load the same file share those pages.
  bool memory_mapped() const { return static_cast<bool>(mapping_); }

  /// Top-k views for a grayscale query image (resized by retrieval_scale() -> RootSIFT ->
  /// words -> tf-idf -> cosine), best first, with the optional distance gate. Views scoring 0
  /// are never returned.
  /// @throws InvalidArgument for an empty image or a gate without a frame.
  std::vector<Retrieved> query(const cv::Mat& gray, const QueryOptions& options) const;
  /// The same from the query's RootSIFT descriptors (of the image at retrieval_scale()).
  std::vector<Retrieved> query_descriptors(const cv::Mat& root_sift,
                                           const QueryOptions& options) const;

  /// The grayscale view image (re-cut from its panorama, or the photo). Keeps the last few
  /// decoded sources in a small cache (not thread-safe).
  /// @throws Error if the source file can no longer be read.
  cv::Mat view_image(int view) const;

 private:
  cv::Mat source_gray(int source) const;
  /// View v of its source's grey image (the panorama cut, or the photo itself).
  cv::Mat cut_view(const cv::Mat& source_gray, const GeoView& v) const;

  map::Camera video_camera_;
  int sift_features_ = 0, orb_features_ = 0;
  double retrieval_scale_ = 1.0;
  std::vector<GeoSource> sources_;
  std::vector<GeoView> views_;
  Vocabulary vocabulary_;
  InvertedIndex index_;
  // ORB features of all views, back to back: view v owns keypoints / descriptor rows
  // [orb_begin_[v], orb_begin_[v + 1]). They live in orb_keypoints_ / orb_descriptors_ for a
  // built database and in the mapped file (mapping_, shared by copies) for a loaded one.
  std::vector<std::int64_t> orb_begin_;
  std::vector<StoredKeypoint> orb_keypoints_;
  std::vector<unsigned char> orb_descriptors_;
  struct Mapping;
  std::shared_ptr<const Mapping> mapping_;
  mutable std::list<std::pair<int, cv::Mat>> cache_;  ///< (source, gray image), most recent first
  mutable std::optional<PanoramaCutter> cutter_;      ///< remap tables of the last panorama size
};

}  // namespace geodrift::geotag
