#pragma once

/// @file
/// SO(3), rotations of R³, stored as a unit quaternion.
/// Tangent ω ∈ R³ (axis·angle). All Jacobians are w.r.t. LEFT perturbations
/// R ← exp(δ)·R, in the tangent order of DESIGN.md.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <cmath>
#include <limits>

#include "geodrift/error.hpp"
#include "geodrift/lie/detail/so3_details.hpp"
#include "geodrift/lie/lie_group_base.hpp"

namespace geodrift::lie {

/// [v]x: the 3x3 skew-symmetric matrix with [v]x·p = v × p.
template <typename Scalar>
Eigen::Matrix<Scalar, 3, 3> skew(const Eigen::Matrix<Scalar, 3, 1>& v) {
  return detail::skew<Scalar>(v);
}

/// Rotation R ∈ SO(3) acting on points as p' = R·p. Tangent ω ∈ R³ (kOmega = 0), θ = |ω|.
/// All Jacobians are w.r.t. LEFT perturbations R ← exp(δ)·R.
template <typename Scalar>
class SO3 : public LieGroupBase<SO3<Scalar>> {
 public:
  static constexpr int kDoF = 3;
  static constexpr int kOmega = 0;  ///< tangent block offset of ω
  static constexpr const char* kName = "SO3";
  using Tangent = Eigen::Matrix<Scalar, 3, 1>;
  using Jacobian = Eigen::Matrix<Scalar, 3, 3>;
  using Point = Eigen::Matrix<Scalar, 3, 1>;
  using Matrix = Eigen::Matrix<Scalar, 3, 3>;
  using Quaternion = Eigen::Quaternion<Scalar>;

  /// Identity rotation.
  SO3() = default;

  /// From a quaternion, normalised here.
  /// @throws InvalidArgument if q is non-finite or its norm is below 1e-6.
  explicit SO3(const Quaternion& q) : q_(q) {
    GEODRIFT_CHECK(q.coeffs().allFinite(),
                   "SO3: quaternion (x y z w) " << q.coeffs().transpose() << " is not finite");
    const Scalar n = q.norm();
    GEODRIFT_CHECK(n > Scalar(1e-6), "SO3: quaternion norm " << n << " is not > 1e-6");
    q_.coeffs() /= n;
  }

  /// From a 3x3 rotation matrix, re-orthonormalised (nearest rotation in Frobenius norm,
  /// U·Vᵀ from the SVD), so a matrix with rounding drift is accepted.
  /// @throws InvalidArgument if R is non-finite or det(R) ≤ 0 (a reflection or singular).
  explicit SO3(const Matrix& R) {
    GEODRIFT_CHECK(R.allFinite(), "SO3: rotation matrix [" << R << "] is not finite");
    GEODRIFT_CHECK(R.determinant() > Scalar(0),
                   "SO3: rotation matrix determinant " << R.determinant() << " is not > 0");
    const Eigen::JacobiSVD<Matrix> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Matrix Rn = svd.matrixU() * svd.matrixV().transpose();
    q_ = Quaternion(Rn);
    q_.normalize();
  }

  /// exp: so(3) → SO(3), R = exp([ω]x).
  /// @param omega rotation vector (rad).
  /// @param J_R_omega (3x3, optional) = left Jacobian Jl(ω): exp(ω + dω) = exp(Jl·dω)·exp(ω).
  /// @throws InvalidArgument if omega is non-finite.
  static SO3 exp(const Tangent& omega, Jacobian* J_R_omega = nullptr) {
    GEODRIFT_CHECK(omega.allFinite(), "SO3::exp: omega " << omega.transpose() << " is not finite");
    if (J_R_omega) *J_R_omega = detail::so3_left_jacobian<Scalar>(omega);
    return SO3(detail::quaternion_exp<Scalar>(omega), Raw{});
  }

  /// log: SO(3) → so(3), θ ∈ [0, π] (accurate up to θ = π; at exactly π the sign of ω is
  /// arbitrary).
  /// @param J_omega_R (3x3, optional) = Jl⁻¹(log R): d(log R)/dδ for R ← exp(δ)·R.
  Tangent log(Jacobian* J_omega_R = nullptr) const {
    const Tangent omega = detail::quaternion_log<Scalar>(q_);
    if (J_omega_R) *J_omega_R = detail::so3_left_jacobian_inverse<Scalar>(omega);
    return omega;
  }

  /// R⁻¹ = Rᵀ.  @param J_inv_R (3x3, optional) = −Ad(R⁻¹) = −Rᵀ.
  SO3 inverse(Jacobian* J_inv_R = nullptr) const {
    const SO3 inv(q_.conjugate(), Raw{});
    if (J_inv_R) *J_inv_R = -inv.matrix();
    return inv;
  }

  /// Composition a·b (apply b first). Renormalises the quaternion against drift.
  /// (Written out: Eigen's quaternion product and normalized() were calls in the pose-graph
  /// residuals' hot loop, ≈ 3 % of a Sim(3) drift solve; the same products, with the norm
  /// applied as one reciprocal square root.)
  SO3 operator*(const SO3& b) const {
    using std::sqrt;
    const Scalar aw = q_.w(), ax = q_.x(), ay = q_.y(), az = q_.z();
    const Scalar bw = b.q_.w(), bx = b.q_.x(), by = b.q_.y(), bz = b.q_.z();
    const Scalar w = aw * bw - ax * bx - ay * by - az * bz;
    const Scalar x = aw * bx + ax * bw + ay * bz - az * by;
    const Scalar y = aw * by + ay * bw + az * bx - ax * bz;
    const Scalar z = aw * bz + az * bw + ax * by - ay * bx;
    const Scalar inv = Scalar(1) / sqrt(w * w + x * x + y * y + z * z);
    return SO3(Quaternion(w * inv, x * inv, y * inv, z * inv), Raw{});
  }

  /// Composition a·b with Jacobians w.r.t. left perturbations of a and of b.
  /// @param J_ab_a (3x3, optional) = I.   @param J_ab_b (3x3, optional) = Ad(a) = R_a.
  SO3 compose(const SO3& b, Jacobian* J_ab_a = nullptr, Jacobian* J_ab_b = nullptr) const {
    if (J_ab_a) J_ab_a->setIdentity();
    if (J_ab_b) *J_ab_b = adjoint();
    return *this * b;
  }

  /// p' = R·p.
  /// @param J_p_R (3x3, optional) = −[p']x.   @param J_p_p (3x3, optional) = R.
  Point act(const Point& p, Eigen::Matrix<Scalar, 3, 3>* J_p_R = nullptr,
            Eigen::Matrix<Scalar, 3, 3>* J_p_p = nullptr) const {
    // p + w·u + v × u with u = 2·(v × p), v = the quaternion's vector part (Eigen's formula,
    // written out so that it is inlined).
    const Point v = q_.vec();
    const Point u = Scalar(2) * v.cross(p);
    const Point q = p + q_.w() * u + v.cross(u);
    if (J_p_R) *J_p_R = -skew<Scalar>(q);
    if (J_p_p) *J_p_p = matrix();
    return q;
  }

  /// Ad(R) = R, with R·exp(d)·R⁻¹ = exp(R·d).
  Jacobian adjoint() const { return matrix(); }

  /// SO3 left Jacobian Jl(ω) = I + (1−cosθ)/θ²·[ω]x + (θ−sinθ)/θ³·[ω]x² (Taylor near θ = 0).
  static Jacobian left_jacobian(const Tangent& omega) {
    return detail::so3_left_jacobian<Scalar>(omega);
  }

  /// Jl⁻¹(ω) = I − [ω]x/2 + (1 − (θ/2)cot(θ/2))/θ²·[ω]x² (exact up to θ = π, Taylor near 0).
  static Jacobian left_jacobian_inverse(const Tangent& omega) {
    return detail::so3_left_jacobian_inverse<Scalar>(omega);
  }

  /// The 3x3 rotation matrix.
  Matrix matrix() const { return q_.toRotationMatrix(); }
  /// The unit quaternion (w ≥ 0 is not enforced; q and −q are the same rotation).
  const Quaternion& quaternion() const { return q_; }

  /// Same rotation in another scalar type (renormalised there).
  template <typename T>
  SO3<T> cast() const {
    return SO3<T>(q_.template cast<T>());
  }

  /// True when the rotation angle of this·other⁻¹ is ≤ tol (rad).
  bool is_approx(const SO3& other, Scalar tol = Eigen::NumTraits<Scalar>::dummy_precision()) const {
    return (*this * other.inverse()).log().norm() <= tol;
  }

 private:
  struct Raw {};  // internal: q is already unit
  SO3(const Quaternion& q, Raw) : q_(q) {}

  Quaternion q_ = Quaternion::Identity();
};

using SO3d = SO3<double>;
using SO3f = SO3<float>;

}  // namespace geodrift::lie
