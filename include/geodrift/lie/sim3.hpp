#pragma once

/// @file
/// Sim(3), similarity transforms S = [s·R t; 0 1] acting on points as p' = s·R·p + t.
/// Tangent ξ = (ω, σ, ν) ∈ R⁷, σ = log s (DESIGN.md, the paper's order). All Jacobians are
/// w.r.t. LEFT perturbations S ← exp(δ)·S. The left Jacobian and its inverse are exact (no
/// first-order shortcut): see detail/sim3_details.hpp for the derivation.

#include <Eigen/Core>
#include <Eigen/LU>
#include <cmath>
#include <type_traits>

#include "geodrift/error.hpp"
#include "geodrift/lie/detail/sim3_avx2.hpp"
#include "geodrift/lie/detail/sim3_details.hpp"
#include "geodrift/lie/detail/so3_details.hpp"
#include "geodrift/lie/lie_group_base.hpp"
#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/so3.hpp"

namespace geodrift::lie {

/// Similarity transform S = [s·R t; 0 1] acting on points as p' = s·R·p + t.
/// Tangent ξ = (ω, σ, ν) ∈ R⁷, σ = log(s); offsets kOmega = 0, kSigma = 3, kNu = 4.
/// exp(ξ) = [e^σ·exp(ω)  C(ω,σ)·ν; 0 1] with C = ∫₀¹ e^{uσ} exp(u[ω]x) du.
/// All Jacobians are w.r.t. LEFT perturbations S ← exp(δ)·S.
template <typename Scalar>
class Sim3 : public LieGroupBase<Sim3<Scalar>> {
 public:
  static constexpr int kDoF = 7;
  static constexpr int kOmega = 0, kSigma = 3, kNu = 4;  ///< tangent block offsets
  static constexpr const char* kName = "Sim3";
  using Tangent = Eigen::Matrix<Scalar, kDoF, 1>;
  using Jacobian = Eigen::Matrix<Scalar, kDoF, kDoF>;
  using Point = Eigen::Matrix<Scalar, 3, 1>;
  using Matrix = Eigen::Matrix<Scalar, 4, 4>;
  using Mat3 = Eigen::Matrix<Scalar, 3, 3>;

  /// Identity.
  Sim3() = default;

  /// S = [scale·R t; 0 1].
  /// @throws InvalidArgument if scale ≤ 0 or t / scale is non-finite.
  Sim3(const SO3<Scalar>& R, const Point& t, Scalar scale) : R_(R), t_(t), s_(scale) {
    GEODRIFT_CHECK(t.allFinite(), "Sim3: translation " << t.transpose() << " is not finite");
    GEODRIFT_CHECK(std::isfinite(scale) && scale > Scalar(0),
                   "Sim3: scale " << scale << " is not a finite value > 0");
  }

  /// SE3 → Sim3 with scale 1.
  explicit Sim3(const SE3<Scalar>& T) : R_(T.rotation()), t_(T.translation()) {}

  /// Sim3 → SE3 as after pose-graph optimisation (Strasdat 2010, ORB-SLAM; DESIGN.md):
  /// [R | t/s]. For a world→camera S_cw this keeps the camera centre c = −(1/s)·Rᵀt and the
  /// orientation, and expresses the pose in the metric of the corrected map.
  SE3<Scalar> to_se3() const { return SE3<Scalar>(R_, t_ / s_); }

  /// exp: sim(3) → Sim(3).
  /// @param xi (ω, σ, ν).
  /// @param J_S_xi (7x7, optional) = left Jacobian Jl(ξ) (see left_jacobian()).
  /// @throws InvalidArgument if xi is non-finite.
  static Sim3 exp(const Tangent& xi, Jacobian* J_S_xi = nullptr) {
    using std::exp;
    GEODRIFT_CHECK(xi.allFinite(), "Sim3::exp: xi " << xi.transpose() << " is not finite");
    if (J_S_xi) {
      *J_S_xi = left_jacobian(xi);
      return Sim3(SO3<Scalar>::exp(xi.template segment<3>(kOmega)),
                  J_S_xi->template block<3, 3>(kNu, kNu) * xi.template segment<3>(kNu),
                  exp(xi[kSigma]), Raw{});
    }
    using std::sqrt;
    const Point omega = xi.template segment<3>(kOmega);
    const Scalar theta2 = omega.squaredNorm();
    const detail::VCoeffs<Scalar> c = detail::sim3_coeffs<Scalar>(sqrt(theta2), xi[kSigma], false);
    return Sim3(SO3<Scalar>::exp(omega),
                detail::w_polynomial_times(c.c0, c.c1, c.c2, omega, theta2,
                                           Point(xi.template segment<3>(kNu))),
                exp(xi[kSigma]), Raw{});
  }

  /// log: Sim(3) → sim(3), θ ∈ [0, π], σ = log s, ν = C(ω,σ)⁻¹·t.
  /// @param J_xi_S (7x7, optional) = Jl⁻¹(log S): d(log S)/dδ for S ← exp(δ)·S. The
  ///        coefficients of C and their derivatives are evaluated once and shared by ν and the
  ///        Jacobian (same values as left_jacobian_inverse(log S)).
  Tangent log(Jacobian* J_xi_S = nullptr) const {
    using std::log;
    using std::sqrt;
    const Point omega = R_.log();
    const Scalar sigma = log(s_);
    const Scalar theta2 = omega.squaredNorm();
    const Scalar theta = sqrt(theta2);
    const detail::VCoeffs<Scalar> c = detail::sim3_coeffs<Scalar>(theta, sigma, J_xi_S != nullptr);
    const InverseCoeffs a = v_inverse_coeffs(c, theta2);
    // Segment assignment: see SE3::log (GCC 12 false -Warray-bounds with float).
    Tangent xi;
    xi.template segment<3>(kOmega) = omega;
    xi[kSigma] = sigma;
    xi.template segment<3>(kNu) = detail::w_polynomial_times(a.a0, a.a1, a.a2, omega, theta2, t_);
    if (J_xi_S) inverse_blocks(omega, theta, theta2, xi.template segment<3>(kNu), t_, c, a, J_xi_S);
    return xi;
  }

  /// S⁻¹ = [Rᵀ/s  −Rᵀt/s; 0 1].  @param J_inv_S (7x7, optional) = −Ad(S⁻¹).
  Sim3 inverse(Jacobian* J_inv_S = nullptr) const {
    const SO3<Scalar> Rinv = R_.inverse();
    const Scalar sinv = Scalar(1) / s_;
    const Sim3 inv(Rinv, -sinv * Rinv.act(t_), sinv, Raw{});
    if (J_inv_S) *J_inv_S = -inv.adjoint();
    return inv;
  }

  /// Composition a·b = [R_a R_b, s_a R_a t_b + t_a, s_a s_b].
  Sim3 operator*(const Sim3& b) const {
    return Sim3(R_ * b.R_, s_ * R_.act(b.t_) + t_, s_ * b.s_, Raw{});
  }

  /// a·b⁻¹ = [R_a·R_bᵀ, t_a − s·(R_a·R_bᵀ)·t_b, s = s_a/s_b]: one rotation of a point instead
  /// of the two of (*this) * b.inverse() (equal to rounding).
  Sim3 times_inverse(const Sim3& b) const {
    const SO3<Scalar> R = R_ * b.R_.inverse();
    const Scalar s = s_ / b.s_;
    return Sim3(R, t_ - s * R.act(b.t_), s, Raw{});
  }

  /// Composition a·b with Jacobians w.r.t. left perturbations of a and b.
  /// @param J_ab_a (7x7, optional) = I.   @param J_ab_b (7x7, optional) = Ad(a).
  Sim3 compose(const Sim3& b, Jacobian* J_ab_a = nullptr, Jacobian* J_ab_b = nullptr) const {
    if (J_ab_a) J_ab_a->setIdentity();
    if (J_ab_b) *J_ab_b = adjoint();
    return *this * b;
  }

  /// p' = s·R·p + t.
  /// @param J_p_S (3x7, optional) = [ −[p']x | p' | I ] in (ω, σ, ν) order.
  /// @param J_p_p (3x3, optional) = s·R.
  Point act(const Point& p, Eigen::Matrix<Scalar, 3, kDoF>* J_p_S = nullptr,
            Eigen::Matrix<Scalar, 3, 3>* J_p_p = nullptr) const {
    const Point q = s_ * R_.act(p) + t_;
    if (J_p_S) *J_p_S << -skew<Scalar>(q), q, Eigen::Matrix<Scalar, 3, 3>::Identity();
    if (J_p_p) *J_p_p = s_ * R_.matrix();
    return q;
  }

  /// Ad(S) with S·exp(d)·S⁻¹ = exp(Ad(S)·d); rows/cols (ω, σ, ν):
  ///   [ R       0    0   ]
  ///   [ 0       1    0   ]
  ///   [ [t]x·R  −t   s·R ]
  Jacobian adjoint() const {
    const Eigen::Matrix<Scalar, 3, 3> R = R_.matrix();
    Jacobian A = Jacobian::Zero();
    A.template block<3, 3>(kOmega, kOmega) = R;
    A(kSigma, kSigma) = Scalar(1);
    A.template block<3, 3>(kNu, kOmega) = skew<Scalar>(t_) * R;
    A.template block<3, 1>(kNu, kSigma) = -t_;
    A.template block<3, 3>(kNu, kNu) = s_ * R;
    return A;
  }

  /// M·Ad(S) for any 7x7 M without forming Ad(S) (a residual's Jacobian through a composition):
  /// with M = [M_ω M_σ M_ν] by column blocks,
  ///   M·Ad(S) = [ (M_ω + M_ν·[t]x)·R   M_σ − M_ν·t   s·M_ν·R ]
  /// (210 multiply-adds instead of 343; equals M * adjoint() to rounding).
  Jacobian times_adjoint(const Jacobian& M) const { return times_adjoint(M, R_.matrix()); }
  /// times_adjoint(M) with R = rotation().matrix() from the caller (several products with one
  /// S: the pose-graph accumulation converts the quaternion once).
  Jacobian times_adjoint(const Jacobian& M, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    Jacobian out;
    times_adjoint_into(M, R, &out);
    return out;
  }
  /// *out = M·Ad(S) (out must not alias M), with R = rotation().matrix(): written in place, no
  /// copy of a returned 7×7 (a residual's Jacobian output; GCC copies 392-byte results with
  /// `rep movsq`, which stalls behind the kernel's vector stores).
  void times_adjoint_into(const Jacobian& M, const Eigen::Matrix<Scalar, 3, 3>& R,
                          Jacobian* out) const {
#ifdef GEODRIFT_AVX2_KERNELS
    if constexpr (std::is_same_v<Scalar, double>) {
      if (::geodrift::detail::avx2_fma_enabled()) {  // the same products, 4-wide with FMA
        detail::sim3_times_adjoint_avx2(M.data(), R.data(), t_.data(), s_, out->data());
        return;
      }
    }
#endif
    const auto Mw = M.template leftCols<3>();
    const auto Mn = M.template rightCols<3>();
    const Eigen::Matrix<Scalar, kDoF, 3> MnR = Mn * R;
    // [t]x·R = t × (columns of R); M_ν·[t]x·R = M_ν·(t × R).
    Eigen::Matrix<Scalar, 3, 3> tR;
    for (int k = 0; k < 3; ++k) tR.col(k) = t_.cross(R.col(k));
    out->template leftCols<3>().noalias() = Mw * R;
    out->template leftCols<3>().noalias() += Mn * tR;
    out->col(kSigma) = M.col(kSigma);
    out->col(kSigma).noalias() -= Mn * t_;
    out->template rightCols<3>() = s_ * MnR;
  }

  /// Ad(S)·d for any d without forming Ad(S) (a tangent moved across S):
  ///   Ad(S)·d = [ R·d_ω ;  d_σ ;  t × (R·d_ω) − d_σ·t + s·R·d_ν ]   (equals adjoint() * d to
  ///   rounding).
  Tangent adjoint_times(const Tangent& d) const { return adjoint_times(d, R_.matrix()); }
  /// adjoint_times(d) with R = rotation().matrix() from the caller.
  Tangent adjoint_times(const Tangent& d, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    const Point w = R * d.template segment<3>(kOmega);
    Tangent out;
    out.template segment<3>(kOmega) = w;
    out[kSigma] = d[kSigma];
    out.template segment<3>(kNu) =
        t_.cross(w) - d[kSigma] * t_ + s_ * (R * d.template segment<3>(kNu));
    return out;
  }

  /// Ad(S)ᵀ·u for any u without forming Ad(S) (a gradient through a composition):
  ///   Ad(S)ᵀ·u = [ Rᵀ·(u_ω − t × u_ν) ;  u_σ − t·u_ν ;  s·Rᵀ·u_ν ]
  /// (equals adjoint().transpose() * u to rounding).
  Tangent adjoint_transpose_times(const Tangent& u) const {
    return adjoint_transpose_times(u, R_.matrix());
  }
  /// adjoint_transpose_times(u) with R = rotation().matrix() from the caller.
  Tangent adjoint_transpose_times(const Tangent& u, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    const Point un = u.template segment<3>(kNu);
    Tangent out;
    out.template segment<3>(kOmega).noalias() =
        R.transpose() * (u.template segment<3>(kOmega) - t_.cross(un));
    out(kSigma) = u(kSigma) - t_.dot(un);
    out.template segment<3>(kNu).noalias() = s_ * (R.transpose() * un);
    return out;
  }

  /// Exact left Jacobian Jl(ξ) = Σ_k ad_ξᵏ/(k+1)!, exp(ξ + dξ) = exp(Jl·dξ)·exp(ξ); rows/cols
  /// (ω, σ, ν):
  ///   [ J   0   0 ]     J = Jl_SO3(ω),  C = c0·I + c1·W + c2·W²  (W = [ω]x),
  ///   [ 0   1   0 ]     A = ∂(Cν)/∂ω + [Cν]x·J,
  ///   [ A   b   C ]     b = ∂(Cν)/∂σ − Cν,
  /// with the coupled (θ, σ) coefficients and their exact derivatives from
  /// detail::sim3_coeffs (closed forms; series near θ = 0, σ = 0 and both).
  static Jacobian left_jacobian(const Tangent& xi) {
    Jacobian Jl;
    blocks(xi, &Jl, nullptr);
    return Jl;
  }

  /// Exact inverse of left_jacobian(ξ) by block inversion of its lower-triangular form:
  ///   [ J⁻¹          0       0   ]
  ///   [ 0            1       0   ]
  ///   [ −C⁻¹·A·J⁻¹   −C⁻¹·b  C⁻¹ ]    (J⁻¹ and C⁻¹ in closed form, v_inverse_coeffs()).
  static Jacobian left_jacobian_inverse(const Tangent& xi) {
    Jacobian Jli;
    blocks(xi, nullptr, &Jli);
    return Jli;
  }

  /// The 4x4 matrix [s·R t; 0 1].
  Matrix matrix() const {
    Matrix M = Matrix::Identity();
    M.template topLeftCorner<3, 3>() = s_ * R_.matrix();
    M.template topRightCorner<3, 1>() = t_;
    return M;
  }
  /// Rotation part R.
  const SO3<Scalar>& rotation() const { return R_; }
  /// Translation part t.
  const Point& translation() const { return t_; }
  /// Scale s = e^σ > 0.
  Scalar scale() const { return s_; }

  /// Same transform in another scalar type.
  template <typename T>
  Sim3<T> cast() const {
    return Sim3<T>(R_.template cast<T>(), t_.template cast<T>(), static_cast<T>(s_));
  }

  /// True when rotations agree to tol (rad), |log s − log s_other| ≤ tol and
  /// |t − t_other| ≤ tol·max(1, |t|, |t_other|).
  bool is_approx(const Sim3& other,
                 Scalar tol = Eigen::NumTraits<Scalar>::dummy_precision()) const {
    using std::abs;
    using std::log;
    using std::max;
    const Scalar mag = max(Scalar(1), max(t_.norm(), other.t_.norm()));
    return R_.is_approx(other.R_, tol) && abs(log(s_ / other.s_)) <= tol &&
           (t_ - other.t_).norm() <= tol * mag;
  }

 private:
  struct Raw {};  // internal: inputs known valid
  Sim3(const SO3<Scalar>& R, const Point& t, Scalar s, Raw) : R_(R), t_(t), s_(s) {}

  // C⁻¹ = a0·I + a1·W + a2·W²: polynomials in W are closed under inversion (W³ = −θ²·W), and
  // matching the I, W, W² terms of C·C⁻¹ = I gives
  //   a0 = 1/c0,  a1 = −c1/Δ,  a2 = (c1² − c2·d)/(c0·Δ),  d = c0 − θ²·c2,  Δ = d² + θ²·c1²
  // (d ± iθ·c1 are C's eigenvalues on the plane ⟂ ω, so Δ > 0 whenever C is invertible).
  // A handful of scalar operations instead of a 3×3 cofactor inverse.
  struct InverseCoeffs {
    Scalar a0, a1, a2;
  };
  static InverseCoeffs v_inverse_coeffs(const detail::VCoeffs<Scalar>& c, Scalar theta2) {
    const Scalar a0 = Scalar(1) / c.c0;
    const Scalar d = c.c0 - theta2 * c.c2;
    const Scalar inv_delta = Scalar(1) / (d * d + theta2 * c.c1 * c.c1);
    return {a0, -c.c1 * inv_delta, (c.c1 * c.c1 - c.c2 * d) * a0 * inv_delta};
  }

  // Jl⁻¹(ξ) for ξ = (ω, σ, ν), from what log() has anyway: θ, θ², t = C·ν, the coefficients c
  // (with derivatives) and those of C⁻¹. Block inversion of left_jacobian()'s lower-triangular
  // form, where the translation row A = D + [t]x·J (D = ∂(Cν)/∂ω, see
  // detail::translation_rows) enters only as A·J⁻¹ = D·J⁻¹ + [t]x: neither J nor A is formed.
  // In D = (c1t·Wν + c2t·W²ν − 2c2·ν)ωᵀ − c1·[ν]x + c2·((ωᵀν)I + ωνᵀ) the rank-one part passes
  // J⁻¹ unchanged (ωᵀW = 0, so ωᵀ·J⁻¹ = ωᵀ). Polynomials in W are formed from W² = ωωᵀ − θ²I
  // and the two remaining 3×3 products are written out (detail::mul3).
  static void inverse_blocks(const Point& omega, Scalar theta, Scalar theta2, const Point& nu,
                             const Point& t, const detail::VCoeffs<Scalar>& c,
                             const InverseCoeffs& a, Jacobian* Jli) {
    const Mat3 Ji =
        detail::w_polynomial(Scalar(1), Scalar(-0.5),
                             detail::so3_left_jacobian_inverse_d2<Scalar>(theta), omega, theta2);
    const Scalar wn = omega.dot(nu);
    const Point Wnu = omega.cross(nu);
    const Point W2nu = wn * omega - theta2 * nu;
    // P = c2·ωνᵀ − c1·[ν]x + c2·(ωᵀν)·I
    Mat3 P = (c.c2 * omega) * nu.transpose();
    const Scalar pd = c.c2 * wn;
    P(0, 0) += pd;
    P(1, 1) += pd;
    P(2, 2) += pd;
    detail::add_skew(&P, -c.c1, nu);
    // A·J⁻¹ = [t]x + P·J⁻¹ + u·ωᵀ,  u = c1t·Wν + c2t·W²ν − 2c2·ν
    Mat3 AJi = detail::mul3(P, Ji);
    const Point u = c.c1t * Wnu + c.c2t * W2nu - Scalar(2) * c.c2 * nu;
    AJi.noalias() += u * omega.transpose();
    detail::add_skew(&AJi, Scalar(1), t);
    const Point b = c.c0s * nu + c.c1s * Wnu + c.c2s * W2nu - t;
    const Mat3 Ci = detail::w_polynomial(a.a0, a.a1, a.a2, omega, theta2);
    Jli->setZero();
    Jli->template block<3, 3>(kOmega, kOmega) = Ji;
    (*Jli)(kSigma, kSigma) = Scalar(1);
    Jli->template block<3, 3>(kNu, kOmega) = -detail::mul3(Ci, AJi);
    Jli->template block<3, 1>(kNu, kSigma) =
        -detail::w_polynomial_times(a.a0, a.a1, a.a2, omega, theta2, b);
    Jli->template block<3, 3>(kNu, kNu) = Ci;
  }

  // Fills Jl and/or Jl⁻¹ (either may be null) from one evaluation of the coefficients.
  static void blocks(const Tangent& xi, Jacobian* Jl, Jacobian* Jli) {
    const Point omega = xi.template segment<3>(kOmega);
    const Point nu = xi.template segment<3>(kNu);
    const Scalar theta = omega.norm();
    const detail::VCoeffs<Scalar> c = detail::sim3_coeffs<Scalar>(theta, xi[kSigma], true);
    if (Jl) {
      const Mat3 J = detail::so3_left_jacobian<Scalar>(omega);
      Mat3 A;
      Point b;
      const Mat3 C = detail::translation_rows<Scalar>(omega, nu, c, J, &A, &b);
      Jl->setZero();
      Jl->template block<3, 3>(kOmega, kOmega) = J;
      (*Jl)(kSigma, kSigma) = Scalar(1);
      Jl->template block<3, 3>(kNu, kOmega) = A;
      Jl->template block<3, 1>(kNu, kSigma) = b;
      Jl->template block<3, 3>(kNu, kNu) = C;
    }
    if (Jli) {
      const Scalar theta2 = omega.squaredNorm();
      const Point t = detail::w_polynomial_times(c.c0, c.c1, c.c2, omega, theta2, nu);
      inverse_blocks(omega, theta, theta2, nu, t, c, v_inverse_coeffs(c, theta2), Jli);
    }
  }

  SO3<Scalar> R_;
  Point t_ = Point::Zero();
  Scalar s_ = Scalar(1);
};

using Sim3d = Sim3<double>;
using Sim3f = Sim3<float>;

}  // namespace geodrift::lie
