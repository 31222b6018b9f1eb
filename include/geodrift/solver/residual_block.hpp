#pragma once

/// @file
/// ResidualBlock<Functor, Params...>: one residual term with fixed sizes, its square-root
/// weight and robust loss.
///
/// ## Functor contract (STYLE.md §6)
/// A functor is a plain struct that knows nothing of weights, losses or sparsity:
/// @code
///   struct MyResidual {
///     static constexpr int kNumResiduals = 7;
///     bool operator()(const lie::Sim3d& S_i, const lie::Sim3d& S_j,   // Manifold<P>::Argument
///                     Eigen::Matrix<double, 7, 1>* r,
///                     Eigen::Matrix<double, 7, 7>* J_r_Si = nullptr,  // kNumResiduals x kDoF
///                     Eigen::Matrix<double, 7, 7>* J_r_Sj = nullptr) const;
///   };
/// @endcode
/// Jacobians are w.r.t. the LEFT perturbation of each parameter (x ← exp(δ)·x for groups,
/// x ← x + δ for R^n), computed only when the pointer is non-null (it is null for constant
/// parameters and for cost-only evaluations). Returning false means "cannot evaluate here"
/// (e.g. a point behind the camera): LM rejects the step, or stops if it happens at the start.
///
/// ## What the block adds
/// r_w = W·r (W: scalar √λ or an upper-triangular square-root information matrix), cost
/// ½ρ(|r_w|²), then the Triggs correction (loss.hpp) of r_w and the Jacobians. No virtual call:
/// Problem stores blocks in one typed container per (Functor, Params...) and loops statically.

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <tuple>
#include <type_traits>
#include <utility>

#include "geodrift/solver/loss.hpp"
#include "geodrift/solver/manifold.hpp"

namespace geodrift::solver {

namespace detail {
template <typename F, std::size_t... I>
void static_for_impl(F&& f, std::index_sequence<I...>) {
  (f(std::integral_constant<std::size_t, I>{}), ...);
}
/// Calls f(integral_constant<size_t, I>) for I = 0..N-1.
template <std::size_t N, typename F>
void static_for(F&& f) {
  static_for_impl(std::forward<F>(f), std::make_index_sequence<N>{});
}
}  // namespace detail

template <typename Functor, typename... Params>
class ResidualBlock {
 public:
  static constexpr int kNumResiduals = Functor::kNumResiduals;
  static constexpr int kNumParams = static_cast<int>(sizeof...(Params));
  static constexpr int kNumPairs = kNumParams * (kNumParams + 1) / 2;
  static_assert(kNumParams >= 1, "a residual block needs at least one parameter");
  static_assert(kNumResiduals >= 1, "kNumResiduals must be >= 1");

  using Residual = Eigen::Matrix<double, kNumResiduals, 1>;
  using SqrtInformation = Eigen::Matrix<double, kNumResiduals, kNumResiduals>;
  using Jacobians = std::tuple<Eigen::Matrix<double, kNumResiduals, Manifold<Params>::kDoF>...>;
  using States = std::tuple<typename Manifold<Params>::State*...>;
  template <std::size_t K>
  using Param = std::tuple_element_t<K, std::tuple<Params...>>;
  template <std::size_t K>
  static constexpr int kDoF = Manifold<Param<K>>::kDoF;

  /// @param sqrt_weight scalar factor applied to r (√λ), and, if sqrt_info_index ≥ 0, the
  ///        index of a square-root information matrix in the container's table.
  ResidualBlock(Functor functor, RobustLoss loss, double sqrt_weight, int sqrt_info_index,
                States states, int id)
      : functor_(std::move(functor)),
        loss_(loss),
        sqrt_weight_(sqrt_weight),
        sqrt_info_index_(sqrt_info_index),
        id_(id),
        states_(states) {
    col_.fill(-1);
    off_.fill(-1);
    stride_.fill(0);
  }

  const Functor& functor() const { return functor_; }
  const RobustLoss& loss() const { return loss_; }
  const States& states() const { return states_; }
  /// Insertion order of this block in its Problem.
  int id() const { return id_; }

  /// Pair index of parameters (k, l), k ≤ l.
  static constexpr int pair_index(int k, int l) {
    return k * kNumParams - k * (k - 1) / 2 + (l - k);
  }

  /// Column layout, set by Problem::finalize(): first column of parameter k (-1 if constant),
  /// and for each pair (k ≤ l) of free parameters, the offset of their H block in the value
  /// array and its stride (see block_structure.hpp).
  std::array<int, kNumParams> col_;
  std::array<int, kNumPairs> off_;
  std::array<int, kNumPairs> stride_;

  /// Evaluates the weighted, robustified residual.
  /// @param sqrt_infos the container's square-root information table (may be null if unused).
  /// @param cost  ½ρ(|W·r|²).
  /// @param r     Triggs-corrected W·r (the Gauss-Newton residual), if jac != null;
  ///              otherwise W·r (uncorrected).
  /// @param jac   if non-null, corrected Jacobians of the FREE parameters (others untouched).
  /// @return false if the functor fails or the residual is not finite.
  /// @param weighted if non-null, receives W·r before the Triggs correction.
  bool evaluate(const SqrtInformation* sqrt_infos, double* cost, Residual* r, Jacobians* jac,
                Residual* weighted = nullptr) const {
    bool ok = call(*r, jac, std::index_sequence_for<Params...>{});
    if (!ok || !r->allFinite()) return false;
    const SqrtInformation* W = sqrt_info_index_ >= 0 ? &sqrt_infos[sqrt_info_index_] : nullptr;
    if (W) {
      *r = ((*W) * (*r)).eval();
    }
    if (sqrt_weight_ != 1.0) *r *= sqrt_weight_;
    if (weighted) *weighted = *r;
    const double s = r->squaredNorm();
    if (loss_.is_trivial()) {
      *cost = 0.5 * s;
      if (jac) apply_weight(W, *jac);
      return std::isfinite(*cost);
    }
    double rho[3];
    loss_.evaluate(s, rho);
    *cost = 0.5 * rho[0];
    if (jac) {
      apply_weight(W, *jac);
      const TriggsCorrector corr(s, rho);
      detail::static_for<sizeof...(Params)>([&](auto k) {
        if (col_[k] >= 0) corr.correct_jacobian(*r, std::get<k>(*jac));
      });
      corr.correct_residual(*r);
    }
    return std::isfinite(*cost);
  }

  /// g += Jᵀr and H += JᵀJ at the recorded offsets (free parameters only).
  void accumulate(const Residual& r, const Jacobians& jac, double* H, double* g) const {
    detail::static_for<sizeof...(Params)>([&](auto k) {
      constexpr std::size_t K = decltype(k)::value;
      if (col_[K] < 0) return;
      const auto& Jk = std::get<K>(jac);
      Eigen::Map<Eigen::Matrix<double, kDoF<K>, 1>>(g + col_[K]).noalias() += Jk.transpose() * r;
      detail::static_for<sizeof...(Params)>([&](auto l) {
        constexpr std::size_t L = decltype(l)::value;
        if constexpr (L >= K) {
          if (col_[L] < 0) return;
          const int p = pair_index(K, L);
          const auto& Jl = std::get<L>(jac);
          if constexpr (L == K) {
            Eigen::Map<Eigen::Matrix<double, kDoF<K>, kDoF<K>>, 0, Eigen::OuterStride<>> B(
                H + off_[p], Eigen::OuterStride<>(stride_[p]));
            B.noalias() += Jk.transpose() * Jk;
          } else if (col_[K] < col_[L]) {
            Eigen::Map<Eigen::Matrix<double, kDoF<K>, kDoF<L>>, 0, Eigen::OuterStride<>> B(
                H + off_[p], Eigen::OuterStride<>(stride_[p]));
            B.noalias() += Jk.transpose() * Jl;
          } else {
            Eigen::Map<Eigen::Matrix<double, kDoF<L>, kDoF<K>>, 0, Eigen::OuterStride<>> B(
                H + off_[p], Eigen::OuterStride<>(stride_[p]));
            B.noalias() += Jl.transpose() * Jk;
          }
        }
      });
    });
  }

  /// W·r at the current states (weighted, no loss): the residual that geodesic acceleration
  /// differentiates. @return false if the functor fails or r is not finite.
  bool weighted_residual(const SqrtInformation* sqrt_infos, Residual* e) const {
    if (!call(*e, nullptr, std::index_sequence_for<Params...>{}) || !e->allFinite()) return false;
    if (sqrt_info_index_ >= 0) *e = (sqrt_infos[sqrt_info_index_] * (*e)).eval();
    if (sqrt_weight_ != 1.0) *e *= sqrt_weight_;
    return true;
  }

  /// Geodesic acceleration (Transtrum & Sethna 2012, see Options::geodesic_acceleration):
  /// rhs += J̃ᵀ·r̃''_v for the free parameters. r''_v, the second directional derivative of the
  /// weighted residual e = W·r along the step v, is taken by the one-sided difference
  ///   r''_v ≈ (2/h)·[(e(x ⊞ h·v) − e(x))/h − J·v]        (their eq. 15),
  /// in the Triggs-corrected model of linearize(): r̃''_v = (2/h)·[C·(e(x ⊞ h·v) − e(x))/h − J̃·v]
  /// with C = √ρ'·(I − α·e·eᵀ/|e|²) the corrector at x (C = I without a loss).
  /// @param e, J e(x) and the corrected J̃(x) as linearize() computed them (stored there).
  /// @param e_h e(x ⊞ h·v) (weighted_residual() at the perturbed states).
  /// @param v the step in column order (Problem's free columns).
  /// @return false if a value is not finite (the caller skips the acceleration then).
  bool accumulate_acceleration(const Residual& e, const Jacobians& J, const Residual& e_h,
                               const double* v, double h, double* rhs) const {
    Residual de = (e_h - e) / h;
    if (!loss_.is_trivial()) {
      const double s = e.squaredNorm();
      double rho[3];
      loss_.evaluate(s, rho);
      TriggsCorrector(s, rho).correct_jacobian(e, de);
    }
    detail::static_for<sizeof...(Params)>([&](auto k) {
      constexpr std::size_t K = decltype(k)::value;
      if (col_[K] >= 0)
        de.noalias() -=
            std::get<K>(J) * Eigen::Map<const Eigen::Matrix<double, kDoF<K>, 1>>(v + col_[K]);
    });
    const Residual dd = (2.0 / h) * de;
    if (!dd.allFinite()) return false;
    detail::static_for<sizeof...(Params)>([&](auto k) {
      constexpr std::size_t K = decltype(k)::value;
      if (col_[K] < 0) return;
      Eigen::Map<Eigen::Matrix<double, kDoF<K>, 1>>(rhs + col_[K]).noalias() +=
          std::get<K>(J).transpose() * dd;
    });
    return true;
  }

 private:
  template <std::size_t... I>
  bool call(Residual& r, Jacobians* jac, std::index_sequence<I...>) const {
    return functor_(Manifold<Params>::view(std::get<I>(states_))..., &r,
                    (jac && col_[I] >= 0 ? &std::get<I>(*jac) : nullptr)...);
  }

  void apply_weight(const SqrtInformation* W, Jacobians& jac) const {
    detail::static_for<sizeof...(Params)>([&](auto k) {
      if (col_[k] < 0) return;
      auto& Jk = std::get<k>(jac);
      if (W) Jk = ((*W) * Jk).eval();
      if (sqrt_weight_ != 1.0) Jk *= sqrt_weight_;
    });
  }

  Functor functor_;
  RobustLoss loss_;
  double sqrt_weight_ = 1.0;
  int sqrt_info_index_ = -1;
  int id_ = -1;
  States states_;
};

}  // namespace geodrift::solver
