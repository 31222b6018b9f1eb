#pragma once

/// @file
/// Scale factor along the path (DESIGN.md "Evaluation", the paper's Fig. 7): estimated over
/// true chord distance across a sliding window of keyframes (1 = locally correct scale; the
/// estimate must be in metres, in W), and the windowed scale statistics used to calibrate the
/// drift simulator.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::eval {

/// Options of the scale factor along the path (DESIGN.md "Evaluation", the paper's Fig. 7).
struct ScaleFactorOptions {
  int window_keyframes = 10;         ///< keyframes i and i + window are compared
  double min_true_distance_m = 1.0;  ///< windows whose true distance is shorter are skipped
                                     ///< (a stopped vehicle: the ratio would be noise)
};

/// Scale factor of the window starting at keyframe `index`.
struct ScaleFactorSample {
  int index = 0;        ///< first keyframe of the window (index into the input vectors)
  double factor = 1.0;  ///< estimated / true distance
  double true_distance_m = 0.0;
};

/// Scale factor along the path: for every keyframe i with i + w in range, the estimated
/// distance |c_{i+w} − c_i| divided by the true distance |g_{i+w} − g_i| (w =
/// window_keyframes, chord distances in 3D, so per-keyframe noise does not inflate a path
/// length). 1 means locally correct scale. Estimated centres must be in metres (corrected) for
/// the factor to be the scale error; for an uncorrected map it is the map's scale per metre.
/// Windows with an entry without ground truth (NaN) or a true distance below
/// min_true_distance_m are skipped.
/// @throws InvalidArgument on size mismatch or window_keyframes < 1.
inline std::vector<ScaleFactorSample> scale_factor_along_path(
    const std::vector<Eigen::Vector3d>& est, const std::vector<Eigen::Vector3d>& gt,
    const ScaleFactorOptions& opt = {}) {
  GEODRIFT_CHECK(est.size() == gt.size(),
                 "scale_factor_along_path: " << est.size() << " estimates but " << gt.size()
                                             << " ground truths");
  GEODRIFT_CHECK(opt.window_keyframes >= 1, "scale_factor_along_path: window_keyframes "
                                                << opt.window_keyframes << " must be >= 1");
  std::vector<ScaleFactorSample> out;
  const std::size_t w = static_cast<std::size_t>(opt.window_keyframes);
  for (std::size_t i = 0; i + w < est.size(); ++i) {
    const std::size_t j = i + w;
    if (!gt[i].allFinite() || !gt[j].allFinite()) continue;
    const double d_true = (gt[j] - gt[i]).norm();
    if (d_true < opt.min_true_distance_m) continue;
    out.push_back({static_cast<int>(i), (est[j] - est[i]).norm() / d_true, d_true});
  }
  return out;
}

/// Roughness of a drifting path's scale (the calibration statistic for the simulator,
/// and what a real monocular VO on KITTI shows): the path is cut into consecutive windows of
/// `window_frames` video frames; each window's scale is (estimated path length)/(true path
/// length) over the keyframe steps (k, k+1) whose first keyframe lies in the window; the window
/// scales are normalised by their mean.
struct WindowScaleStats {
  std::vector<double> scales;   ///< normalised window scales, in path order (valid windows only)
  double mean_raw = 0.0;        ///< mean of the raw window scales (estimate units per metre)
  double min = 0.0, max = 0.0;  ///< of the normalised scales
  double sd = 0.0;              ///< population SD of the normalised scales
  double step_sd = 0.0;         ///< SD of differences between consecutive valid windows
};

/// @param est keyframe centres of the estimate (any units), in time order.
/// @param gt ground-truth centres (metres), same order.
/// @param frame_index video frame of each keyframe (non-decreasing).
/// @param window_frames window length in frames (50 in the issue).
/// @param min_true_length_m windows with a shorter true path (stops) are skipped, and a skipped
///        window breaks the chain of steps.
/// @throws InvalidArgument on size mismatch, window_frames < 1, or fewer than 2 valid windows.
inline WindowScaleStats windowed_scale_statistics(const std::vector<Eigen::Vector3d>& est,
                                                  const std::vector<Eigen::Vector3d>& gt,
                                                  const std::vector<int>& frame_index,
                                                  int window_frames = 50,
                                                  double min_true_length_m = 5.0) {
  GEODRIFT_CHECK(est.size() == gt.size() && est.size() == frame_index.size(),
                 "windowed_scale_statistics: sizes differ (" << est.size() << ", " << gt.size()
                                                             << ", " << frame_index.size() << ")");
  GEODRIFT_CHECK(window_frames >= 1,
                 "windowed_scale_statistics: window_frames " << window_frames << " must be >= 1");
  std::vector<double> raw;
  std::vector<int> window_id;
  double len_est = 0.0, len_true = 0.0;
  int current = -1;
  const auto flush = [&]() {
    if (current >= 0 && len_true >= min_true_length_m) {
      raw.push_back(len_est / len_true);
      window_id.push_back(current);
    }
    len_est = len_true = 0.0;
  };
  for (std::size_t k = 0; k + 1 < est.size(); ++k) {
    const int wid = frame_index[k] / window_frames;
    if (wid != current) {
      flush();
      current = wid;
    }
    len_est += (est[k + 1] - est[k]).norm();
    len_true += (gt[k + 1] - gt[k]).norm();
  }
  flush();
  GEODRIFT_CHECK(raw.size() >= 2, "windowed_scale_statistics: only "
                                      << raw.size() << " windows with >= " << min_true_length_m
                                      << " m of true path");
  WindowScaleStats s;
  for (double v : raw) s.mean_raw += v;
  s.mean_raw /= static_cast<double>(raw.size());
  s.scales.reserve(raw.size());
  for (double v : raw) s.scales.push_back(v / s.mean_raw);
  s.min = *std::min_element(s.scales.begin(), s.scales.end());
  s.max = *std::max_element(s.scales.begin(), s.scales.end());
  double var = 0.0;
  for (double v : s.scales) var += (v - 1.0) * (v - 1.0);
  s.sd = std::sqrt(var / static_cast<double>(s.scales.size()));
  std::vector<double> steps;
  for (std::size_t i = 1; i < s.scales.size(); ++i)
    if (window_id[i] == window_id[i - 1] + 1) steps.push_back(s.scales[i] - s.scales[i - 1]);
  if (!steps.empty()) {
    double m = 0.0;
    for (double d : steps) m += d;
    m /= static_cast<double>(steps.size());
    double v = 0.0;
    for (double d : steps) v += (d - m) * (d - m);
    s.step_sd = std::sqrt(v / static_cast<double>(steps.size()));
  }
  return s;
}

}  // namespace geodrift::eval
