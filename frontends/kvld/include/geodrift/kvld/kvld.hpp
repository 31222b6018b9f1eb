#pragma once

// K-VLD: K virtual-line-descriptor consistency filter for putative feature matches.
//
// Implements Z. Liu and R. Marlet, "Virtual Line Descriptor and Semi-Local Matching Method for
// Reliable Feature Correspondence", BMVC 2012, with the defaults and the retry schedule of the
// authors' code (Zhe-LIU-Imagine/KVLD, adapted in openMVG as matching/kvld). The behaviour is
// specified in shared/notes/kvld.md; this is an independent implementation (no code copied).
//
// Coordinates everywhere: pixels of the full-resolution image, origin at the centre of the
// top-left pixel, x right, y down (OpenCV). Angles: radians, measured from +x towards +y
// (clockwise on screen), i.e. OpenCV's KeyPoint::angle converted from degrees.
//
// Typical use (geo-tag pipeline: one keyframe against many views):
//
//   const kvld::ImageScale key_scale(keyframe_gray);          // once per image
//   const kvld::ImageScale view_scale(view_gray);              // once per view (cacheable)
//   const auto F1 = kvld::keypoints_from_cv(orb_keypoints_key);
//   const auto F2 = kvld::keypoints_from_cv(orb_keypoints_view);
//   const auto putative = kvld::match_putative(desc_key, desc_view);
//   const kvld::Result r = kvld::filter(key_scale, view_scale, F1, F2, putative);
//   for (const kvld::Match& m : r.matches) ...                 // F1[m.i1] <-> F2[m.i2]

#include <array>
#include <cstddef>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace geodrift::kvld {

inline constexpr int kDimension = 10;    ///< discs per VLD (`dimension`)
inline constexpr int kSubdirection = 8;  ///< descriptor bins per disc (`subdirection`)
inline constexpr int kBinNum = 24;       ///< main-orientation bins per disc (`binNum`, even)

// ------------------------------------------------------------------------------------------
// Scale space
// ------------------------------------------------------------------------------------------

/// One level of the K-VLD scale space: central-difference gradients of the (box-averaged)
/// image. Row-major, `width * height` entries each.
struct ScaleLevel {
  int width = 0;
  int height = 0;
  /// Size of one level pixel in full-resolution pixels: sqrt(2)^k for level k.
  double ratio = 1.0;
  /// Gradient orientation atan2(gy, gx) in [0, 2π) (y down); -1 where the gradient is exactly
  /// zero; 0 on the one-pixel border (never sampled).
  std::vector<float> angle;
  /// Gradient magnitude hypot(gx, gy), gx = I(x+1,y) - I(x-1,y), gy = I(x,y+1) - I(x,y-1);
  /// 0 on the border.
  std::vector<float> magnitude;
  /// Cache for the VLD's inner loop: `angle` · 24/(2π) (0 where the gradient is zero).
  std::vector<float> angle_bins;
};

/// Precomputed gradient pyramid of one grayscale image (kvld.md §3.2).
///
/// Level 0 is the image itself. Level k (k ≥ 1) has size ⌊W/√2ᵏ⌋ × ⌊H/√2ᵏ⌋ and each of its
/// pixels (i, j) is the exact area average of the (piecewise-constant) input over the square
/// [i·√2ᵏ, (i+1)·√2ᵏ) × [j·√2ᵏ, (j+1)·√2ᵏ), evaluated with an integral image (the box
/// average that replaces a Gaussian blur in the reference code). Number of levels =
/// ⌊log₂(max(W, H)/r₀)⌋ + 1 with base radius r₀ = 5.
///
/// Built once per image and reused for any number of pairs (it is immutable, so it may be
/// shared between threads). Memory: 3 floats per pixel per level, levels shrinking by 2 in
/// area: about 24·W·H bytes (11 MB for 1241×376). Building it costs about 2.7 ORB
/// detect+compute of the same image (30 ms against 11 ms CPU: BENCHMARKS.md "K-VLD").
///
/// Intensities are used as given; the reference code and the `max_contrast` gate (300) assume
/// a 0–255 scale, which is what an 8-bit image gives.
class ImageScale {
 public:
  /// From a single-channel image of depth CV_8U, CV_16U, CV_32F or CV_64F.
  /// @throws InvalidArgument if the image is empty, has more than one channel, another depth,
  ///         is smaller than 3×3, or holds a non-finite value.
  explicit ImageScale(const cv::Mat& gray, double base_radius = 5.0);

  /// From a raw row-major float buffer; `stride` = floats between row starts (≥ width).
  /// @throws InvalidArgument on a null pointer, a size below 3×3, stride < width, a
  ///         non-finite pixel or base_radius ≤ 0.
  ImageScale(const float* data, int width, int height, std::ptrdiff_t stride,
             double base_radius = 5.0);

  int width() const { return width_; }
  int height() const { return height_; }
  double base_radius() const { return base_radius_; }
  int num_levels() const { return static_cast<int>(levels_.size()); }
  const ScaleLevel& level(int k) const { return levels_.at(static_cast<std::size_t>(k)); }

  /// Level whose radius band contains the disc radius r (full-resolution pixels): 0 for
  /// r ≤ r₀, otherwise the smallest k with r ≤ r₀·√2ᵏ⁺¹, clamped to the last level.
  int level_for_radius(double r) const;

 private:
  void build(const std::vector<float>& image);

  int width_ = 0;
  int height_ = 0;
  double base_radius_ = 5.0;
  std::vector<ScaleLevel> levels_;
};

// ------------------------------------------------------------------------------------------
// Virtual line descriptor
// ------------------------------------------------------------------------------------------

/// Virtual line descriptor of the segment P1 → P2 (kvld.md §3.3).
struct Vld {
  /// Per disc, 8 relative-orientation bins, L1-normalised over all 80 (sum 1, or all 0).
  std::array<double, kDimension * kSubdirection> descriptor{};
  /// Per disc, the 24-bin index i maximising hist[i] − hist[i ± 12] (first on ties).
  std::array<int, kDimension> main_bin{};
  /// Per disc, that maximal difference, L1-normalised over the 10 discs (or all 0).
  std::array<double, kDimension> weight{};
  /// Σ (unnormalised) disc weights / (L / level ratio). ≤ 0 or > 300 means "unusable".
  double contrast = 0.0;
  double length = 0.0;  ///< L = |P2 − P1|, full-resolution pixels
  int level = 0;        ///< scale-space level the discs were sampled on
};

/// Builds the VLD of the segment (x1, y1) → (x2, y2) on `scale` (kvld.md §3.3): disc radius
/// ρ = max(L/11, 2) at level 0, level = scale.level_for_radius(ρ); disc i = 1..10 centred at
/// P1 + i/11·(P2 − P1); every level pixel at distance d ≤ ρ/ratio from a centre and at least
/// one pixel inside the level border adds w = exp(−d²/(4.5·(ρ/ratio)²))·|∇I| to the
/// 24-bin and 8-bin histograms of its orientation relative to the segment direction
/// (nearest-bin rounding, the top bin wraps to 0).
/// @throws InvalidArgument if a coordinate is non-finite.
Vld compute_vld(const ImageScale& scale, double x1, double y1, double x2, double y2);

/// Difference D between two VLDs (kvld.md §3.3): 128 if either contrast is ≤ 0 or > 300,
/// otherwise 0.36·Σ|desc₁ − desc₂| + (0.64/24)·Σᵢ circdist₂₄(binᵢ, bin′ᵢ)·(wᵢ + w′ᵢ).
/// Pairs with D < 0.35 (`Options::juge`) are VLD-consistent.
double vld_difference(const Vld& a, const Vld& b, double max_contrast = 300.0);

// ------------------------------------------------------------------------------------------
// Keypoints, matches, geometric consistency
// ------------------------------------------------------------------------------------------

/// A keypoint as K-VLD needs it. Pixels (x right, y down); `scale` > 0 in pixels (any
/// detector-consistent measure: ORB KeyPoint::size, or 1.2^octave); `angle` in radians from
/// +x towards +y. Scale and angle are only read when `Options::geometry` is on.
struct Keypoint {
  double x = 0.0;
  double y = 0.0;
  double scale = 1.0;
  double angle = 0.0;
};

/// Converts OpenCV keypoints: pt → (x, y), angle degrees → radians, and scale = size, or, with
/// `octave_scale_factor` > 0, scale = octave_scale_factor^octave (ORB: 1.2^octave; only for
/// detectors whose `octave` field is the plain pyramid level, not SIFT's packed one). An
/// angle of −1 (OpenCV's "not computed") becomes NaN, which `filter` rejects when geometry
/// is on.
/// @throws InvalidArgument if octave_scale_factor is negative or non-finite.
std::vector<Keypoint> keypoints_from_cv(const std::vector<cv::KeyPoint>& keypoints,
                                        double octave_scale_factor = 0.0);

/// A putative or kept match: index into the first and into the second keypoint list.
struct Match {
  int i1 = 0;
  int i2 = 0;
  friend bool operator==(const Match& a, const Match& b) { return a.i1 == b.i1 && a.i2 == b.i2; }
};

/// Geometric consistency of matches (a1 ↔ b1) and (a2 ↔ b2) (kvld.md §3.4): the vector
/// a2→a1 rotated by (angle_b1 − angle_a1) and scaled by scale_b1/scale_a1 predicts b2→b1; e₁
/// = |pred − (b1 − b2)| / min(|pred|, |b1 − b2|); e₂ likewise with match 2's rotation and
/// scale. Returns min(e₁, e₂); < 0.5 (`Options::distance_thres`) is consistent. Symmetric in
/// the two matches. Degenerate inputs (coincident points) give +inf or NaN, never "consistent".
double geometric_consistency(const Keypoint& a1, const Keypoint& a2, const Keypoint& b1,
                             const Keypoint& b2);

// ------------------------------------------------------------------------------------------
// K-VLD
// ------------------------------------------------------------------------------------------

/// Parameters; the defaults are the published ones (kvld.md §3.6).
struct Options {
  double inlier_rate = 0.04;    ///< p in range = √(3·W·H/(π·p·n)); halved on each retry
  int K = 3;                    ///< consistent neighbours required (first run)
  bool geometry = true;         ///< geometric checks (§3.4, step 4 of §3.5)
  bool unique_match = true;     ///< one-to-one output (step 3)
  double juge = 0.35;           ///< VLD difference threshold
  double distance_thres = 0.5;  ///< geometric consistency threshold
  double min_dist = 10.0;       ///< min endpoint separation in BOTH images, pixels
  int max_connection = 20;      ///< stop counting a match's neighbours after this many
  double max_contrast = 300.0;  ///< lines above this contrast (or ≤ 0) are inconsistent
  double range_ratio = 1.0;     ///< extra multiplier of the neighbourhood radius
  /// Driver (kvld_filter.cpp): while survival ratio < inlier_rate and fewer than `max_runs`
  /// runs were made, halve inlier_rate, set K = `retry_K` and run again. 1 = no retries.
  int max_runs = 5;
  int retry_K = 2;
  bool collect_edges = false;  ///< fill Result::edges (consistent pairs among kept matches)

  /// True when every value is in its domain; otherwise false and *why names the first bad one.
  bool validate(std::string* why = nullptr) const;
};

/// A VLD-consistent pair of kept matches (for drawing the K-VLD graph).
struct Edge {
  int m1 = 0;           ///< index into the putative list
  int m2 = 0;           ///< index into the putative list, m1 < m2
  double vld_diff = 0;  ///< D of the pair (< juge)
};

/// Output of `filter`.
struct Result {
  std::vector<Match> matches;     ///< kept matches, in putative order
  std::vector<int> kept_indices;  ///< their indices in the putative list
  /// Per kept match: with geometry on, the mean geometric consistency error over its valid
  /// neighbours (lower is better; +inf if it had none); with geometry off, the sum of D over
  /// its VLD-consistent neighbours. As the reference code's `score`.
  std::vector<double> scores;
  std::vector<int> num_consistent;  ///< consistent neighbours counted in the last pass
  double survival_ratio = 0.0;      ///< |kept| / |putative| (0 for an empty input)
  int runs = 0;                     ///< K-VLD runs made by the retry schedule
  double final_inlier_rate = 0.0;   ///< inlier_rate of the last run
  int final_K = 0;                  ///< K of the last run
  std::size_t vld_pairs = 0;        ///< pairs whose two VLDs were built (all runs)
  std::size_t tested_pairs = 0;     ///< pairs tested (cache entries)
  std::vector<Edge> edges;          ///< only with Options::collect_edges
};

/// Runs K-VLD with the published retry schedule on the putative matches between the images
/// behind `scale1` and `scale2` (kvld.md §3.5). The consistency cache persists across runs.
///
/// An empty putative list gives an empty Result (ratio 0, runs 0).
/// @throws InvalidArgument if options are invalid; a keypoint coordinate is non-finite or
///         outside its image; with geometry on, a scale is not > 0 or an angle non-finite; a
///         match index is out of range.
Result filter(const ImageScale& scale1, const ImageScale& scale2, const std::vector<Keypoint>& F1,
              const std::vector<Keypoint>& F2, const std::vector<Match>& putative,
              const Options& options = {});

// ------------------------------------------------------------------------------------------
// Putative matching (before K-VLD)
// ------------------------------------------------------------------------------------------

struct PutativeOptions {
  double ratio = 0.8;      ///< Lowe ratio: best < ratio · second best (kvld_filter.cpp uses 0.8)
  bool mutual = true;      ///< keep i→j only if j's nearest neighbour in image 1 is i
  int max_matches = 1000;  ///< keep the best (smallest descriptor distance) this many; 0 = all
  bool validate(std::string* why = nullptr) const;
};

/// Brute-force nearest-neighbour matching of descriptors (rows), Hamming for CV_8U (ORB,
/// BRIEF), L2 for CV_32F (SIFT), with the ratio test, the optional mutual check and the cap.
/// Result sorted by descriptor distance, best first. Fewer than 2 rows in desc2: no matches.
/// @throws InvalidArgument if the descriptors differ in type or width, or are neither CV_8U
///         nor CV_32F single-channel.
std::vector<Match> match_putative(const cv::Mat& desc1, const cv::Mat& desc2,
                                  const PutativeOptions& options = {});

}  // namespace geodrift::kvld
