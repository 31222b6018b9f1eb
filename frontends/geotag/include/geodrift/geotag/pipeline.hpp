#pragma once

/// @file
/// The per-keyframe geo-tag pipeline (the paper's Sec. 3.3, all four steps after collection):
///
///   keyframe image --RootSIFT BoW--> top-k views (optionally distance-gated)
///   for each view: ORB(keyframe) x ORB(view) putative matches (ratio 0.8 + mutual check,
///     capped at 1,000 best) --K-VLD--> kept matches
///     kept matches whose keyframe keypoint observes a map point = 2D-3D pairs (C_map-geo)
///     --PnP RANSAC + LM (localize_view)--> view pose in M --> map::Correspondence.
///
/// A view that localized once is not tried again (option), so one geo view gives one
/// correspondence. A view whose putative matches hold fewer keyframe keypoints with a map point
/// than acceptance needs (max(min_correspondences, min_inliers)) skips K-VLD and PnP: K-VLD only
/// removes matches, so the attempt could not succeed. Every attempt is reported (ViewAttempt).

#include <Eigen/Core>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "geodrift/geo/local_frame.hpp"
#include "geodrift/geotag/database.hpp"
#include "geodrift/geotag/localize.hpp"
#include "geodrift/map/correspondence.hpp"
#include "geodrift/map/keyframe.hpp"

namespace geodrift::geotag {

/// What the pipeline needs of one keyframe: its pose in M, its grayscale image (undistorted,
/// the video camera), its ORB keypoints + descriptors and, per keypoint, the id of the map
/// point it observes (-1 for none).
struct KeyframeFeatures {
  map::Keyframe keyframe;
  cv::Mat gray;
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;         ///< ORB, CV_8U x 32, one row per keypoint
  std::vector<int> point_ids;  ///< same size as keypoints
  /// The keyframe's optical axis in W (unit), when known (after INIT): enables the view
  /// direction gate (PipelineOptions::gate_view_direction).
  std::optional<Eigen::Vector3d> optical_axis_w;
};

struct PipelineOptions {
  int top_k = 5;  ///< views retrieved per keyframe (the paper's top-k)
  /// Distance gate of the retrieval: when on, and a position estimate is passed to process(),
  /// only views within gate_radius_m (horizontal, W) of it are candidates.
  bool gate = false;
  double gate_radius_m = 50.0;
  double ratio = 0.8;       ///< Lowe ratio of the putative ORB matches
  int max_putative = 1000;  ///< cap on putative matches (kVLD is O(N^2) in them)
  bool use_kvld = true;     ///< K-VLD filter (when geodrift::kvld is built)
  LocalizeOptions localize;
  double sigma_m = 2.0;  ///< Correspondence::sigma_m (geo-tag accuracy, metres)
  bool localize_each_view_once = true;
  double min_retrieval_score = 0.0;  ///< views scoring below this are skipped
  /// Panorama views are level; a keyframe of a road vehicle is level up to the road's grade.
  /// A localized panorama view whose image y axis (down) is tilted from the keyframe's by more
  /// than this is rejected as a wrong localization (10 deg: an 18 % grade plus margin). Not
  /// applied to photos (their pitch and roll are unknown); <= 0 disables it.
  double max_view_tilt_deg = 10.0;
  /// Cost controls (the per-keyframe work is RootSIFT + retrieval, then per view ORB matching,
  /// K-VLD and PnP). Adjacent keyframes of a car are ~1 m apart while panoramas are 5 m
  /// apart, so consecutive keyframes retrieve and try the same views:
  /// - keyframe_stride: run the pipeline on every n-th keyframe only (1 = every keyframe);
  /// - top_k_gated: views tried per keyframe when a gate position is given (after INIT the
  ///   gate already removes far views; 0 = top_k);
  /// - max_localized_per_keyframe: stop trying views of a keyframe once this many localized
  ///   (0 = try all top-k).
  int keyframe_stride = 1;
  /// Skip a retrieved view (no matching) whose horizontal viewing direction differs from the
  /// keyframe's (KeyframeFeatures::optical_axis_w) by more than half the sum of the two
  /// horizontal fields of view: their frusta are then disjoint at infinity and share at most
  /// nearby objects at the edges. On the rendered 1,050 m stretch of 02, none of 244 such
  /// attempts localized (all 110 localized views were within 67.5 deg; KITTI's field is 81 deg).
  bool gate_view_direction = true;
  int top_k_gated = 0;
  int max_localized_per_keyframe = 0;
};

/// Accumulated cost of the pipeline, in thread CPU seconds (robust on a loaded machine) and
/// wall seconds.
struct PipelineStats {
  int keyframes_seen = 0;     ///< process() calls
  int keyframes_queried = 0;  ///< of those, not skipped by keyframe_stride
  int views_tried = 0;
  int views_skipped_direction = 0;  ///< retrieved but skipped by gate_view_direction
  double retrieval_cpu_s = 0;       ///< RootSIFT on the keyframe + vocabulary + tf-idf scoring
  double orb_match_cpu_s = 0;       ///< ratio + mutual ORB matching
  double kvld_cpu_s = 0;            ///< K-VLD incl. scale spaces of keyframe and view images
  double pnp_cpu_s = 0;             ///< PnP RANSAC + LM (+ tilt check)
  double total_cpu_s = 0;
  double total_wall_s = 0;
};

/// The outcome of one keyframe x view attempt.
struct ViewAttempt {
  int keyframe = -1;
  int view = -1;
  float score = 0;
  int putative = 0;  ///< ratio + mutual ORB matches
  int kept = 0;      ///< after K-VLD (= putative when K-VLD is off; 0 when it was skipped)
  int pairs_3d = 0;  ///< kept matches with a map point
  LocalizeResult result;
  /// Angle (deg) between the view's and the keyframe's down axes for the PnP estimate (NaN
  /// when PnP gave no estimate; only computed for panorama views).
  double tilt_deg = std::numeric_limits<double>::quiet_NaN();
  int correspondence = -1;  ///< Correspondence::id when the view localized, else -1
};

class GeoLocalizer {
 public:
  /// @throws InvalidArgument if the database is empty.
  GeoLocalizer(const Database& db, const geo::LocalFrame& frame, const PipelineOptions& options);
  ~GeoLocalizer();
  GeoLocalizer(const GeoLocalizer&) = delete;
  GeoLocalizer& operator=(const GeoLocalizer&) = delete;

  /// Runs the pipeline for one keyframe; returns the correspondences it produced (ids
  /// numbered from 0 over the localizer's life).
  /// @param point_position  M position of a map point id, or nullptr when unknown.
  /// @param position_w      current position estimate in W (used only when the retrieval gate is
  ///                        on; nullptr = no gate for this keyframe).
  /// @param attempts        if non-null, receives one entry per view tried.
  /// @throws InvalidArgument for inconsistent keyframe features (sizes, empty image).
  std::vector<map::Correspondence> process(
      const KeyframeFeatures& kf,
      const std::function<const Eigen::Vector3d*(int point_id)>& point_position,
      const Eigen::Vector3d* position_w = nullptr, std::vector<ViewAttempt>* attempts = nullptr);

  /// Matches one keyframe to one view (ratio + mutual, then K-VLD when enabled), as
  /// (keyframe keypoint index, view keypoint index) pairs; counts in *attempt.
  std::vector<std::pair<int, int>> match(const KeyframeFeatures& kf, int view,
                                         ViewAttempt* attempt);

  bool have_kvld() const;
  const std::set<int>& localized_views() const { return localized_; }
  const PipelineStats& stats() const { return stats_; }

 private:
  /// Ratio + mutual ORB matches, capped at max_putative (best first).
  std::vector<cv::DMatch> putative(const KeyframeFeatures& kf, int view, ViewAttempt* attempt);
  /// K-VLD (when enabled) over putative matches, as (keyframe, view) keypoint index pairs.
  std::vector<std::pair<int, int>> filter(const KeyframeFeatures& kf, int view,
                                          const std::vector<cv::DMatch>& putative,
                                          ViewAttempt* attempt);

  struct Cache;
  const Database& db_;
  geo::LocalFrame frame_;
  PipelineOptions options_;
  int next_id_ = 0;
  std::set<int> localized_;
  PipelineStats stats_;
  std::unique_ptr<Cache> cache_;
};

}  // namespace geodrift::geotag
