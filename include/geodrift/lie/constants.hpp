#pragma once

/// @file
/// Thresholds of the Lie-group code: below each one a closed form would cancel catastrophically,
/// so a Taylor series is used instead. Every threshold is paired with the number of series terms
/// kept, chosen so the truncation error is below double rounding at the threshold.

namespace geodrift::lie {

/// Rotation angle (rad) below which SO3/SE3 closed forms (sin(θ)/θ, (1-cosθ)/θ², the SE3 left
/// Jacobian coefficients and their θ-derivatives) switch to Taylor series in θ². The series keep
/// terms up to θ⁴ or θ⁶; at θ = 1e-2 the first dropped term is < 1e-18 while the closed forms
/// lose at most eps/θ⁴ ≈ 2e-8 relative in the worst (fifth-order) coefficient above it.
template <typename Scalar>
inline constexpr Scalar kSmallAngle = Scalar(1e-2);

/// Rotation angle (rad) below which the Sim3 V-matrix coefficients c1, c2 and their σ- and
/// θ-derivatives are evaluated by their series in θ² (with σ-moments g_k(σ) as coefficients)
/// instead of the complex closed forms Im φ(σ+iθ)/θ, (φ(σ) − Re φ(σ+iθ))/θ², which lose
/// eps/θ⁴ relative. kSim3ThetaSeriesTerms terms keep the truncation < 1e-17 at θ = 0.5.
template <typename Scalar>
inline constexpr Scalar kSim3ThetaSeries = Scalar(0.5);

/// Number of terms m = 0..kSim3ThetaSeriesTerms-1 kept in the Sim3 θ² series.
inline constexpr int kSim3ThetaSeriesTerms = 8;

/// |σ| below which the σ-moments g_k(σ) = ∫₀¹ sᵏ e^{sσ} ds are computed by their power series
/// plus the (then stable) downward recurrence; above it the upward recurrence
/// g_k = (e^σ − k g_{k−1})/σ is stable enough (growth Π k/|σ| stays < 1e4 for k ≤ 17).
template <typename Scalar>
inline constexpr Scalar kSim3SigmaSeries = Scalar(4);

/// Largest number of power-series terms summed for one σ-moment (|σ| ≤ 4 converges in < 60).
inline constexpr int kSim3SigmaSeriesMaxTerms = 80;

}  // namespace geodrift::lie
