#pragma once
/// @file
/// geodrift::vo::Odometry — a minimal ORB monocular SfM in the manner of ORB-SLAM's tracking and
/// local mapping threads, in a fixed order (deterministic; see "Threads" below):
///
///   frame ─► ORB (grid) ─► [not initialised] two-view init against a reference frame, retried on
///                          later frames, reference renewed when it gets too old
///                       ─► [tracking] constant-velocity prediction ─► projection matching of the
///                          last frame's points ─► robust pose refinement (Gauss-Newton, Huber,
///                          outlier rounds) ─► local-map projection matching ─► refinement
///                          (fallback: descriptor matching to the reference keyframe + PnP RANSAC)
///                       ─► keyframe decision ─► [local mapping] new observations, culling of
///                          recent points, triangulation with covisible keyframes, local BA over
///                          the covisibility window through the core solver (Schur), culling of
///                          bad observations/points and redundant keyframes
///                       ─► [lost] relocalisation: descriptor matching to recent keyframes + PnP
///
/// Threads (OdometryOptions::pipeline_mapping, default on): the local mapping of a keyframe runs
/// during the next process() call on the caller's thread while that frame's ORB features are
/// extracted on a second thread; it always completes before the frame is tracked, so the
/// results do not depend on timing (identical to pipeline_mapping = false). The keyframe
/// callback is always called on the caller's thread, from process(), finish() or map().
///
/// Keyframes are handed out (callback `on_keyframe_final`) once they can no longer change: when
/// `finalize_lag` newer keyframes exist (so they have left the local BA window) or at finish().
/// The batch carries the raw keyframe (T_cw in M), the map points first seen final with it, its
/// observations, and the KeyframeView the geo-tag pipeline needs. The full current map is
/// available any time through map().
///
/// Conventions: the map frame M is the first keyframe's camera frame, its unit set by the
/// initial map's median depth = 1 (as ORB-SLAM); poses are T_cw (M -> camera, OpenCV camera
/// x right, y down, z forward); pixels are those of the undistorted frames; the core's LEFT
/// perturbation in every pose refinement and BA.

#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "geodrift/map/map.hpp"
#include "geodrift/vo/features.hpp"
#include "geodrift/vo/input.hpp"
#include "geodrift/vo/two_view.hpp"

namespace geodrift::vo {

/// What the geo-tag pipeline needs to localize a geo view against a keyframe (issue 6):
/// match the view's ORB features against `keypoints/descriptors`, then use `point_ids` to turn
/// keyframe keypoints into 2D-3D correspondences (map point positions: the batch's points, the
/// Corrector, or Odometry::map()).
struct KeyframeView {
  int keyframe_id = -1;
  int frame_index = -1;
  lie::SE3d T_cw;                       ///< raw pose in M when it was handed out
  map::Camera camera;                   ///< undistorted pinhole camera of `image`
  cv::Mat image;                        ///< CV_8UC1, undistorted (the image the VO worked on)
  std::vector<cv::KeyPoint> keypoints;  ///< pixel (undistorted), size, angle, octave
  cv::Mat descriptors;                  ///< CV_8UC1, keypoints.size() x 32 (ORB)
  std::vector<int> point_ids;           ///< per keypoint: map::MapPoint::id or -1
};

/// A keyframe that became final, ready for the Corrector: add `keyframe`, then `new_points`
/// (their reference keyframe is this or an earlier final keyframe), then `observations` (this
/// keyframe's observations of points already handed out, in this or an earlier batch).
struct KeyframeBatch {
  map::Keyframe keyframe;
  std::vector<map::MapPoint> new_points;
  std::vector<map::Observation> observations;
  KeyframeView view;
};

struct OdometryOptions {
  OrbOptions orb;
  TwoViewOptions init;
  int init_max_reference_age = 30;    ///< frames before the init reference frame is renewed
  int min_tracked_inliers = 30;       ///< fewer after refinement: tracking lost for this frame
  int reloc_min_inliers = 40;         ///< relocalisation acceptance
  int reloc_keyframes = 5;            ///< most recent keyframes tried when relocalising
  double search_radius_px = 12.0;     ///< projection search radius at level 0 (x level scale)
  int keyframe_max_frames = 10;       ///< a keyframe at least this often (frames)
  int keyframe_min_frames = 1;        ///< and not more often than this
  double keyframe_track_ratio = 0.6;  ///< keyframe when inliers < ratio x reference KF points
  int local_window = 8;               ///< keyframes optimised by local BA (newest + covisible)
  int triangulation_neighbors = 6;    ///< covisible keyframes used to triangulate new points
  int ba_iterations = 8;              ///< LM iterations per local BA (two rounds of half)
  int num_threads = 1;                ///< core solver threads (1 or 2)
  int finalize_lag = 12;              ///< keyframes newer than a keyframe before it is final
  bool keep_final_images = false;     ///< keep KeyframeView images after handing them out
  /// Run a keyframe's local mapping (triangulation, local BA, culling, handing out final
  /// keyframes) at the start of the next process() call, overlapped with that frame's ORB
  /// extraction on a second thread. Mapping still completes before the frame is tracked, so the
  /// results are bit-identical to the synchronous order (false: mapping inside the process() call
  /// that made the keyframe, one thread).
  bool pipeline_mapping = true;
};

/// Per-frame outcome.
struct FrameResult {
  enum class State {
    kNotInitialized,
    kInitialized,
    kTracked,
    kLost,
    kRelocalized
  } state = State::kNotInitialized;
  bool keyframe = false;  ///< a keyframe was made from this frame
  int features = 0;
  int matches = 0;      ///< 2D-3D correspondences after refinement (inliers)
  lie::SE3d T_cw;       ///< valid for kInitialized/kTracked/kRelocalized
  std::string message;  ///< init failure reason, loss reason, ...
  bool has_pose() const {
    return state == State::kInitialized || state == State::kTracked || state == State::kRelocalized;
  }
};

/// Time spent per stage, seconds (summed over all frames).
struct OdometryTimings {
  double features = 0, init = 0, tracking = 0, keyframe = 0, triangulation = 0, local_ba = 0,
         culling = 0;
  /// Handing final keyframes out, including the time spent in the keyframe callback (for
  /// `geodrift run --geotags`: the geo-tag localization and the Corrector).
  double handover = 0;
  int local_ba_runs = 0;
};

class Odometry {
 public:
  /// @throws InvalidArgument for an invalid camera (width/height must be known) or options.
  Odometry(const map::Camera& camera, const OdometryOptions& options = {});
  ~Odometry();
  Odometry(const Odometry&) = delete;
  Odometry& operator=(const Odometry&) = delete;

  /// Called for every keyframe that became final, in keyframe-id order.
  void set_keyframe_callback(std::function<void(const KeyframeBatch&)> cb);

  /// Processes one undistorted 8-bit grayscale frame of camera().
  /// @throws InvalidArgument when the image size or type does not match the camera.
  FrameResult process(const Frame& frame);

  /// Hands out every remaining keyframe (end of the sequence).
  void finish();

  bool initialized() const;
  /// The current map: live keyframes, points with >= 2 observations, their observations.
  /// Completes a pending local mapping first (may call the keyframe callback).
  map::Map map() const;
  /// The view of a live keyframe (image only while it is not final, or keep_final_images).
  /// @throws InvalidArgument for an unknown or culled keyframe id.
  KeyframeView keyframe_view(int keyframe_id) const;
  /// Frames whose pose was estimated, by frame index, with their T_cw (map frame M).
  const std::vector<std::pair<int, lie::SE3d>>& frame_poses() const;
  /// Live keyframes / map points, as of the last completed local mapping (a pending one, see
  /// pipeline_mapping, is not forced: cheap enough for a progress line).
  int num_keyframes() const;
  int num_points() const;
  const OdometryTimings& timings() const;
  const map::Camera& camera() const;
  /// Initialisation attempts and the reason of the last failure (for reports).
  int init_attempts() const;
  const std::string& last_init_failure() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace geodrift::vo
