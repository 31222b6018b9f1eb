#pragma once

/// @file
/// The geo-tagged image database: views (panorama cuts and photos) with their geo-tags, a SIFT
/// bag-of-words vocabulary and tf-idf inverted file for retrieval, and every view's ORB
/// features for matching. Built once (Database::build, minutes for thousands of views),
/// saved to one binary file, loaded in well under a second per thousand views.
///
/// File format (Database::save): "GDGEOTAGDB" magic, format version, byte-order mark, the build
/// settings, the video camera, sources (paths, geo-tags, kinds, photo intrinsics), views, the
/// vocabulary tree, the inverted file and the ORB keypoints + descriptors of every view. Images
/// are NOT copied: views are re-cut from their source files on demand (view_image()), so the
/// sources must stay where they were at build time (their absolute paths are stored).

#include <Eigen/Core>
#include <cstddef>
#include <functional>
#include <list>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/geotag/features.hpp"
#include "geodrift/geotag/views.hpp"
#include "geodrift/geotag/vocabulary.hpp"
#include "geodrift/map/camera.hpp"

namespace geodrift::geotag {

/// Progress report: stage name, items done, items in this stage.
using ProgressFn = std::function<void(const char* stage, std::size_t done, std::size_t total)>;

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
    int orb_features = 2000;   ///< ORB features per view (matching)
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
  /// The view's precomputed ORB features (keypoints in view pixels).
  const Features& orb(int view) const { return orb_.at(view); }

  /// Top-k views for a grayscale query image (RootSIFT -> words -> tf-idf -> cosine), best
  /// first, with the optional distance gate. Views scoring 0 are never returned.
  /// @throws InvalidArgument for an empty image or a gate without a frame.
  std::vector<Retrieved> query(const cv::Mat& gray, const QueryOptions& options) const;
  /// The same from the query's RootSIFT descriptors.
  std::vector<Retrieved> query_descriptors(const cv::Mat& root_sift,
                                           const QueryOptions& options) const;

  /// The grayscale view image (re-cut from its panorama, or the photo). Keeps the last few
  /// decoded sources in a small cache (not thread-safe).
  /// @throws Error if the source file can no longer be read.
  cv::Mat view_image(int view) const;

 private:
  cv::Mat source_gray(int source) const;

  map::Camera video_camera_;
  int sift_features_ = 0, orb_features_ = 0;
  std::vector<GeoSource> sources_;
  std::vector<GeoView> views_;
  Vocabulary vocabulary_;
  InvertedIndex index_;
  std::vector<Features> orb_;
  mutable std::list<std::pair<int, cv::Mat>> cache_;  ///< (source, gray image), most recent first
};

}  // namespace geodrift::geotag
