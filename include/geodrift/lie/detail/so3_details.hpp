#pragma once

/// @file
/// Implementation details of SO3 / SE3 (and the parts Sim3 shares): closed forms with their
/// Taylor branches. Nothing outside include/geodrift/lie names this namespace.
///
/// Notation: ω ∈ R³, θ = |ω|, W = [ω]x. The SO3 left Jacobian is
///   Jl(ω) = I + c1(θ)·W + c2(θ)·W²,  c1 = (1 − cosθ)/θ²,  c2 = (θ − sinθ)/θ³,
/// and the "V matrix" of SE3 (t = V·ν in exp) is the same matrix. Sim3 generalises it to
/// C(ω, σ) = c0(σ)·I + c1(θ,σ)·W + c2(θ,σ)·W² (sim3_details.hpp).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "geodrift/lie/constants.hpp"

namespace geodrift::lie::detail {

template <typename Scalar>
using Vec3 = Eigen::Matrix<Scalar, 3, 1>;
template <typename Scalar>
using Mat3 = Eigen::Matrix<Scalar, 3, 3>;

/// [v]x, the 3x3 skew matrix with [v]x·p = v × p.
template <typename Scalar>
Mat3<Scalar> skew(const Vec3<Scalar>& v) {
  Mat3<Scalar> m;
  m << Scalar(0), -v.z(), v.y(), v.z(), Scalar(0), -v.x(), -v.y(), v.x(), Scalar(0);
  return m;
}

/// M += k·[v]x, entry by entry (no skew matrix formed).
template <typename Scalar>
void add_skew(Mat3<Scalar>* M, Scalar k, const Vec3<Scalar>& v) {
  const Scalar x = k * v[0], y = k * v[1], z = k * v[2];
  (*M)(0, 1) -= z;
  (*M)(1, 0) += z;
  (*M)(0, 2) += y;
  (*M)(2, 0) -= y;
  (*M)(1, 2) -= x;
  (*M)(2, 1) += x;
}

/// A·B for 3×3 matrices, written out: Eigen's fixed-size product and its assignment were two
/// out-of-line calls at -O2 in the Sim(3) log path (≈ 5 % of a pose-graph linearisation).
template <typename Scalar>
Mat3<Scalar> mul3(const Mat3<Scalar>& A, const Mat3<Scalar>& B) {
  Mat3<Scalar> C;
#pragma GCC unroll 3
  for (int j = 0; j < 3; ++j) {
    const Scalar b0 = B(0, j), b1 = B(1, j), b2 = B(2, j);
    C(0, j) = A(0, 0) * b0 + A(0, 1) * b1 + A(0, 2) * b2;
    C(1, j) = A(1, 0) * b0 + A(1, 1) * b1 + A(1, 2) * b2;
    C(2, j) = A(2, 0) * b0 + A(2, 1) * b1 + A(2, 2) * b2;
  }
  return C;
}

/// The polynomial k0·I + k1·W + k2·W² in W = [ω]x as a matrix, from W² = ωωᵀ − θ²·I
/// (theta2 = θ² = |ω|²): no 3×3 product.
template <typename Scalar>
Mat3<Scalar> w_polynomial(Scalar k0, Scalar k1, Scalar k2, const Vec3<Scalar>& omega,
                          Scalar theta2) {
  const Scalar d = k0 - k2 * theta2;
  const Scalar x = omega[0], y = omega[1], z = omega[2];
  const Scalar kx = k2 * x, ky = k2 * y, kz = k2 * z;
  Mat3<Scalar> m;
  m(0, 0) = d + kx * x;
  m(1, 1) = d + ky * y;
  m(2, 2) = d + kz * z;
  m(0, 1) = kx * y - k1 * z;
  m(1, 0) = kx * y + k1 * z;
  m(0, 2) = kx * z + k1 * y;
  m(2, 0) = kx * z - k1 * y;
  m(1, 2) = ky * z - k1 * x;
  m(2, 1) = ky * z + k1 * x;
  return m;
}

/// (k0·I + k1·W + k2·W²)·v = (k0 − k2·θ²)·v + k1·(ω × v) + k2·(ωᵀv)·ω.
template <typename Scalar>
Vec3<Scalar> w_polynomial_times(Scalar k0, Scalar k1, Scalar k2, const Vec3<Scalar>& omega,
                                Scalar theta2, const Vec3<Scalar>& v) {
  return (k0 - k2 * theta2) * v + k1 * omega.cross(v) + (k2 * omega.dot(v)) * omega;
}

/// Unit quaternion exp(ω) = (cos(θ/2), sin(θ/2)/θ · ω).
template <typename Scalar>
Eigen::Quaternion<Scalar> quaternion_exp(const Vec3<Scalar>& omega) {
  using std::cos;
  using std::sin;
  using std::sqrt;
  const Scalar theta2 = omega.squaredNorm();
  const Scalar theta = sqrt(theta2);
  Scalar w, k;  // k = sin(θ/2)/θ
  if (theta < kSmallAngle<Scalar>) {
    // Taylor to θ⁴: the dropped θ⁶ term is < 1e-17 at θ = 1e-2.
    w = Scalar(1) - theta2 / Scalar(8) + theta2 * theta2 / Scalar(384);
    k = Scalar(0.5) - theta2 / Scalar(48) + theta2 * theta2 / Scalar(3840);
  } else {
    w = cos(theta / Scalar(2));
    k = sin(theta / Scalar(2)) / theta;
  }
  Eigen::Quaternion<Scalar> q(w, k * omega.x(), k * omega.y(), k * omega.z());
  q.normalize();
  return q;
}

/// log of a unit quaternion, θ ∈ [0, π]. Uses θ = 2·atan2(|v|, |w|) (sign of q fixed so w ≥ 0),
/// which stays accurate near θ = π where acos-based formulas lose half the digits.
template <typename Scalar>
Vec3<Scalar> quaternion_log(const Eigen::Quaternion<Scalar>& q_in) {
  using std::atan2;
  using std::sqrt;
  const Scalar sign = q_in.w() < Scalar(0) ? Scalar(-1) : Scalar(1);
  const Scalar w = sign * q_in.w();
  const Vec3<Scalar> v = sign * q_in.vec();
  const Scalar n2 = v.squaredNorm();
  const Scalar n = sqrt(n2);
  Scalar k;  // θ / |v|
  if (n < kSmallAngle<Scalar> * w) {
    // θ/|v| = 2·atan(x)/n with x = n/w < 1e-2: 2/w·(1 − x²/3 + x⁴/5 − x⁶/7); the first dropped
    // term x⁸/9 is < 1e-17 relative.
    const Scalar x2 = n2 / (w * w);
    k = Scalar(2) / w *
        (Scalar(1) - x2 / Scalar(3) + x2 * x2 / Scalar(5) - x2 * x2 * x2 / Scalar(7));
  } else {
    k = Scalar(2) * atan2(n, w) / n;
  }
  return k * v;
}

/// Coefficients of C = c0·I + c1·W + c2·W² and their derivatives, used to build left Jacobians.
///   c0s, c1s, c2s = ∂/∂σ;   c1t, c2t = (∂/∂θ)/θ   (c0 does not depend on θ).
template <typename Scalar>
struct VCoeffs {
  Scalar c0 = Scalar(1), c1 = Scalar(0.5), c2 = Scalar(1) / Scalar(6);
  Scalar c0s = Scalar(0), c1s = Scalar(0), c2s = Scalar(0);
  Scalar c1t = Scalar(0), c2t = Scalar(0);
};

/// σ = 0 (SO3 / SE3) coefficients: c1 = (1−cosθ)/θ², c2 = (θ−sinθ)/θ³ and (dc/dθ)/θ.
/// @param with_derivatives compute c1t, c2t as well (needed by the SE3 left Jacobian only).
template <typename Scalar>
VCoeffs<Scalar> se3_coeffs(Scalar theta, bool with_derivatives) {
  using std::cos;
  using std::sin;
  VCoeffs<Scalar> c;
  const Scalar t2 = theta * theta;
  if (theta < kSmallAngle<Scalar>) {
    // c1 = Σ (−1)^m θ^{2m}/(2m+2)!,  c2 = Σ (−1)^m θ^{2m}/(2m+3)!  (terms to θ⁶).
    c.c1 = Scalar(0.5) - t2 / Scalar(24) + t2 * t2 / Scalar(720) - t2 * t2 * t2 / Scalar(40320);
    c.c2 = Scalar(1) / Scalar(6) - t2 / Scalar(120) + t2 * t2 / Scalar(5040) -
           t2 * t2 * t2 / Scalar(362880);
    if (with_derivatives) {
      c.c1t = -Scalar(1) / Scalar(12) + t2 / Scalar(180) - t2 * t2 / Scalar(6720);
      c.c2t = -Scalar(1) / Scalar(60) + t2 / Scalar(1260) - t2 * t2 / Scalar(60480);
    }
  } else {
    const Scalar s = sin(theta), co = cos(theta);
    const Scalar one_m_cos = Scalar(1) - co, t_m_sin = theta - s;
    c.c1 = one_m_cos / t2;
    c.c2 = t_m_sin / (t2 * theta);
    if (with_derivatives) {
      c.c1t = (theta * s - Scalar(2) * one_m_cos) / (t2 * t2);
      c.c2t = (theta * one_m_cos - Scalar(3) * t_m_sin) / (t2 * t2 * theta);
    }
  }
  return c;
}

/// SO3 left Jacobian Jl(ω) = I + c1·W + c2·W² (exact; Taylor below kSmallAngle).
template <typename Scalar>
Mat3<Scalar> so3_left_jacobian(const Vec3<Scalar>& omega) {
  const VCoeffs<Scalar> c = se3_coeffs<Scalar>(omega.norm(), false);
  const Mat3<Scalar> W = skew<Scalar>(omega);
  return Mat3<Scalar>::Identity() + c.c1 * W + c.c2 * (W * W);
}

/// d2(θ) = (1 − (θ/2)·cot(θ/2))/θ², the W² coefficient of the SO3 inverse left Jacobian below.
template <typename Scalar>
Scalar so3_left_jacobian_inverse_d2(Scalar theta) {
  using std::cos;
  using std::sin;
  const Scalar t2 = theta * theta;
  if (theta < kSmallAngle<Scalar>)
    return Scalar(1) / Scalar(12) + t2 / Scalar(720) + t2 * t2 / Scalar(30240);
  const Scalar h = theta / Scalar(2);
  return (Scalar(1) - h * cos(h) / sin(h)) / t2;
}

/// SO3 inverse left Jacobian Jl⁻¹(ω) = I − W/2 + d2·W², d2 = (1 − (θ/2)·cot(θ/2))/θ².
/// cot(θ/2) replaces (1+cosθ)/sinθ so the formula stays finite and accurate up to θ = π.
template <typename Scalar>
Mat3<Scalar> so3_left_jacobian_inverse(const Vec3<Scalar>& omega) {
  const Scalar d2 = so3_left_jacobian_inverse_d2(omega.norm());
  const Mat3<Scalar> W = skew<Scalar>(omega);
  return Mat3<Scalar>::Identity() - Scalar(0.5) * W + d2 * (W * W);
}

/// The translation/σ row blocks of the SE3/Sim3 left Jacobian.
///
/// With exp(ω, σ, ν) = (R = exp(ω), s = e^σ, t = C(ω,σ)·ν) and the left perturbation
/// exp(ξ + dξ) = exp(Jl·dξ)·exp(ξ), the translation row of Jl is
///   δν = C·dν + A·dω + b·dσ,   A = ∂(Cν)/∂ω + [t]x·Jl_so3(ω),   b = ∂(Cν)/∂σ − t,
/// because exp(δ)·X moves t by δν + [δω]x·t + δσ·t to first order. With C = c0 I + c1 W + c2 W²:
///   ∂(Cν)/∂ω = c1t·(Wν)ωᵀ + c2t·(W²ν)ωᵀ − c1·[ν]x + c2·((ωᵀν)I + ωνᵀ − 2νωᵀ).
/// @param A   3x3 output, d(δν)/dω.
/// @param b   3x1 output, d(δν)/dσ (Sim3 only; may be nullptr).
/// @return    C (3x3), the ν→δν block.
template <typename Scalar>
Mat3<Scalar> translation_rows(const Vec3<Scalar>& omega, const Vec3<Scalar>& nu,
                              const VCoeffs<Scalar>& c, const Mat3<Scalar>& Jl_omega,
                              Mat3<Scalar>* A, Vec3<Scalar>* b) {
  const Mat3<Scalar> W = skew<Scalar>(omega);
  const Mat3<Scalar> W2 = W * W;
  const Mat3<Scalar> C = c.c0 * Mat3<Scalar>::Identity() + c.c1 * W + c.c2 * W2;
  const Vec3<Scalar> t = C * nu;
  const Vec3<Scalar> Wnu = W * nu;
  const Vec3<Scalar> W2nu = W * Wnu;
  *A = (c.c1t * Wnu + c.c2t * W2nu) * omega.transpose() - c.c1 * skew<Scalar>(nu) +
       c.c2 * (omega.dot(nu) * Mat3<Scalar>::Identity() + omega * nu.transpose() -
               Scalar(2) * nu * omega.transpose()) +
       skew<Scalar>(t) * Jl_omega;
  if (b) *b = c.c0s * nu + c.c1s * Wnu + c.c2s * W2nu - t;
  return C;
}

}  // namespace geodrift::lie::detail
