#pragma once

/// @file
/// Piecewise-similarity correction: the naive baseline every scale-drift correction must beat
/// (DESIGN.md "Correction" item 4; issue 24 item 5). The raw monocular path is cut into
/// segments between consecutive anchors (by keyframe order) and each segment is mapped into W
/// by its own similarity, fitted to the anchors alone: no pose graph, no covisibility, no
/// smoothing across segment boundaries.
///
/// Conventions (DESIGN.md): keyframe poses T_cw are world→camera in the map frame M (arbitrary
/// unit); W is metric, x east, y north, z up. A segment's similarity is S_wm with
/// p_W = S_wm·p_M; each keyframe's corrected pose is S_i = T_cw,i · S_wm⁻¹ ∈ Sim(3), W → camera
/// in M units (scale s_i = M units per metre), exactly the Corrector's state; its metric pose
/// in W is S_i.to_se3(). The output in W does not depend on the unit or frame of M: every
/// quantity fitted is a similarity between M and W, and every tolerance on M is relative to
/// the path's own extent.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <complex>
#include <string>
#include <vector>

#include "geodrift/error.hpp"
#include "geodrift/eval/umeyama.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"
#include "geodrift/map/keyframe.hpp"

namespace geodrift::correction {

/// Which similarity a segment gets.
enum class PiecewiseVariant {
  /// In the levelled frame: a 2D similarity (scale, yaw, horizontal translation) mapping the
  /// segment's two end anchors exactly onto their W horizontal positions, plus a height
  /// offset (heights scaled by the same scale). Needs W's up direction in M.
  k2D,
  /// A full Sim(3) per segment, Umeyama-fitted to its two end anchors and their neighbours
  /// (previous and next anchor): 3 or 4 points, exact at the ends only for noiseless,
  /// piecewise-constant drift shared by the neighbours.
  k3D,
};

inline const char* to_string(PiecewiseVariant v) {
  switch (v) {
    case PiecewiseVariant::k2D:
      return "piecewise-2d";
    case PiecewiseVariant::k3D:
      return "piecewise-3d";
  }
  return "?";
}

/// One anchor: a place whose position is known both in the map and in the world.
struct PiecewiseAnchor {
  /// Index (into the keyframe list) of the keyframe the anchor belongs to: the keyframe the
  /// geo view was localized against, or the keyframe a GNSS fix was taken at.
  int keyframe = 0;
  /// Camera centre in M (map units): the geo view's centre, or for a GNSS fix the keyframe's
  /// own centre.
  Eigen::Vector3d p_m = Eigen::Vector3d::Zero();
  /// Position in W (metres, x east, y north, z up).
  Eigen::Vector3d y_w = Eigen::Vector3d::Zero();
};

/// Options of piecewise_similarity().
struct PiecewiseOptions {
  PiecewiseVariant variant = PiecewiseVariant::k2D;
  /// Consecutive anchors at different keyframes whose W positions (horizontal for k2D, 3D for
  /// k3D) are closer than this, in metres, are one place in W. If they are also one place in
  /// the map (within 1e-9 of the path's extent: rounding) they are merged (a stationary
  /// camera); otherwise the segment between them would have scale 0 and the call throws.
  double min_anchor_spacing_m = 1e-3;

  /// @return false (and why) when an option is outside its domain.
  bool validate(std::string* why) const {
    if (variant != PiecewiseVariant::k2D && variant != PiecewiseVariant::k3D) {
      if (why) *why = "piecewise: unknown variant";
      return false;
    }
    if (!(std::isfinite(min_anchor_spacing_m) && min_anchor_spacing_m > 0)) {
      if (why)
        *why = "piecewise: min_anchor_spacing_m " + std::to_string(min_anchor_spacing_m) +
               " must be finite and > 0";
      return false;
    }
    return true;
  }
};

/// Anchors after merging: one place per entry, in keyframe order.
struct PiecewiseNode {
  int keyframe = 0;       ///< first keyframe of the merged anchors (starts the next segment)
  int last_keyframe = 0;  ///< last keyframe of the merged anchors
  int first_anchor = 0;   ///< the merged input anchors are [first_anchor, first_anchor + count)
  int count = 0;
  Eigen::Vector3d p_m = Eigen::Vector3d::Zero();  ///< mean camera centre, M
  Eigen::Vector3d y_w = Eigen::Vector3d::Zero();  ///< mean position, W (metres)
};

/// One segment: between nodes k and k + 1.
struct PiecewiseSegment {
  int first_node = 0, last_node = 0;  ///< k, k + 1 (indices into PiecewiseResult::nodes)
  lie::Sim3d S_wm;                    ///< p_W = S_wm·p_M (scale: metres per M unit)
  /// max over the two end nodes of |S_wm·p_m − y_w| (metres, 3D). k2D: the horizontal part is
  /// zero to rounding, so this is the height mismatch; k3D: the fit's residual at the ends.
  double end_error_m = 0.0;
};

/// Result of piecewise_similarity().
struct PiecewiseResult {
  /// Per keyframe: S_i = T_cw,i · S_wm⁻¹ of its segment, W → camera in M units.
  std::vector<lie::Sim3d> S;
  /// Per keyframe: the segment it used (index into `segments`).
  std::vector<int> segment;
  std::vector<PiecewiseNode> nodes;
  std::vector<PiecewiseSegment> segments;

  /// Metric pose of keyframe i in W (world → camera, metres): S_i.to_se3().
  lie::SE3d pose_w(int i) const { return S[i].to_se3(); }
};

namespace detail {

/// A rotation taking the unit vector `up` to +z. Which one does not matter: each segment's
/// yaw absorbs the remaining rotation about z.
inline Eigen::Matrix3d piecewise_levelling(const Eigen::Vector3d& up) {
  return Eigen::Quaterniond::FromTwoVectors(up, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

}  // namespace detail

/// Piecewise-similarity correction of a drifting monocular path from anchors (the naive
/// baseline of DESIGN.md "Correction" item 4).
///
/// Anchors are merged first: consecutive anchors at the same keyframe (e.g. several views of
/// one panorama) become one node at their mean M and W positions; consecutive anchors at one
/// place in both M and W (a stationary camera) likewise. Node k and node k + 1 bound segment
/// k. Keyframe i uses the segment k with node_k.keyframe ≤ i < node_{k+1}.keyframe; keyframes
/// before the first node use segment 0 and keyframes from the last node on use the last
/// segment (its similarity carried on after the last anchor, as issue 24 specifies).
///
/// k2D: M is levelled by a rotation R taking `up_m` to +z (p_L = R·p_M). Horizontally, the
/// complex similarity w = q·m + t (q = s·e^{iθ}) maps the end nodes' levelled positions onto
/// their W positions exactly. Heights: z_W = s·z_L + c with c the mean of the two ends'
/// offsets, so S_wm = (Rz(θ)·R, (t, c), s) is a proper Sim(3) (the model of INIT, paper Sec.
/// 3.4, fitted to two points); heights are exact at the ends only when the levelled height
/// change agrees with the W one (end_error_m says by how much not). Horizontal positions are
/// continuous at every node; heights may step by the two segments' offset difference.
///
/// k3D: S_wm = Umeyama Sim(3) (eval::umeyama) of the nodes k − 1 … k + 2 that exist (3 or 4
/// points: the ends plus their neighbours), so a segment's rotation is observable even on a
/// gently curving road; it is not exact at the ends. `up_m` is not used.
///
/// How the Corrector uses it: T_cw = the raw keyframe poses in insertion order; one anchor
/// per correspondence, keyframe = its keyframe's index, p_m = centre of (T_vk·T_cw,k), y_w =
/// its geo-tag position, sorted stably by keyframe; up_m = INIT's levelling,
/// `InitResult::R_level.row(2).transpose()` (W's up in M; any up estimate works standalone,
/// e.g. the PCA normal of the camera centres signed by the cameras' up). Keyframe state =
/// result.S; a map point X_m with reference keyframe r goes to
/// segments[segment[r]].S_wm.act(X_m) (= S_r⁻¹·T_cw,r·X_m, DESIGN.md's point rule).
///
/// @param T_cw     raw keyframe poses, world→camera in M, time order (at least one)
/// @param anchors  at least 2 (k3D: at least 3 distinct places), keyframe indices in range and
///                 non-decreasing
/// @param up_m     k2D: W's up direction expressed in M (any length > 0; its sign matters —
///                 a downward vector mirrors the path); k3D: ignored (may be zero)
/// @throws InvalidArgument on a non-finite pose, anchor or up vector; a keyframe index out of
///         range or decreasing; fewer than 2 distinct places after merging (k3D: 3); two
///         consecutive places coincident in M but not in W (zero-length segment) or in W but
///         not in M (zero scale); a degenerate k3D fit (collinear points).
inline PiecewiseResult piecewise_similarity(const std::vector<lie::SE3d>& T_cw,
                                            const std::vector<PiecewiseAnchor>& anchors,
                                            const Eigen::Vector3d& up_m,
                                            const PiecewiseOptions& options = {}) {
  std::string why;
  GEODRIFT_CHECK(options.validate(&why), why);
  const bool planar = options.variant == PiecewiseVariant::k2D;
  const int n = static_cast<int>(T_cw.size());
  GEODRIFT_CHECK(n > 0, "piecewise: no keyframes");
  for (int i = 0; i < n; ++i) {
    GEODRIFT_CHECK(T_cw[i].matrix().allFinite(),
                   "piecewise: keyframe " << i << " pose is not finite");
    map::check_map_coordinates(T_cw[i].translation(), "piecewise", "keyframe", i, "translation");
  }
  GEODRIFT_CHECK(anchors.size() >= 2,
                 "piecewise: " << anchors.size() << " anchor(s), at least 2 are needed");
  for (std::size_t j = 0; j < anchors.size(); ++j) {
    const PiecewiseAnchor& a = anchors[j];
    GEODRIFT_CHECK(a.keyframe >= 0 && a.keyframe < n, "piecewise: anchor "
                                                          << j << " keyframe " << a.keyframe
                                                          << " outside [0, " << n - 1 << "]");
    GEODRIFT_CHECK(a.p_m.allFinite() && a.y_w.allFinite(),
                   "piecewise: anchor " << j << " position is not finite");
    GEODRIFT_CHECK(j == 0 || a.keyframe >= anchors[j - 1].keyframe,
                   "piecewise: anchor " << j << " keyframe " << a.keyframe << " precedes anchor "
                                        << j - 1 << " keyframe " << anchors[j - 1].keyframe
                                        << " (anchors must be in keyframe order)");
  }
  Eigen::Matrix3d R_lev = Eigen::Matrix3d::Identity();
  if (planar) {
    const double norm = up_m.norm();
    GEODRIFT_CHECK(
        up_m.allFinite() && std::isfinite(norm) && norm > 0,
        "piecewise 2D: up direction (" << up_m.transpose() << ") must be finite and non-zero");
    R_lev = detail::piecewise_levelling(up_m / norm);
  }

  // "One place in M" is relative to the extent of the path (keyframe centres and anchors), so
  // the decision does not depend on M's unit, origin or orientation.
  std::vector<Eigen::Vector3d> centres(n);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    centres[i] = T_cw[i].inverse().translation();
    mean += centres[i];
  }
  for (const auto& a : anchors) mean += a.p_m;
  mean /= static_cast<double>(n + static_cast<int>(anchors.size()));
  double radius = 0;
  for (const auto& c : centres) radius = std::max(radius, (c - mean).norm());
  for (const auto& a : anchors) radius = std::max(radius, (a.p_m - mean).norm());
  const double tol_m = 1e-9 * 2.0 * radius;

  // Distances that matter to the variant: horizontal (levelled) for k2D, 3D for k3D.
  const auto dist_m = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return planar ? (R_lev * (a - b)).head<2>().norm() : (a - b).norm();
  };
  const auto dist_w = [&](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return planar ? (a - b).head<2>().norm() : (a - b).norm();
  };
  const auto coincident_m = [&](double d) { return d <= tol_m; };
  const auto coincident_w = [&](double d) { return d < options.min_anchor_spacing_m; };

  // ---- 1. merge anchors into nodes ------------------------------------------------------
  std::vector<PiecewiseNode> nodes;
  for (std::size_t j = 0; j < anchors.size(); ++j) {
    const PiecewiseAnchor& a = anchors[j];
    if (!nodes.empty()) {
      PiecewiseNode& b = nodes.back();
      const bool same_keyframe = a.keyframe == b.last_keyframe;
      const bool same_place =
          coincident_m(dist_m(a.p_m, b.p_m)) && coincident_w(dist_w(a.y_w, b.y_w));
      if (same_keyframe || same_place) {
        const double k = static_cast<double>(b.count);
        b.p_m = (k * b.p_m + a.p_m) / (k + 1);
        b.y_w = (k * b.y_w + a.y_w) / (k + 1);
        b.last_keyframe = a.keyframe;
        ++b.count;
        continue;
      }
    }
    PiecewiseNode node;
    node.keyframe = node.last_keyframe = a.keyframe;
    node.first_anchor = static_cast<int>(j);
    node.count = 1;
    node.p_m = a.p_m;
    node.y_w = a.y_w;
    nodes.push_back(node);
  }
  const int num_nodes = static_cast<int>(nodes.size());
  GEODRIFT_CHECK(num_nodes >= 2, "piecewise: the " << anchors.size()
                                                   << " anchors merge into 1 place (same "
                                                      "keyframe or same position): at least 2 "
                                                      "distinct places are needed");
  GEODRIFT_CHECK(planar || num_nodes >= 3,
                 "piecewise 3D: " << num_nodes
                                  << " distinct anchor places, the Umeyama fit of a segment "
                                     "needs at least 3");

  // ---- 2. every segment has a length in M and in W -------------------------------------
  // On the final nodes (merging moves a node's mean), and before any fit: a k3D fit spans
  // neighbouring segments and would report a degenerate neighbour as its own collinearity.
  for (int k = 0; k + 1 < num_nodes; ++k) {
    const PiecewiseNode& a = nodes[k];
    const PiecewiseNode& b = nodes[k + 1];
    const double dm = dist_m(a.p_m, b.p_m), dw = dist_w(a.y_w, b.y_w);
    const int ja = a.first_anchor + a.count - 1, jb = b.first_anchor;
    GEODRIFT_CHECK(!coincident_m(dm), "piecewise: anchors "
                                          << ja << " (keyframe " << a.last_keyframe << ") and "
                                          << jb << " (keyframe " << b.keyframe
                                          << ") are at one place in the map (zero-length "
                                             "segment) but "
                                          << dw << " m apart in W");
    GEODRIFT_CHECK(!coincident_w(dw), "piecewise: anchors "
                                          << ja << " (keyframe " << a.last_keyframe << ") and "
                                          << jb << " (keyframe " << b.keyframe << ") are " << dw
                                          << " m apart in W (below min_anchor_spacing_m "
                                          << options.min_anchor_spacing_m
                                          << ") but distinct in the map: the segment's scale "
                                             "would be 0");
  }

  // ---- 3. one similarity per segment ----------------------------------------------------
  std::vector<PiecewiseSegment> segments(num_nodes - 1);
  for (int k = 0; k + 1 < num_nodes; ++k) {
    const PiecewiseNode& a = nodes[k];
    const PiecewiseNode& b = nodes[k + 1];
    PiecewiseSegment& seg = segments[k];
    seg.first_node = k;
    seg.last_node = k + 1;
    if (planar) {
      using C = std::complex<double>;
      const Eigen::Vector3d pa = R_lev * a.p_m, pb = R_lev * b.p_m;
      const C ma(pa.x(), pa.y()), mb(pb.x(), pb.y());
      const C wa(a.y_w.x(), a.y_w.y()), wb(b.y_w.x(), b.y_w.y());
      const C q = (wb - wa) / (mb - ma);
      const double s = std::abs(q);
      // Through the midpoint: the two ends' rounding errors are balanced.
      const C t = 0.5 * (wa + wb) - q * (0.5 * (ma + mb));
      const double c = 0.5 * ((a.y_w.z() - s * pa.z()) + (b.y_w.z() - s * pb.z()));
      const Eigen::Matrix3d Rz =
          Eigen::AngleAxisd(std::arg(q), Eigen::Vector3d::UnitZ()).toRotationMatrix();
      seg.S_wm = lie::Sim3d(lie::SO3d(Eigen::Matrix3d(Rz * R_lev)),
                            Eigen::Vector3d(t.real(), t.imag(), c), s);
    } else {
      std::vector<Eigen::Vector3d> src, dst;
      for (int m = std::max(0, k - 1); m <= std::min(num_nodes - 1, k + 2); ++m) {
        src.push_back(nodes[m].p_m);
        dst.push_back(nodes[m].y_w);
      }
      const eval::Alignment al = eval::umeyama(src, dst, true);
      GEODRIFT_CHECK(al.ok(), "piecewise 3D: segment " << k << " (anchors " << a.first_anchor
                                                       << " to " << b.first_anchor + b.count - 1
                                                       << "), fitted to " << src.size()
                                                       << " anchor places: " << al.message);
      seg.S_wm = lie::Sim3d(lie::SO3d(al.R), al.t, al.s);
    }
    seg.end_error_m =
        std::max((seg.S_wm.act(a.p_m) - a.y_w).norm(), (seg.S_wm.act(b.p_m) - b.y_w).norm());
  }

  // ---- 4. every keyframe takes its segment's similarity ---------------------------------
  PiecewiseResult out;
  out.S.resize(n);
  out.segment.resize(n);
  std::vector<lie::Sim3d> S_mw(segments.size());
  for (std::size_t k = 0; k < segments.size(); ++k) S_mw[k] = segments[k].S_wm.inverse();
  int k = 0;  // keyframes and nodes both ascend: one sweep
  for (int i = 0; i < n; ++i) {
    while (k + 2 < num_nodes && nodes[k + 1].keyframe <= i) ++k;
    out.segment[i] = k;
    out.S[i] = lie::Sim3d(T_cw[i]) * S_mw[k];
  }
  out.nodes = std::move(nodes);
  out.segments = std::move(segments);
  return out;
}

}  // namespace geodrift::correction
