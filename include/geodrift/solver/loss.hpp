#pragma once

/// @file
/// Robust losses ρ(s) of the squared residual norm s = |r|², and the Triggs correction that
/// turns a robustified residual into a Gauss-Newton block.
///
/// Cost convention (as Ceres): a residual block contributes ½·ρ(|W·r|²) to the total cost,
/// where W is its square-root weight. ρ(s) = s for the trivial loss.

#include <Eigen/Core>
#include <cmath>
#include <string>

#include "geodrift/error.hpp"

namespace geodrift::solver {

/// A robust loss, held by value (no virtual call): trivial, Huber or Cauchy.
///   trivial : ρ(s) = s
///   Huber   : ρ(s) = s                     for s ≤ δ²,
///             ρ(s) = 2δ·√s − δ²             otherwise        (δ: residual-norm threshold)
///   Cauchy  : ρ(s) = c²·log(1 + s/c²)                        (c: scale)
/// evaluate() returns ρ, ρ' = dρ/ds and ρ'' = d²ρ/ds².
class RobustLoss {
 public:
  enum class Type { kTrivial, kHuber, kCauchy };

  /// ρ(s) = s (plain least squares).
  RobustLoss() = default;
  static RobustLoss trivial() { return RobustLoss(); }
  /// Huber with threshold delta on the residual norm (same units as the weighted residual).
  /// @throws InvalidArgument unless delta is finite and > 0.
  static RobustLoss huber(double delta) {
    GEODRIFT_CHECK(std::isfinite(delta) && delta > 0.0,
                   "Huber loss delta " << delta << " is not finite and > 0");
    return RobustLoss(Type::kHuber, delta);
  }
  /// Cauchy with scale c. @throws InvalidArgument unless c is finite and > 0.
  static RobustLoss cauchy(double c) {
    GEODRIFT_CHECK(std::isfinite(c) && c > 0.0,
                   "Cauchy loss scale " << c << " is not finite and > 0");
    return RobustLoss(Type::kCauchy, c);
  }

  Type type() const { return type_; }
  double parameter() const { return a_; }
  bool is_trivial() const { return type_ == Type::kTrivial; }

  /// rho[0] = ρ(s), rho[1] = ρ'(s), rho[2] = ρ''(s) for s = |r|² ≥ 0.
  void evaluate(double s, double rho[3]) const {
    rho[0] = s;
    rho[1] = 1.0;
    rho[2] = 0.0;
    switch (type_) {
      case Type::kTrivial:
        return;
      case Type::kHuber:
        if (s > b_) {
          const double r = std::sqrt(s);
          rho[0] = 2.0 * a_ * r - b_;
          rho[1] = a_ / r;
          rho[2] = -0.5 * rho[1] / s;
        }
        return;
      case Type::kCauchy: {
        const double sum = 1.0 + s * c_;  // c_ = 1/c²
        const double inv = 1.0 / sum;
        rho[0] = b_ * std::log(sum);
        rho[1] = inv;
        rho[2] = -c_ * inv * inv;
        return;
      }
    }
  }

 private:
  RobustLoss(Type type, double a) : type_(type), a_(a), b_(a * a), c_(1.0 / (a * a)) {}

  Type type_ = Type::kTrivial;
  double a_ = 0.0;  ///< δ (Huber) or c (Cauchy)
  double b_ = 0.0;  ///< a²
  double c_ = 0.0;  ///< 1/a²
};

/// Triggs correction: rescales a residual r (already weighted) and its Jacobian blocks J so that
/// the Gauss-Newton model ½|r̃ + J̃δ|² matches the robustified cost ½ρ(|r + Jδ|²) to second
/// order in δ (gradient exactly, Hessian up to the dropped second-order terms of r).
/// Source: B. Triggs, P. McLauchlan, R. Hartley, A. Fitzgibbon, "Bundle Adjustment — A Modern
/// Synthesis", Vision Algorithms 2000, §6.3 (eq. 11); the same as Ceres' `Corrector`:
///   α solves ½α² − α − (ρ''/ρ')·s = 0, i.e. α = 1 − √(1 + 2sρ''/ρ'),
///   r̃ = √ρ' / (1 − α) · r,   J̃ = √ρ' · (I − α·r·rᵀ/s) · J.
/// When ρ'' ≤ 0 (Huber and Cauchy in their robust regions) or s = 0 the curvature term would
/// make the model indefinite, so α = 0 (plain √ρ' reweighting), as Ceres does.
class TriggsCorrector {
 public:
  /// @param s |r|², @param rho the output of RobustLoss::evaluate(s).
  TriggsCorrector(double s, const double rho[3]) {
    sqrt_rho1_ = std::sqrt(rho[1]);
    if (s == 0.0 || rho[2] <= 0.0) {
      residual_scaling_ = sqrt_rho1_;
      alpha_sq_norm_ = 0.0;
      return;
    }
    const double D = 1.0 + 2.0 * s * rho[2] / rho[1];
    const double alpha = 1.0 - std::sqrt(D);
    residual_scaling_ = sqrt_rho1_ / (1.0 - alpha);
    alpha_sq_norm_ = alpha / s;
  }

  /// J ← √ρ'·(J − α/s · r·(rᵀJ)); call BEFORE correct_residual (uses the original r).
  template <typename R, typename J>
  void correct_jacobian(const Eigen::MatrixBase<R>& r, Eigen::MatrixBase<J>& jac) const {
    if (alpha_sq_norm_ != 0.0) {
      const Eigen::Matrix<double, 1, J::ColsAtCompileTime> rt_j = r.transpose() * jac;
      jac.noalias() -= (alpha_sq_norm_ * r) * rt_j;
    }
    jac *= sqrt_rho1_;
  }
  template <typename R>
  void correct_residual(Eigen::MatrixBase<R>& r) const {
    r *= residual_scaling_;
  }

 private:
  double sqrt_rho1_ = 1.0;
  double residual_scaling_ = 1.0;
  double alpha_sq_norm_ = 0.0;
};

}  // namespace geodrift::solver
