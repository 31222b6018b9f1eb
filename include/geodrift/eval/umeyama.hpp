#pragma once

/// @file
/// Umeyama (1991) least-squares alignment of two point sets: a similarity dst ≈ s·R·src + t
/// (Sim(3)) or a rigid one (s = 1). Source points in their own frame (e.g. the map M), target
/// points in the target frame (e.g. W, metres). Degenerate inputs (fewer than 3 pairs,
/// coincident or collinear points) are reported in Alignment::status, never turned into an
/// arbitrary rotation.

#include <Eigen/Core>
#include <Eigen/SVD>
#include <cmath>
#include <string>
#include <vector>

#include "geodrift/error.hpp"

namespace geodrift::eval {

/// Why an alignment could not be determined.
enum class AlignmentStatus {
  kOk,      ///< unique solution
  kTooFew,  ///< fewer than 3 point pairs (2 for kSE3 is still ambiguous: rotation about the line)
  kCoincident,  ///< source points (numerically) all at one place: scale and rotation unobservable
  kCollinear,   ///< source points on one line: the rotation about that line is unobservable
};

/// A similarity dst ≈ s·R·src + t (Umeyama 1991). For an SE(3) alignment s = 1.
/// `status != kOk` means the input was degenerate; then (s, R, t) are identity and `message`
/// says why. Frames: src in its own frame (e.g. the map M), dst in the target frame (e.g. W).
struct Alignment {
  double s = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  AlignmentStatus status = AlignmentStatus::kOk;
  std::string message;
  double rmse = 0.0;  ///< RMS of |dst − (s·R·src + t)| over the pairs, units of dst

  bool ok() const { return status == AlignmentStatus::kOk; }
  /// Applies the similarity to a src-frame point.
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const { return s * (R * p) + t; }
};

/// Collinearity gate: the configuration counts as collinear when σ2/σ1 of the centred source
/// covariance (variances, so a spread ratio of 1e-5) is below this.
inline constexpr double kAlignmentCollinearRatio = 1e-10;
/// Coincidence gate: the points count as coincident when the largest variance is below this
/// times the largest squared coordinate (a spread of 1e-10 of the coordinates' magnitude, i.e.
/// rounding level), so far-from-origin coordinates (UTM) with a real spread are not flagged.
inline constexpr double kAlignmentCoincidentRatio = 1e-20;

/// Least-squares similarity (with_scale = true, Sim(3)) or rigid (false, SE(3)) alignment
/// minimising Σ|dst_i − (s·R·src_i + t)|², closed form of Umeyama, "Least-squares estimation of
/// transformation parameters between two point patterns", PAMI 13(4), 1991, eqs. (38)-(42):
/// Σ = (1/n)·Σ dst_c·src_cᵀ = U·D·Vᵀ, S = diag(1, 1, ±1) making det(R) = +1, R = U·S·Vᵀ,
/// s = tr(D·S)/var(src), t = mean(dst) − s·R·mean(src). The scale is positive by construction.
/// Degenerate inputs (fewer than 3 pairs, coincident or collinear source points) are reported
/// in the result's status, never turned into an arbitrary rotation.
/// @throws InvalidArgument if the sizes differ or a coordinate is not finite.
inline Alignment umeyama(const std::vector<Eigen::Vector3d>& src,
                         const std::vector<Eigen::Vector3d>& dst, bool with_scale = true) {
  GEODRIFT_CHECK(src.size() == dst.size(), "umeyama: " << src.size() << " source points but "
                                                       << dst.size() << " destination points");
  for (std::size_t i = 0; i < src.size(); ++i)
    GEODRIFT_CHECK(src[i].allFinite() && dst[i].allFinite(),
                   "umeyama: point pair " << i << " is not finite");
  Alignment out;
  const std::size_t n = src.size();
  if (n < 3) {
    out.status = AlignmentStatus::kTooFew;
    out.message = "umeyama: " + std::to_string(n) + " point pairs, at least 3 are needed";
    return out;
  }
  Eigen::Vector3d mu_s = Eigen::Vector3d::Zero(), mu_d = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    mu_s += src[i];
    mu_d += dst[i];
  }
  mu_s /= static_cast<double>(n);
  mu_d /= static_cast<double>(n);
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero(), cov_s = Eigen::Matrix3d::Zero();
  double var_s = 0.0, extent = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d a = src[i] - mu_s, b = dst[i] - mu_d;
    sigma += b * a.transpose();
    cov_s += a * a.transpose();
    var_s += a.squaredNorm();
    extent = std::max(extent, src[i].squaredNorm());
  }
  sigma /= static_cast<double>(n);
  cov_s /= static_cast<double>(n);
  var_s /= static_cast<double>(n);

  // Degeneracy of the source configuration: eigenvalues of its covariance.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd_s(cov_s);
  const Eigen::Vector3d ev = svd_s.singularValues();
  if (ev(0) <= kAlignmentCoincidentRatio * extent || ev(0) <= 1e-300) {
    out.status = AlignmentStatus::kCoincident;
    out.message = "umeyama: the " + std::to_string(n) +
                  " source points coincide; scale and rotation are unobservable";
    return out;
  }
  if (ev(1) <= kAlignmentCollinearRatio * ev(0)) {
    out.status = AlignmentStatus::kCollinear;
    out.message = "umeyama: the " + std::to_string(n) +
                  " source points are collinear; the rotation about their line is unobservable";
    return out;
  }

  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d S(1.0, 1.0, 1.0);
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) S(2) = -1.0;
  out.R = svd.matrixU() * S.asDiagonal() * svd.matrixV().transpose();
  out.s = with_scale ? svd.singularValues().dot(S) / var_s : 1.0;
  out.t = mu_d - out.s * (out.R * mu_s);
  double sq = 0.0;
  for (std::size_t i = 0; i < n; ++i) sq += (dst[i] - out.apply(src[i])).squaredNorm();
  out.rmse = std::sqrt(sq / static_cast<double>(n));
  return out;
}

}  // namespace geodrift::eval
