#pragma once

/// @file
/// An independent SE(3) implementation for the Ceres reference twin (bench/reference) and the
/// SE3 pose-graph benchmarks: written from Barfoot, "State Estimation for Robotics" (2017),
/// Sec. 7.1, re-ordered to geodrift's tangent order (omega, nu) and LEFT perturbation
/// X <- exp(delta)·X. It deliberately does not use geodrift::lie so the committed Ceres
/// numbers do not depend on the code they check.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace geodrift::bench::ref {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

inline Mat3 skew(const Vec3& v) {
  Mat3 m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

/// log of a unit quaternion as a rotation vector (accurate near 0 and near pi).
inline Vec3 so3_log(const Eigen::Quaterniond& q_in) {
  Eigen::Quaterniond q = q_in;
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Vec3 v = q.vec();
  const double n = v.norm();
  if (n < 1e-8) {
    // 2·atan(n/w)/n = (2/w)(1 - n²/(3w²) + ...)
    return (2.0 / q.w()) * (1.0 - n * n / (3.0 * q.w() * q.w())) * v;
  }
  return (2.0 * std::atan2(n, q.w()) / n) * v;
}

inline Eigen::Quaterniond so3_exp(const Vec3& w) {
  const double theta = w.norm();
  if (theta < 1e-8) {
    Eigen::Quaterniond q(1.0, 0.5 * w.x(), 0.5 * w.y(), 0.5 * w.z());
    q.normalize();
    return q;
  }
  const double s = std::sin(0.5 * theta) / theta;
  return Eigen::Quaterniond(std::cos(0.5 * theta), s * w.x(), s * w.y(), s * w.z());
}

/// SO(3) left Jacobian J(w) = I + (1-cos t)/t² [w]x + (t - sin t)/t³ [w]x².
inline Mat3 so3_left_jacobian(const Vec3& w) {
  const double t2 = w.squaredNorm(), t = std::sqrt(t2);
  double a, b;
  if (t < 1e-4) {
    a = 0.5 - t2 / 24.0;
    b = 1.0 / 6.0 - t2 / 120.0;
  } else {
    a = (1.0 - std::cos(t)) / t2;
    b = (t - std::sin(t)) / (t2 * t);
  }
  const Mat3 W = skew(w);
  return Mat3::Identity() + a * W + b * W * W;
}

/// SO(3) inverse left Jacobian J⁻¹(w) = I - ½[w]x + (1/t² - (1+cos t)/(2 t sin t)) [w]x².
inline Mat3 so3_left_jacobian_inverse(const Vec3& w) {
  const double t2 = w.squaredNorm(), t = std::sqrt(t2);
  const double c =
      t < 1e-4 ? 1.0 / 12.0 + t2 / 720.0 : 1.0 / t2 - (1.0 + std::cos(t)) / (2.0 * t * std::sin(t));
  const Mat3 W = skew(w);
  return Mat3::Identity() - 0.5 * W + c * W * W;
}

/// Barfoot's Q(rho, phi) (eq. 7.86): the off-diagonal block of the SE(3) left Jacobian.
inline Mat3 se3_q(const Vec3& phi, const Vec3& rho) {
  const double t2 = phi.squaredNorm(), t = std::sqrt(t2);
  double c1, c2, c3;
  if (t < 1e-4) {
    c1 = 1.0 / 6.0 - t2 / 120.0;
    c2 = 1.0 / 24.0 - t2 / 720.0;
    c3 = 1.0 / 120.0 - t2 / 2520.0;
  } else {
    const double s = std::sin(t), c = std::cos(t);
    c1 = (t - s) / (t2 * t);
    c2 = (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2);
    c3 = (2.0 * t - 3.0 * s + t * c) / (2.0 * t2 * t2 * t);
  }
  const Mat3 P = skew(phi), R = skew(rho);
  const Mat3 PR = P * R, RP = R * P, PRP = PR * P;
  return 0.5 * R + c1 * (PR + RP + PRP) + c2 * (P * PR + RP * P - 3.0 * PRP) +
         c3 * (PRP * P + P * PRP);
}

/// A rigid transform p' = R·p + t.
struct SE3 {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Vec3 t = Vec3::Zero();

  SE3 operator*(const SE3& b) const { return {q * b.q, q * b.t + t}; }
  SE3 inverse() const {
    const Eigen::Quaterniond qi = q.conjugate();
    return {qi, -(qi * t)};
  }
  /// exp(omega, nu) = [exp(omega), J(omega)·nu].
  static SE3 exp(const Vec6& xi) {
    const Vec3 w = xi.head<3>();
    return {so3_exp(w), so3_left_jacobian(w) * xi.tail<3>()};
  }
  /// log in (omega, nu) order; if J_inv is given, the SE(3) inverse left Jacobian at the
  /// result, [[J⁻¹, 0], [-J⁻¹·Q·J⁻¹, J⁻¹]] in (omega, nu) order.
  Vec6 log(Mat6* J_inv = nullptr) const {
    const Vec3 w = so3_log(q);
    const Mat3 Ji = so3_left_jacobian_inverse(w);
    Vec6 xi;
    xi.head<3>() = w;
    xi.tail<3>() = Ji * t;
    if (J_inv) {
      J_inv->topLeftCorner<3, 3>() = Ji;
      J_inv->topRightCorner<3, 3>().setZero();
      J_inv->bottomLeftCorner<3, 3>() = -Ji * se3_q(w, xi.tail<3>()) * Ji;
      J_inv->bottomRightCorner<3, 3>() = Ji;
    }
    return xi;
  }
  /// Ad(X) with X·exp(d)·X⁻¹ = exp(Ad·d), (omega, nu) order: [[R, 0], [[t]x·R, R]].
  Mat6 adjoint() const {
    const Mat3 R = q.toRotationMatrix();
    Mat6 A;
    A.topLeftCorner<3, 3>() = R;
    A.topRightCorner<3, 3>().setZero();
    A.bottomLeftCorner<3, 3>() = skew(t) * R;
    A.bottomRightCorner<3, 3>() = R;
    return A;
  }
};

/// SE(3) pose-graph edge in geodrift's convention (poses T_iw, world -> body):
///   r = log(Z_ij⁻¹ · T_i · T_j⁻¹), Z_ij = T_wi⁻¹·T_wj = T_i·T_j⁻¹ at the truth.
/// Left perturbations: Z⁻¹·exp(d)·T_i·T_j⁻¹ = exp(Ad(Z⁻¹)·d)·E, so J_i = Jl⁻¹(r)·Ad(Z⁻¹);
/// Z⁻¹·T_i·T_j⁻¹·exp(-d) = exp(-Ad(E)·d)·E, so J_j = -Jl⁻¹(r)·Ad(E).
inline Vec6 relative_pose_residual(const SE3& Z_inv, const SE3& T_i, const SE3& T_j, Mat6* J_i,
                                   Mat6* J_j) {
  const SE3 E = Z_inv * T_i * T_j.inverse();
  if (!J_i && !J_j) return E.log();
  Mat6 Jl_inv;
  const Vec6 r = E.log(&Jl_inv);
  if (J_i) *J_i = Jl_inv * Z_inv.adjoint();
  if (J_j) *J_j = -Jl_inv * E.adjoint();
  return r;
}

}  // namespace geodrift::bench::ref
