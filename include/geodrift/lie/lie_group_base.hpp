#pragma once

/// @file
/// LieGroupBase<Derived>: the operations every geodrift Lie group deduces from its minimum API
/// (exp, log, inverse, operator*, matrix). One CRTP layer; each group owns its storage.
/// Perturbations are on the LEFT, X ← exp(δ)·X (DESIGN.md).

#include <Eigen/Core>
#include <ostream>

namespace geodrift::lie {

/// CRTP mixin with the deduced group operations.
/// @tparam Derived SO3<Scalar>, SE3<Scalar> or Sim3<Scalar>; it provides `static exp(Tangent)`,
///         `log()`, `inverse()`, `operator*`, `matrix()` and `static constexpr const char* kName`.
template <typename Derived>
class LieGroupBase {
 public:
  /// Relative transform a.between(b) = a⁻¹·b (b expressed in a's frame; GTSAM's convention).
  Derived between(const Derived& other) const { return derived().inverse() * other; }

  /// Left retraction x ⊞ δ = exp(δ)·x, the update the solver applies.
  /// @param delta tangent vector of size Derived::kDoF in DESIGN.md's order.
  template <typename D>
  Derived boxplus(const Eigen::MatrixBase<D>& delta) const {
    return Derived::exp(delta.eval()) * derived();
  }

  /// Left difference x ⊟ y = log(x·y⁻¹), so that y ⊞ (x ⊟ y) = x.
  /// @return tangent vector (Derived::Tangent).
  auto boxminus(const Derived& y) const { return (derived() * y.inverse()).log(); }

  /// Prints the group name and its homogeneous matrix on one line, e.g. `SE3[1 0 0 0; ...]`.
  friend std::ostream& operator<<(std::ostream& os, const LieGroupBase& x) {
    const Eigen::IOFormat fmt(Eigen::FullPrecision, Eigen::DontAlignCols, " ", "; ", "", "", "[",
                              "]");
    return os << Derived::kName << x.derived().matrix().format(fmt);
  }

 protected:
  LieGroupBase() = default;
  const Derived& derived() const { return static_cast<const Derived&>(*this); }
};

}  // namespace geodrift::lie
