#pragma once

/// @file
/// SE(3), rigid transforms T = [R t; 0 1] acting on points as p' = R·p + t.
/// Tangent ξ = (ω, ν) ∈ R⁶ (DESIGN.md order: rotation first). All Jacobians are w.r.t. LEFT
/// perturbations T ← exp(δ)·T.

#include <Eigen/Core>

#include "geodrift/error.hpp"
#include "geodrift/lie/detail/so3_details.hpp"
#include "geodrift/lie/lie_group_base.hpp"
#include "geodrift/lie/so3.hpp"

namespace geodrift::lie {

/// Rigid transform T = [R t; 0 1], p' = R·p + t. Tangent ξ = (ω, ν), kOmega = 0, kNu = 3;
/// exp(ξ) = [exp(ω)  V(ω)·ν; 0 1] with V = Jl_SO3(ω).
/// All Jacobians are w.r.t. LEFT perturbations T ← exp(δ)·T.
template <typename Scalar>
class SE3 : public LieGroupBase<SE3<Scalar>> {
 public:
  static constexpr int kDoF = 6;
  static constexpr int kOmega = 0;  ///< tangent block offset of ω (rotation)
  static constexpr int kNu = 3;     ///< tangent block offset of ν (translation)
  static constexpr const char* kName = "SE3";
  using Tangent = Eigen::Matrix<Scalar, 6, 1>;
  using Jacobian = Eigen::Matrix<Scalar, 6, 6>;
  using Point = Eigen::Matrix<Scalar, 3, 1>;
  using Matrix = Eigen::Matrix<Scalar, 4, 4>;

  /// Identity.
  SE3() = default;

  /// T = [R t; 0 1].
  /// @throws InvalidArgument if t is non-finite.
  SE3(const SO3<Scalar>& R, const Point& t) : R_(R), t_(t) {
    GEODRIFT_CHECK(t.allFinite(), "SE3: translation " << t.transpose() << " is not finite");
  }

  /// exp: se(3) → SE(3).
  /// @param xi (ω, ν).
  /// @param J_T_xi (6x6, optional) = left Jacobian Jl(ξ) (see left_jacobian()).
  /// @throws InvalidArgument if xi is non-finite.
  static SE3 exp(const Tangent& xi, Jacobian* J_T_xi = nullptr) {
    GEODRIFT_CHECK(xi.allFinite(), "SE3::exp: xi " << xi.transpose() << " is not finite");
    const Point omega = xi.template segment<3>(kOmega);
    const Point nu = xi.template segment<3>(kNu);
    if (J_T_xi) {
      *J_T_xi = left_jacobian(xi);
      return SE3(SO3<Scalar>::exp(omega), J_T_xi->template block<3, 3>(kNu, kNu) * nu, Raw{});
    }
    return SE3(SO3<Scalar>::exp(omega), detail::so3_left_jacobian<Scalar>(omega) * nu, Raw{});
  }

  /// log: SE(3) → se(3), θ ∈ [0, π].
  /// @param J_xi_T (6x6, optional) = Jl⁻¹(log T): d(log T)/dδ for T ← exp(δ)·T.
  Tangent log(Jacobian* J_xi_T = nullptr) const {
    const Point omega = R_.log();
    const Eigen::Matrix<Scalar, 3, 3> Vinv = detail::so3_left_jacobian_inverse<Scalar>(omega);
    // Segment assignment rather than `xi << omega, ...`: GCC 12 reports a false -Warray-bounds
    // on Eigen's packet copy of a Vector3f inside a comma initialiser.
    Tangent xi;
    xi.template segment<3>(kOmega) = omega;
    xi.template segment<3>(kNu) = Vinv * t_;
    if (J_xi_T) *J_xi_T = left_jacobian_inverse(xi);
    return xi;
  }

  /// T⁻¹ = [Rᵀ −Rᵀt; 0 1].  @param J_inv_T (6x6, optional) = −Ad(T⁻¹).
  SE3 inverse(Jacobian* J_inv_T = nullptr) const {
    const SO3<Scalar> Rinv = R_.inverse();
    const SE3 inv(Rinv, -(Rinv.act(t_)), Raw{});
    if (J_inv_T) *J_inv_T = -inv.adjoint();
    return inv;
  }

  /// Composition a·b = [R_a R_b, R_a t_b + t_a].
  SE3 operator*(const SE3& b) const { return SE3(R_ * b.R_, R_.act(b.t_) + t_, Raw{}); }

  /// a·b⁻¹ = [R_a·R_bᵀ, t_a − (R_a·R_bᵀ)·t_b]: one rotation of a point instead of the two of
  /// (*this) * b.inverse() (equal to rounding).
  SE3 times_inverse(const SE3& b) const {
    const SO3<Scalar> R = R_ * b.R_.inverse();
    return SE3(R, t_ - R.act(b.t_), Raw{});
  }

  /// Composition a·b with Jacobians w.r.t. left perturbations of a and b.
  /// @param J_ab_a (6x6, optional) = I.   @param J_ab_b (6x6, optional) = Ad(a).
  SE3 compose(const SE3& b, Jacobian* J_ab_a = nullptr, Jacobian* J_ab_b = nullptr) const {
    if (J_ab_a) J_ab_a->setIdentity();
    if (J_ab_b) *J_ab_b = adjoint();
    return *this * b;
  }

  /// p' = R·p + t.
  /// @param J_p_T (3x6, optional) = [ −[p']x | I ] in (ω, ν) order.
  /// @param J_p_p (3x3, optional) = R.
  Point act(const Point& p, Eigen::Matrix<Scalar, 3, kDoF>* J_p_T = nullptr,
            Eigen::Matrix<Scalar, 3, 3>* J_p_p = nullptr) const {
    const Point q = R_.act(p) + t_;
    if (J_p_T) *J_p_T << -skew<Scalar>(q), Eigen::Matrix<Scalar, 3, 3>::Identity();
    if (J_p_p) *J_p_p = R_.matrix();
    return q;
  }

  /// Ad(T) with T·exp(d)·T⁻¹ = exp(Ad(T)·d); rows/cols (ω, ν):
  ///   [ R       0 ]
  ///   [ [t]x·R  R ]
  Jacobian adjoint() const {
    const Eigen::Matrix<Scalar, 3, 3> R = R_.matrix();
    Jacobian A;
    A << R, Eigen::Matrix<Scalar, 3, 3>::Zero(), skew<Scalar>(t_) * R, R;
    return A;
  }

  /// M·Ad(T) for any 6x6 M without forming Ad(T): with M = [M_ω M_ν] by column blocks,
  ///   M·Ad(T) = [ (M_ω + M_ν·[t]x)·R   M_ν·R ]   (equals M * adjoint() to rounding).
  Jacobian times_adjoint(const Jacobian& M) const { return times_adjoint(M, R_.matrix()); }
  /// times_adjoint(M) with R = rotation().matrix() from the caller (several products with one
  /// T: the pose-graph accumulation converts the quaternion once).
  Jacobian times_adjoint(const Jacobian& M, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    Jacobian out;
    times_adjoint_into(M, R, &out);
    return out;
  }
  /// *out = M·Ad(T) (out must not alias M), with R = rotation().matrix(): written in place.
  void times_adjoint_into(const Jacobian& M, const Eigen::Matrix<Scalar, 3, 3>& R,
                          Jacobian* out) const {
    Eigen::Matrix<Scalar, 3, 3> tR;
    for (int k = 0; k < 3; ++k) tR.col(k) = t_.cross(R.col(k));
    out->template leftCols<3>().noalias() = M.template leftCols<3>() * R;
    out->template leftCols<3>().noalias() += M.template rightCols<3>() * tR;
    out->template rightCols<3>().noalias() = M.template rightCols<3>() * R;
  }

  /// Ad(T)·d for any d without forming Ad(T) (a tangent moved across T):
  ///   Ad(T)·d = [ R·d_ω ;  t × (R·d_ω) + R·d_ν ]   (equals adjoint() * d to rounding).
  Tangent adjoint_times(const Tangent& d) const { return adjoint_times(d, R_.matrix()); }
  /// adjoint_times(d) with R = rotation().matrix() from the caller.
  Tangent adjoint_times(const Tangent& d, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    const Point w = R * d.template segment<3>(kOmega);
    Tangent out;
    out.template segment<3>(kOmega) = w;
    out.template segment<3>(kNu) = t_.cross(w) + R * d.template segment<3>(kNu);
    return out;
  }

  /// Ad(T)ᵀ·u for any u without forming Ad(T) (a gradient through a composition):
  ///   Ad(T)ᵀ·u = [ Rᵀ·(u_ω − t × u_ν) ;  Rᵀ·u_ν ]   (equals adjoint().transpose() * u to
  ///   rounding).
  Tangent adjoint_transpose_times(const Tangent& u) const {
    return adjoint_transpose_times(u, R_.matrix());
  }
  /// adjoint_transpose_times(u) with R = rotation().matrix() from the caller.
  Tangent adjoint_transpose_times(const Tangent& u, const Eigen::Matrix<Scalar, 3, 3>& R) const {
    const Point un = u.template segment<3>(kNu);
    Tangent out;
    out.template segment<3>(kOmega).noalias() =
        R.transpose() * (u.template segment<3>(kOmega) - t_.cross(un));
    out.template segment<3>(kNu).noalias() = R.transpose() * un;
    return out;
  }

  /// Exact left Jacobian Jl(ξ) = Σ_k ad_ξᵏ/(k+1)!, with exp(ξ + dξ) = exp(Jl·dξ)·exp(ξ):
  ///   [ J   0 ]      J = Jl_SO3(ω),
  ///   [ Q   J ]      Q = ∂(J(ω)ν)/∂ω + [J(ω)ν]x·J(ω)   (Barfoot's Q(ν, ω), closed form in
  ///                  detail::translation_rows; Taylor below kSmallAngle).
  static Jacobian left_jacobian(const Tangent& xi) {
    Eigen::Matrix<Scalar, 3, 3> J, Q;
    left_jacobian_blocks(xi, &J, &Q);
    Jacobian Jl;
    Jl << J, Eigen::Matrix<Scalar, 3, 3>::Zero(), Q, J;
    return Jl;
  }

  /// Exact inverse of left_jacobian(ξ) by block inversion of the lower-triangular form:
  ///   [ J⁻¹          0   ]
  ///   [ −J⁻¹·Q·J⁻¹   J⁻¹ ]      (J⁻¹ = Jl_SO3⁻¹(ω) in closed form).
  static Jacobian left_jacobian_inverse(const Tangent& xi) {
    Eigen::Matrix<Scalar, 3, 3> J, Q;
    left_jacobian_blocks(xi, &J, &Q);
    const Eigen::Matrix<Scalar, 3, 3> Ji =
        detail::so3_left_jacobian_inverse<Scalar>(xi.template segment<3>(kOmega));
    Jacobian Jli;
    Jli << Ji, Eigen::Matrix<Scalar, 3, 3>::Zero(), -Ji * Q * Ji, Ji;
    return Jli;
  }

  /// The 4x4 homogeneous matrix [R t; 0 1].
  Matrix matrix() const {
    Matrix M = Matrix::Identity();
    M.template topLeftCorner<3, 3>() = R_.matrix();
    M.template topRightCorner<3, 1>() = t_;
    return M;
  }
  /// Rotation part R.
  const SO3<Scalar>& rotation() const { return R_; }
  /// Translation part t (metres).
  const Point& translation() const { return t_; }

  /// Same transform in another scalar type.
  template <typename T>
  SE3<T> cast() const {
    return SE3<T>(R_.template cast<T>(), t_.template cast<T>());
  }

  /// True when the rotations agree to tol (rad) and |t − t_other| ≤ tol·max(1, |t|, |t_other|).
  bool is_approx(const SE3& other, Scalar tol = Eigen::NumTraits<Scalar>::dummy_precision()) const {
    using std::max;
    const Scalar mag = max(Scalar(1), max(t_.norm(), other.t_.norm()));
    return R_.is_approx(other.R_, tol) && (t_ - other.t_).norm() <= tol * mag;
  }

 private:
  /// The blocks of left_jacobian(ξ): J = Jl_SO3(ω) and Barfoot's Q(ν, ω).
  static void left_jacobian_blocks(const Tangent& xi, Eigen::Matrix<Scalar, 3, 3>* J,
                                   Eigen::Matrix<Scalar, 3, 3>* Q) {
    const Point omega = xi.template segment<3>(kOmega);
    const detail::VCoeffs<Scalar> c = detail::se3_coeffs<Scalar>(omega.norm(), true);
    const Eigen::Matrix<Scalar, 3, 3> W = skew<Scalar>(omega);
    *J = Eigen::Matrix<Scalar, 3, 3>::Identity() + c.c1 * W + c.c2 * (W * W);
    detail::translation_rows<Scalar>(omega, xi.template segment<3>(kNu), c, *J, Q, nullptr);
  }

  struct Raw {};  // internal: inputs known finite
  SE3(const SO3<Scalar>& R, const Point& t, Raw) : R_(R), t_(t) {}

  SO3<Scalar> R_;
  Point t_ = Point::Zero();
};

using SE3d = SE3<double>;
using SE3f = SE3<float>;

}  // namespace geodrift::lie
