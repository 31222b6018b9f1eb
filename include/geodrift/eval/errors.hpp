#pragma once

/// @file
/// The paper's evaluation metrics (DESIGN.md "Evaluation"): the 2D error (horizontal distance
/// in W, metres) of corrected keyframe centres against ground truth, with mean / SD / max, also
/// after the last anchor alone; the global Sim(3) error (Umeyama alignment of the uncorrected
/// path, in M, to ground truth in W); ATE and RPE. Missing ground truth is marked by NaN
/// entries, which are skipped.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/eval/umeyama.hpp"

namespace geodrift::eval {

/// Summary of a set of non-negative errors: mean ("Ave" in the paper's tables), population
/// standard deviation (divides by n), maximum, RMS and count. All zero when count == 0.
struct ErrorStats {
  double mean = 0.0;
  double sd = 0.0;
  double max = 0.0;
  double rmse = 0.0;
  int count = 0;
};

/// Mean, population SD, max and RMS of `e`.
inline ErrorStats error_stats(const std::vector<double>& e) {
  ErrorStats s;
  s.count = static_cast<int>(e.size());
  if (e.empty()) return s;
  double sum = 0.0, sq = 0.0;
  for (double v : e) {
    sum += v;
    sq += v * v;
    s.max = std::max(s.max, v);
  }
  const double n = static_cast<double>(e.size());
  s.mean = sum / n;
  s.rmse = std::sqrt(sq / n);
  double var = 0.0;
  for (double v : e) var += (v - s.mean) * (v - s.mean);
  s.sd = std::sqrt(var / n);
  return s;
}

/// DESIGN.md "Evaluation": the 2D error over ALL keyframes with ground truth, and separately
/// over the keyframes after the last anchor (frame_index > last_anchor_frame).
struct HorizontalErrorReport {
  ErrorStats all;
  ErrorStats after_last_anchor;
  std::vector<double> per_keyframe;  ///< same order as the input; NaN where no ground truth
};

/// True when a ground-truth entry is present (the convention here: missing = any NaN).
inline bool has_ground_truth(const Eigen::Vector3d& gt) { return gt.allFinite(); }

/// 2D error = horizontal distance in W, sqrt(dx² + dy²) (W is x east, y north, z up;
/// DESIGN.md), between estimated and ground-truth keyframe centres.
/// @param est_w  estimated keyframe centres in W, metres (must be finite).
/// @param gt_w   ground-truth centres in W; an entry with a NaN means "no ground truth" and is
///               skipped.
/// @param frame_index  video frame of each keyframe (to split off the part after the last
///               anchor); may be empty when last_anchor_frame is not used.
/// @param last_anchor_frame  keyframes with frame_index > this are also reported alone; pass
///               std::numeric_limits<int>::max() for "no split".
/// @throws InvalidArgument on size mismatch or a non-finite estimate.
inline HorizontalErrorReport horizontal_errors(
    const std::vector<Eigen::Vector3d>& est_w, const std::vector<Eigen::Vector3d>& gt_w,
    const std::vector<int>& frame_index = {},
    int last_anchor_frame = std::numeric_limits<int>::max()) {
  GEODRIFT_CHECK(est_w.size() == gt_w.size(),
                 "horizontal_errors: " << est_w.size() << " estimates but " << gt_w.size()
                                       << " ground-truth entries");
  GEODRIFT_CHECK(frame_index.empty() || frame_index.size() == est_w.size(),
                 "horizontal_errors: " << frame_index.size() << " frame indices for "
                                       << est_w.size() << " keyframes");
  HorizontalErrorReport r;
  r.per_keyframe.assign(est_w.size(), std::numeric_limits<double>::quiet_NaN());
  std::vector<double> all, after;
  for (std::size_t i = 0; i < est_w.size(); ++i) {
    GEODRIFT_CHECK(est_w[i].allFinite(), "horizontal_errors: estimate " << i << " not finite");
    if (!has_ground_truth(gt_w[i])) continue;
    const double e = (est_w[i] - gt_w[i]).head<2>().norm();
    r.per_keyframe[i] = e;
    all.push_back(e);
    if (!frame_index.empty() && frame_index[i] > last_anchor_frame) after.push_back(e);
  }
  r.all = error_stats(all);
  r.after_last_anchor = error_stats(after);
  return r;
}

/// Calibration of horizontal covariances: the fraction of keyframes (with ground truth) whose
/// true position lies inside the estimate's `probability` ellipse, i.e. whose error d (2D, in
/// W) has dᵀ·Σ⁻¹·d ≤ χ²₂(probability) = −2·ln(1 − probability). A calibrated Σ gives about
/// `probability`. Keyframes whose Σ is not positive definite count as outside.
/// @throws InvalidArgument on size mismatch or a probability outside (0, 1).
inline double ellipse_coverage(const std::vector<Eigen::Vector3d>& est_w,
                               const std::vector<Eigen::Vector3d>& gt_w,
                               const std::vector<Eigen::Matrix2d>& cov_en,
                               double probability = 0.95) {
  GEODRIFT_CHECK(est_w.size() == gt_w.size() && est_w.size() == cov_en.size(),
                 "ellipse_coverage: " << est_w.size() << " estimates, " << gt_w.size()
                                      << " ground-truth entries, " << cov_en.size()
                                      << " covariances");
  GEODRIFT_CHECK(probability > 0 && probability < 1,
                 "ellipse_coverage: probability " << probability << " is not in (0, 1)");
  const double gate = -2.0 * std::log(1.0 - probability);
  int in = 0, n = 0;
  for (std::size_t i = 0; i < est_w.size(); ++i) {
    if (!has_ground_truth(gt_w[i])) continue;
    ++n;
    const Eigen::Matrix2d& S = cov_en[i];
    const double det = S(0, 0) * S(1, 1) - S(0, 1) * S(1, 0);
    if (!(S(0, 0) > 0 && det > 0) || !S.allFinite()) continue;
    const Eigen::Vector2d d = (est_w[i] - gt_w[i]).head<2>();
    const double m2 =
        (S(1, 1) * d.x() * d.x() - 2 * S(0, 1) * d.x() * d.y() + S(0, 0) * d.y() * d.y()) / det;
    in += m2 <= gate;
  }
  return n ? static_cast<double>(in) / n : std::numeric_limits<double>::quiet_NaN();
}

/// DESIGN.md "Global Sim3 error": Umeyama Sim(3) alignment (3D) of all uncorrected keyframe
/// centres to ground truth, then the 2D error of the aligned centres.
struct GlobalSim3Error {
  Alignment alignment;  ///< M -> W; check alignment.ok()
  HorizontalErrorReport errors;
};

/// @param est_m uncorrected keyframe centres in the map frame M (any scale).
/// @param gt_w ground truth in W (NaN entries = no ground truth; skipped in the alignment).
/// On degenerate input the alignment status says why and `errors` is empty.
inline GlobalSim3Error global_sim3_error(const std::vector<Eigen::Vector3d>& est_m,
                                         const std::vector<Eigen::Vector3d>& gt_w,
                                         const std::vector<int>& frame_index = {},
                                         int last_anchor_frame = std::numeric_limits<int>::max()) {
  GEODRIFT_CHECK(est_m.size() == gt_w.size(),
                 "global_sim3_error: " << est_m.size() << " estimates but " << gt_w.size()
                                       << " ground-truth entries");
  std::vector<Eigen::Vector3d> src, dst;
  for (std::size_t i = 0; i < est_m.size(); ++i)
    if (has_ground_truth(gt_w[i])) {
      src.push_back(est_m[i]);
      dst.push_back(gt_w[i]);
    }
  GlobalSim3Error out;
  out.alignment = umeyama(src, dst, true);
  if (!out.alignment.ok()) return out;
  std::vector<Eigen::Vector3d> aligned(est_m.size());
  for (std::size_t i = 0; i < est_m.size(); ++i) aligned[i] = out.alignment.apply(est_m[i]);
  out.errors = horizontal_errors(aligned, gt_w, frame_index, last_anchor_frame);
  return out;
}

/// How estimated positions are aligned to ground truth before an ATE.
enum class AteAlignment { kNone, kSE3, kSim3 };

/// Absolute trajectory error: RMS of the 3D distance between (optionally aligned) estimated and
/// ground-truth positions, metres. Entries without ground truth (NaN) are skipped.
/// @throws InvalidArgument on size mismatch, or if the requested alignment is degenerate.
inline double ate_rmse(const std::vector<Eigen::Vector3d>& est,
                       const std::vector<Eigen::Vector3d>& gt,
                       AteAlignment align = AteAlignment::kNone) {
  GEODRIFT_CHECK(est.size() == gt.size(),
                 "ate_rmse: " << est.size() << " estimates but " << gt.size() << " ground truths");
  std::vector<Eigen::Vector3d> src, dst;
  for (std::size_t i = 0; i < est.size(); ++i)
    if (has_ground_truth(gt[i])) {
      GEODRIFT_CHECK(est[i].allFinite(), "ate_rmse: estimate " << i << " not finite");
      src.push_back(est[i]);
      dst.push_back(gt[i]);
    }
  if (src.empty()) return 0.0;
  if (align == AteAlignment::kNone) {
    double sq = 0.0;
    for (std::size_t i = 0; i < src.size(); ++i) sq += (src[i] - dst[i]).squaredNorm();
    return std::sqrt(sq / static_cast<double>(src.size()));
  }
  const Alignment a = umeyama(src, dst, align == AteAlignment::kSim3);
  GEODRIFT_CHECK(a.ok(), "ate_rmse: " << a.message);
  return a.rmse;
}

/// Relative pose error statistics (Sturm et al. 2012, TUM RGB-D benchmark): for pose pairs
/// (i, j), E = (G_i⁻¹·G_j)⁻¹·(P_i⁻¹·P_j); translational error |trans(E)| in metres, rotational
/// error angle(rot(E)) in radians.
struct RpeResult {
  ErrorStats translation;  ///< metres
  ErrorStats rotation;     ///< radians
};

/// How the second pose of each RPE pair is chosen.
enum class RpeDelta {
  kFrames,  ///< j = i + delta (indices into the pose vectors)
  kMetres,  ///< j = first index whose ground-truth path length from i is >= delta metres
};

/// RPE over all pairs (i, j(i)). Poses are camera-to-world T_wc in metres (the estimate must be
/// metric, i.e. corrected, for the translational part to mean anything).
/// @throws InvalidArgument on size mismatch or delta <= 0.
inline RpeResult relative_pose_error(const std::vector<Eigen::Isometry3d>& est_T_wc,
                                     const std::vector<Eigen::Isometry3d>& gt_T_wc, double delta,
                                     RpeDelta unit = RpeDelta::kFrames) {
  GEODRIFT_CHECK(est_T_wc.size() == gt_T_wc.size(),
                 "relative_pose_error: " << est_T_wc.size() << " estimates but " << gt_T_wc.size()
                                         << " ground truths");
  GEODRIFT_CHECK(delta > 0, "relative_pose_error: delta " << delta << " must be > 0");
  const std::size_t n = est_T_wc.size();
  std::vector<double> dist(n, 0.0);
  for (std::size_t i = 1; i < n; ++i)
    dist[i] = dist[i - 1] + (gt_T_wc[i].translation() - gt_T_wc[i - 1].translation()).norm();
  std::vector<double> et, er;
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t j = n;
    if (unit == RpeDelta::kFrames) {
      j = i + static_cast<std::size_t>(std::llround(delta));
    } else {
      for (std::size_t k = i + 1; k < n; ++k)
        if (dist[k] - dist[i] >= delta) {
          j = k;
          break;
        }
    }
    if (j >= n) break;
    const Eigen::Isometry3d E =
        (gt_T_wc[i].inverse() * gt_T_wc[j]).inverse() * (est_T_wc[i].inverse() * est_T_wc[j]);
    et.push_back(E.translation().norm());
    er.push_back(Eigen::AngleAxisd(E.rotation()).angle());
  }
  return {error_stats(et), error_stats(er)};
}

/// KITTI odometry benchmark error (devkit evaluate_odometry.cpp, Geiger et al. 2012): for every
/// start frame in steps of `step_frames` and every segment length L, the end frame is the first
/// one whose ground-truth path length from the start exceeds L; the error pose
/// E = (P_i⁻¹·P_j)⁻¹·(G_i⁻¹·G_j) gives t_err = |trans(E)|/L and r_err = angle(E)/L.
struct KittiSegmentError {
  double translation_percent = 0.0;  ///< mean t_err × 100 (%)
  double rotation_deg_per_m = 0.0;   ///< mean r_err in degrees per metre
  int segments = 0;
};

/// @param lengths_m segment lengths; the brief's default is {100}; the devkit uses
///        {100, 200, ..., 800}.
/// @throws InvalidArgument on size mismatch, empty lengths, a length <= 0 or step_frames < 1.
inline KittiSegmentError kitti_segment_error(const std::vector<Eigen::Isometry3d>& est_T_wc,
                                             const std::vector<Eigen::Isometry3d>& gt_T_wc,
                                             const std::vector<double>& lengths_m = {100.0},
                                             int step_frames = 10) {
  GEODRIFT_CHECK(est_T_wc.size() == gt_T_wc.size(),
                 "kitti_segment_error: " << est_T_wc.size() << " estimates but " << gt_T_wc.size()
                                         << " ground truths");
  GEODRIFT_CHECK(!lengths_m.empty(), "kitti_segment_error: no segment lengths");
  GEODRIFT_CHECK(step_frames >= 1,
                 "kitti_segment_error: step_frames " << step_frames << " must be >= 1");
  for (double L : lengths_m)
    GEODRIFT_CHECK(L > 0, "kitti_segment_error: segment length " << L << " must be > 0");
  const std::size_t n = gt_T_wc.size();
  std::vector<double> dist(n, 0.0);
  for (std::size_t i = 1; i < n; ++i)
    dist[i] = dist[i - 1] + (gt_T_wc[i].translation() - gt_T_wc[i - 1].translation()).norm();
  KittiSegmentError out;
  double sum_t = 0.0, sum_r = 0.0;
  for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(step_frames)) {
    for (double L : lengths_m) {
      std::size_t j = n;
      for (std::size_t k = i; k < n; ++k)
        if (dist[k] > dist[i] + L) {
          j = k;
          break;
        }
      if (j >= n) continue;
      const Eigen::Isometry3d E =
          (est_T_wc[i].inverse() * est_T_wc[j]).inverse() * (gt_T_wc[i].inverse() * gt_T_wc[j]);
      sum_t += E.translation().norm() / L;
      sum_r += Eigen::AngleAxisd(E.rotation()).angle() / L;
      ++out.segments;
    }
  }
  if (out.segments > 0) {
    out.translation_percent = 100.0 * sum_t / out.segments;
    out.rotation_deg_per_m = sum_r / out.segments * (180.0 / 3.14159265358979323846);
  }
  return out;
}

}  // namespace geodrift::eval
