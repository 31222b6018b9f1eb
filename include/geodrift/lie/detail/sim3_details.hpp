#pragma once

/// @file
/// Implementation details of Sim3: the exact coefficients of
///   C(ω, σ) = ∫₀¹ e^{uσ}·exp(uW) du = c0·I + c1·W + c2·W²    (t = C·ν in exp),
/// and of their σ- and θ-derivatives, which the exact Sim3 left Jacobian needs
/// (detail::translation_rows). Nothing outside include/geodrift/lie names this namespace.
///
/// Derivation. W = [ω]x has eigenvalues 0, ±iθ with spectral projectors P0 = I + W²/θ²,
/// P± = (−W²/θ² ∓ iW/θ)/2, so for any analytic f, f(σI + W) = f(σ)·P0 + f(σ+iθ)·P+ +
/// f(σ−iθ)·P−, i.e. with z = σ + iθ:
///   f(σI+W) = f(σ)·I + (Im f(z)/θ)·W + ((f(σ) − Re f(z))/θ²)·W².
/// C = φ(σI + W) with φ(z) = (eᶻ − 1)/z, hence
///   c0 = φ(σ),  c1 = Im φ(z)/θ,  c2 = (φ(σ) − Re φ(z))/θ².
/// φ is holomorphic, so ∂/∂σ φ(z) = φ'(z) and ∂/∂θ φ(z) = i·φ'(z), giving
///   c0s = φ'(σ), c1s = Im φ'(z)/θ, c2s = (φ'(σ) − Re φ'(z))/θ²,
///   c1t = (Re φ'(z) − c1)/θ²,  c2t = (c1s − 2·c2)/θ²        (c·t = (∂c/∂θ)/θ).
/// These are exact. For θ < kSim3ThetaSeries they cancel, and the series in θ² are used:
/// with the σ-moments g_k(σ) = ∫₀¹ sᵏ e^{sσ} ds = φ⁽ᵏ⁾(σ),
///   c1  = Σ_{m≥0} (−1)^m θ^{2m} g_{2m+1}/(2m+1)!      c1s = Σ_{m≥0} (−1)^m θ^{2m} g_{2m+2}/(2m+1)!
///   c2  = Σ_{m≥1} (−1)^{m+1} θ^{2m−2} g_{2m}/(2m)!    c2s = Σ_{m≥1} (−1)^{m+1} θ^{2m−2}
///   g_{2m+1}/(2m)! c1t = Σ_{m≥1} (−1)^m 2m θ^{2m−2} g_{2m+1}/(2m+1)! c2t = Σ_{m≥2} (−1)^{m+1}
///   (2m−2) θ^{2m−4} g_{2m}/(2m)!
/// and g_k(σ) itself has a power series for small |σ| (covering σ → 0 and θ, σ → 0 together).

#include <cmath>
#include <complex>
#include <limits>

#include "geodrift/lie/constants.hpp"
#include "geodrift/lie/detail/so3_details.hpp"

namespace geodrift::lie::detail {

/// Highest σ-moment index the θ² series needs: g_{2M} with M = kSim3ThetaSeriesTerms.
inline constexpr int kSim3MaxMoment = 2 * kSim3ThetaSeriesTerms;

/// 1/k! for k = 0..kSim3MaxMoment + 1 (the series' factorials, no division in the loops).
inline constexpr double kInvFactorial[kSim3MaxMoment + 2] = {1.0,
                                                             1.0,
                                                             1.0 / 2.0,
                                                             1.0 / 6.0,
                                                             1.0 / 24.0,
                                                             1.0 / 120.0,
                                                             1.0 / 720.0,
                                                             1.0 / 5040.0,
                                                             1.0 / 40320.0,
                                                             1.0 / 362880.0,
                                                             1.0 / 3628800.0,
                                                             1.0 / 39916800.0,
                                                             1.0 / 479001600.0,
                                                             1.0 / 6227020800.0,
                                                             1.0 / 87178291200.0,
                                                             1.0 / 1307674368000.0,
                                                             1.0 / 20922789888000.0,
                                                             1.0 / 355687428096000.0};

/// 1/k for k = 0..kSim3MaxMoment + kSim3SigmaSeriesMaxTerms (entry 0 unused): the moments'
/// power series and recurrences multiply by these instead of dividing (a division is a serial
/// ≈ 13-cycle step in their dependency chains; 1/k is correctly rounded at compile time).
struct InverseIntegers {
  static constexpr int kSize = kSim3MaxMoment + kSim3SigmaSeriesMaxTerms + 1;
  double value[kSize];
  constexpr InverseIntegers() : value{} {
    for (int k = 1; k < kSize; ++k) value[k] = 1.0 / k;
  }
  constexpr double operator[](int k) const { return value[k]; }
};
inline constexpr InverseIntegers kInvInteger{};

/// Number of θ² series terms M used for a given θ < kSim3ThetaSeries. The truncation of every
/// coefficient's series (c1, c2, their σ- and θ-derivatives; the worst are c2s and c1t, whose
/// first dropped term is O(θ^{2M−2})) relative to its leading term is, with M terms at θ below
/// kSim3ThetaSeriesBound[M], at most what kSim3ThetaSeriesTerms terms give at θ =
/// kSim3ThetaSeries (1.8e-18 for nominal moments g_k = 1/(k+1); the σ-dependence of the moments,
/// a factor ≤ e^{2|σ|}, is the same for both). Computed from the dropped terms' closed forms:
///   M = 4: θ < 6.4e-3,  5: 4.05e-2,  6: 0.127,  7: 0.279  (rounded down below).
/// Fewer terms and moments make the near-identity case (pose-graph residuals) about half as
/// expensive. tests/lie checks reduced series against the full one and the closed form.
inline constexpr double kSim3ThetaSeriesBound[kSim3ThetaSeriesTerms] = {
    0.0, 0.0, 0.0, 0.0, 6.4e-3, 4.0e-2, 0.125, 0.275};

/// M for θ (see kSim3ThetaSeriesBound): the smallest M ≥ 4 whose bound exceeds θ, else
/// kSim3ThetaSeriesTerms.
template <typename Scalar>
int sim3_theta_series_terms(Scalar theta) {
  for (int m = 4; m < kSim3ThetaSeriesTerms; ++m)
    if (theta < Scalar(kSim3ThetaSeriesBound[m])) return m;
  return kSim3ThetaSeriesTerms;
}

/// g_k(σ) = ∫₀¹ sᵏ e^{sσ} ds for k = 0..n (n ≤ kSim3MaxMoment), written to g[0..n].
/// |σ| ≤ kSim3SigmaSeries: power series Σ_j σʲ/(j!(n+j+1)) for g_n, then the downward
/// recurrence g_{k−1} = (e^σ − σ·g_k)/k (stable there). Otherwise the upward recurrence
/// g_k = (e^σ − k·g_{k−1})/σ from g_0 = (e^σ − 1)/σ.
template <typename Scalar>
void sigma_moments(Scalar sigma, int n, Scalar* g) {
  using std::abs;
  using std::exp;
  const Scalar es = exp(sigma);
  if (abs(sigma) <= kSim3SigmaSeries<Scalar>) {
    Scalar term = Scalar(1);  // σʲ/j!
    Scalar sum = Scalar(kInvInteger[n + 1]);
    for (int j = 1; j < kSim3SigmaSeriesMaxTerms; ++j) {
      term *= sigma * Scalar(kInvInteger[j]);
      const Scalar add = term * Scalar(kInvInteger[n + j + 1]);
      sum += add;
      if (abs(add) <= std::numeric_limits<Scalar>::epsilon() * Scalar(1e-2) * abs(sum)) break;
    }
    g[n] = sum;
    for (int k = n; k >= 1; --k) g[k - 1] = (es - sigma * g[k]) * Scalar(kInvInteger[k]);
  } else {
    const Scalar inv = Scalar(1) / sigma;
    g[0] = (es - Scalar(1)) * inv;
    for (int k = 1; k <= n; ++k) g[k] = (es - Scalar(k) * g[k - 1]) * inv;
  }
}

/// The θ² series of the coefficients (θ < kSim3ThetaSeries) with M terms (4 ≤ M ≤
/// kSim3ThetaSeriesTerms; sim3_coeffs picks M by sim3_theta_series_terms). Exposed so tests
/// can compare a reduced M with the full series.
template <typename Scalar>
VCoeffs<Scalar> sim3_coeffs_series(Scalar theta, Scalar sigma, int M, bool with_derivatives) {
  VCoeffs<Scalar> c;
  Scalar g[kSim3MaxMoment + 1];
  const int max_moment = 2 * M;
  sigma_moments(sigma, max_moment, g);
  c.c0 = g[0];
  c.c0s = g[1];
  const Scalar t2 = theta * theta;
  Scalar c1 = 0, c2 = 0, c1s = 0, c2s = 0, c1t = 0, c2t = 0;
  // p = (−1)^m θ^{2m}; term m of c1 / c1s: p·g_{2m+1}/(2m+1)!, p·g_{2m+2}/(2m+1)!.
  Scalar p = Scalar(1);
  for (int m = 0; m < M; ++m) {
    const Scalar f1 = Scalar(kInvFactorial[2 * m + 1]);
    c1 += p * g[2 * m + 1] * f1;
    c1s += p * g[2 * m + 2] * f1;  // 2m+2 ≤ 2M
    p *= -t2;
  }
  // Terms carrying θ^{2m−2} / θ^{2m−4}: powers are built by multiplication (never divided by
  // θ), so θ = 0 is exact.
  Scalar q = Scalar(1);   // (−1)^{m+1} θ^{2m−2} for m = 1
  Scalar r = Scalar(-1);  // (−1)^{m+1} θ^{2m−4} for m = 2
  for (int m = 1; m <= M; ++m) {
    const Scalar f2 = Scalar(kInvFactorial[2 * m]);
    c2 += q * g[2 * m] * f2;
    if (2 * m + 1 <= max_moment) {
      const Scalar f1 = Scalar(kInvFactorial[2 * m + 1]);
      c2s += q * g[2 * m + 1] * f2;
      // c1t term m: (−1)^m 2m θ^{2m−2} g_{2m+1}/(2m+1)! = −q·2m·g_{2m+1}·f1.
      c1t -= q * Scalar(2 * m) * g[2 * m + 1] * f1;
    }
    if (m >= 2) {
      c2t += r * Scalar(2 * m - 2) * g[2 * m] * f2;
      r *= -t2;
    }
    q *= -t2;
  }
  c.c1 = c1;
  c.c2 = c2;
  if (with_derivatives) {
    c.c1s = c1s;
    c.c2s = c2s;
    c.c1t = c1t;
    c.c2t = c2t;
  }
  return c;
}

/// Exact coefficients of C(ω, σ) and their derivatives (see the file comment).
/// @param theta |ω| ≥ 0.   @param sigma log scale.
/// @param with_derivatives also fill c0s..c2s, c1t, c2t (the left Jacobian needs them; exp and
///        log need only c0, c1, c2).
template <typename Scalar>
VCoeffs<Scalar> sim3_coeffs(Scalar theta, Scalar sigma, bool with_derivatives) {
  if (theta < kSim3ThetaSeries<Scalar>)
    return sim3_coeffs_series(theta, sigma, sim3_theta_series_terms(theta), with_derivatives);
  VCoeffs<Scalar> c;
  Scalar g[2];
  sigma_moments(sigma, 1, g);
  using Complex = std::complex<Scalar>;
  const Complex z(sigma, theta);
  const Complex ez = std::exp(z);
  const Complex phi = (ez - Scalar(1)) / z;
  const Scalar t2 = theta * theta;
  c.c0 = g[0];
  c.c1 = phi.imag() / theta;
  c.c2 = (g[0] - phi.real()) / t2;
  if (with_derivatives) {
    const Complex dphi = (ez * (z - Scalar(1)) + Scalar(1)) / (z * z);
    c.c0s = g[1];
    c.c1s = dphi.imag() / theta;
    c.c2s = (g[1] - dphi.real()) / t2;
    c.c1t = (dphi.real() - c.c1) / t2;
    c.c2t = (c.c1s - Scalar(2) * c.c2) / t2;
  }
  return c;
}

}  // namespace geodrift::lie::detail
