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
/// ## Linked Jacobians (optional)
/// A two-parameter functor whose second Jacobian is −(first)·Ad(G) for a group element G it
/// computes anyway (RelativePoseResidual: J_r_Sj = −J_r_Si·Ad(S_i·S_j⁻¹)) may declare
/// @code
///   using LinkGroup = lie::Sim3d;   // see below for what the group must provide
///   bool linked(const lie::Sim3d& S_i, const lie::Sim3d& S_j, Eigen::Matrix<double, 7, 1>* r,
///               Eigen::Matrix<double, 7, 7>* J_r_Si, lie::Sim3d* G) const;  // G: J_r_Sj link
/// @endcode
/// The group provides rotation().matrix() and times_adjoint(M, R) = M·Ad,
/// adjoint_times(d, R) = Ad·d and adjoint_transpose_times(u, R) = Adᵀ·u with R that rotation
/// matrix (SE3d and Sim3d do).
/// When both parameters are free, ResidualBlock then evaluates only J̃_i (weight and Triggs
/// correction act from the left, so J̃_j = −J̃_i·Ad(G) still holds) and accumulates
///   H_ii += J̃_iᵀJ̃_i,  H_ij −= H_ii'·Ad(G),  H_jj += Ad(G)ᵀ·H_ii'·Ad(G),  g_i += u,
///   g_j −= Ad(G)ᵀ·u   (H_ii' = J̃_iᵀJ̃_i, u = J̃_iᵀr̃),
/// with two structured adjoint products instead of forming J̃_j and two more JᵀJ products.
/// operator() must stay consistent with linked() (tests compare both paths).
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

#include "geodrift/solver/detail/block_kernels.hpp"
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

/// Functor::LinkGroup if the functor declares one (see "Linked Jacobians" above), else void.
template <typename F, typename = void>
struct LinkGroupOf {
  using type = void;
};
template <typename F>
struct LinkGroupOf<F, std::void_t<typename F::LinkGroup>> {
  using type = typename F::LinkGroup;
};

/// dst (column-major, outer stride `stride`) += M, or = M if `assign` (the block's first
/// writer in a linearisation: H needs no zeroing pass), one contiguous fixed-size column at a
/// time. Eigen vectorises the add of a fixed-size column; an add into the whole strided block
/// map (and any product with a transposed Jacobian as its left factor) stays a scalar loop.
template <typename Mat>
inline void add_block(double* dst, int stride, const Mat& M, bool assign) {
  using Col = Eigen::Matrix<double, Mat::RowsAtCompileTime, 1>;
  if (assign) {
    for (int c = 0; c < Mat::ColsAtCompileTime; ++c)
      Eigen::Map<Col>(dst + static_cast<std::ptrdiff_t>(c) * stride) = M.col(c);
  } else {
    for (int c = 0; c < Mat::ColsAtCompileTime; ++c)
      Eigen::Map<Col>(dst + static_cast<std::ptrdiff_t>(c) * stride) += M.col(c);
  }
}
/// dst −= M (or = −M if `assign`), as add_block.
template <typename Mat>
inline void subtract_block(double* dst, int stride, const Mat& M, bool assign) {
  using Col = Eigen::Matrix<double, Mat::RowsAtCompileTime, 1>;
  if (assign) {
    for (int c = 0; c < Mat::ColsAtCompileTime; ++c)
      Eigen::Map<Col>(dst + static_cast<std::ptrdiff_t>(c) * stride) = -M.col(c);
  } else {
    for (int c = 0; c < Mat::ColsAtCompileTime; ++c)
      Eigen::Map<Col>(dst + static_cast<std::ptrdiff_t>(c) * stride) -= M.col(c);
  }
}
/// JᵀJ of a fixed-size J from the dot products of its columns (upper triangle, mirrored):
/// 28 dots instead of a 343-multiply 7×7 product for a pose-graph J̃ (57 -> 34 ns).
/// Square 6×6 / 7×7 J use the AVX2 kernel where the CPU has it (block_kernels.hpp: 4-wide FMA
/// columns of Jᵀ·J; equal to rounding).
template <typename Mat>
inline Eigen::Matrix<double, Mat::ColsAtCompileTime, Mat::ColsAtCompileTime> gram(const Mat& J) {
  constexpr int N = Mat::ColsAtCompileTime;
  Eigen::Matrix<double, N, N> M;
#ifdef GEODRIFT_AVX2_KERNELS
  if constexpr (std::is_same_v<typename Mat::Scalar, double> && Mat::RowsAtCompileTime == N &&
                (N == 6 || N == 7)) {
    if (block_kernels_avx2()) {
      BlockKernelsAvx2<N>::gram(J.data(), M.data());
      return M;
    }
  }
#endif
  for (int c = 0; c < N; ++c) {
    for (int r = 0; r < c; ++r) M(r, c) = M(c, r) = J.col(r).dot(J.col(c));
    M(c, c) = J.col(c).squaredNorm();
  }
  return M;
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
  /// The functor's LinkGroup (void if it declares none); see "Linked Jacobians".
  using LinkGroup = typename detail::LinkGroupOf<Functor>::type;
  static constexpr bool kHasLink = !std::is_void_v<LinkGroup>;
  using FirstJacobian = std::tuple_element_t<0, Jacobians>;

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
    assign_.fill(false);
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
  /// Per pair: this block is the first writer of its H block in Problem::linearize()'s order,
  /// so it assigns instead of adding (set by Problem after partitioning; false = add).
  std::array<bool, kNumPairs> assign_;

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
    if (!call(*r, jac, std::index_sequence_for<Params...>{})) return false;
    return weigh(sqrt_infos, cost, r, jac != nullptr, weighted, [&](const auto& fn) {
      detail::static_for<sizeof...(Params)>([&](auto k) {
        if (col_[k] >= 0) fn(std::get<k>(*jac));
      });
    });
  }

  /// Whether the linked path applies (the functor declares a link and both parameters are free).
  bool linked() const {
    if constexpr (kHasLink)
      return col_[0] >= 0 && col_[1] >= 0;
    else
      return false;
  }

  /// As evaluate() with Jacobians, through Functor::linked(): the weighted, corrected residual,
  /// J̃ of the first parameter and the link G (J̃ of the second is −J̃_0·Ad(G)).
  template <typename G>
  bool evaluate_linked(const SqrtInformation* sqrt_infos, double* cost, Residual* r,
                       FirstJacobian* J0, G* link, Residual* weighted = nullptr) const {
    static_assert(kHasLink && std::is_same_v<G, LinkGroup>, "the functor declares no LinkGroup");
    if (!functor_.linked(Manifold<Param<0>>::view(std::get<0>(states_)),
                         Manifold<Param<1>>::view(std::get<1>(states_)), r, J0, link))
      return false;
    return weigh(sqrt_infos, cost, r, true, weighted, [&](const auto& fn) { fn(*J0); });
  }

  /// g += Jᵀr and H += JᵀJ at the recorded offsets (free parameters only).
  void accumulate(const Residual& r, const Jacobians& jac, double* H, double* g) const {
    // Jᵀ of every free parameter stored column-major, so that Jᵀr and JᵀJ are products with a
    // column-major left factor (vectorised by Eigen) and the results are added column by column.
    std::tuple<Eigen::Matrix<double, Manifold<Params>::kDoF, kNumResiduals>...> Jt;
    detail::static_for<sizeof...(Params)>([&](auto k) {
      constexpr std::size_t K = decltype(k)::value;
      if (col_[K] < 0) return;
      std::get<K>(Jt) = std::get<K>(jac).transpose();
      Eigen::Map<Eigen::Matrix<double, kDoF<K>, 1>>(g + col_[K]).noalias() += std::get<K>(Jt) * r;
    });
    detail::static_for<sizeof...(Params)>([&](auto k) {
      constexpr std::size_t K = decltype(k)::value;
      if (col_[K] < 0) return;
      detail::static_for<sizeof...(Params)>([&](auto l) {
        constexpr std::size_t L = decltype(l)::value;
        if constexpr (L >= K) {
          if (col_[L] < 0) return;
          const int p = pair_index(K, L);
          if constexpr (L == K) {
            Eigen::Matrix<double, kDoF<K>, kDoF<K>> M;
            M.noalias() = std::get<K>(Jt) * std::get<K>(jac);
            detail::add_block(H + off_[p], stride_[p], M, assign_[p]);
          } else if (col_[K] < col_[L]) {
            Eigen::Matrix<double, kDoF<K>, kDoF<L>> M;
            M.noalias() = std::get<K>(Jt) * std::get<L>(jac);
            detail::add_block(H + off_[p], stride_[p], M, assign_[p]);
          } else {
            Eigen::Matrix<double, kDoF<L>, kDoF<K>> M;
            M.noalias() = std::get<L>(Jt) * std::get<K>(jac);
            detail::add_block(H + off_[p], stride_[p], M, assign_[p]);
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
    Residual de = corrected_difference(e, e_h, h);
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

  /// accumulate_acceleration() on the linked path, from the stored J̃_0 and link G: with
  /// J̃_1 = −J̃_0·Ad(G), J̃·v = J̃_0·(v_0 − Ad(G)·v_1) and J̃_1ᵀ·d = −Ad(G)ᵀ·(J̃_0ᵀ·d), so
  /// J̃_1 is never formed (two adjoint-vector products instead of a 7×7 one and a second J̃ᵀ·d).
  template <typename G>
  bool accumulate_acceleration_linked(const Residual& e, const FirstJacobian& J0, const G& link,
                                      const Residual& e_h, const double* v, double h,
                                      double* rhs) const {
    static_assert(kHasLink && std::is_same_v<G, LinkGroup>, "the functor declares no LinkGroup");
    using Vec = Eigen::Matrix<double, kDoF<0>, 1>;
    const Eigen::Map<const Vec> v0(v + col_[0]), v1(v + col_[1]);
    const auto R = link.rotation().matrix();  // one conversion for both adjoint products
    Residual de = corrected_difference(e, e_h, h);
    de.noalias() -= J0 * (v0 - link.adjoint_times(v1, R));
    const Residual dd = (2.0 / h) * de;
    if (!dd.allFinite()) return false;
    const Vec u = J0.transpose() * dd;
    Eigen::Map<Vec>(rhs + col_[0]) += u;
    Eigen::Map<Vec>(rhs + col_[1]) -= link.adjoint_transpose_times(u, R);
    return true;
  }

  /// The linked accumulation (see "Linked Jacobians"), from evaluate_linked()'s r̃, J̃_0 and G.
  template <typename G>
  void accumulate_linked(const Residual& r, const FirstJacobian& J0, const G& link, double* H,
                         double* g) const {
    constexpr int D = kDoF<0>;
    static_assert(kDoF<1> == D && G::kDoF == D, "linked parameters must have the group's DoF");
    using Mat = Eigen::Matrix<double, D, D>;
    using Vec = Eigen::Matrix<double, D, 1>;
    const auto R = link.rotation().matrix();  // one conversion for the three adjoint products
    const Vec u = J0.transpose() * r;
    const Mat M = detail::gram(J0);            // H_ii contribution
    const Mat N = link.times_adjoint(M, R);    // −H_ij = H_ii'·Ad(G)
    const Mat Nt = N.transpose();              // Ad(G)ᵀ·H_ii'
    const Mat Mj = link.times_adjoint(Nt, R);  // H_jj contribution Ad(G)ᵀ·H_ii'·Ad(G)
    Eigen::Map<Vec>(g + col_[0]) += u;
    Eigen::Map<Vec>(g + col_[1]) -= link.adjoint_transpose_times(u, R);
    constexpr int p00 = pair_index(0, 0), p01 = pair_index(0, 1), p11 = pair_index(1, 1);
    detail::add_block(H + off_[p00], stride_[p00], M, assign_[p00]);
    detail::add_block(H + off_[p11], stride_[p11], Mj, assign_[p11]);
    if (col_[0] < col_[1])  // block rows of parameter 0
      detail::subtract_block(H + off_[p01], stride_[p01], N, assign_[p01]);
    else  // block rows of parameter 1
      detail::subtract_block(H + off_[p01], stride_[p01], Nt, assign_[p01]);
  }

 private:
  template <std::size_t... I>
  bool call(Residual& r, Jacobians* jac, std::index_sequence<I...>) const {
    return functor_(Manifold<Params>::view(std::get<I>(states_))..., &r,
                    (jac && col_[I] >= 0 ? &std::get<I>(*jac) : nullptr)...);
  }

  /// C·(e_h − e)/h of accumulate_acceleration(): the weighted residual's difference quotient
  /// through the Triggs corrector C at e (C = I without a loss).
  Residual corrected_difference(const Residual& e, const Residual& e_h, double h) const {
    Residual de = (e_h - e) / h;
    if (!loss_.is_trivial()) {
      const double s = e.squaredNorm();
      double rho[3];
      loss_.evaluate(s, rho);
      TriggsCorrector(s, rho).correct_jacobian(e, de);
    }
    return de;
  }

  /// Shared tail of evaluate() / evaluate_linked(): r ← W·r (copied to *weighted if non-null),
  /// cost ½ρ(|r|²), and (with_jac)
  /// each free Jacobian J ← W·J then the Triggs correction of J and r. for_each(fn) calls fn on
  /// every free Jacobian.
  template <typename ForEach>
  bool weigh(const SqrtInformation* sqrt_infos, double* cost, Residual* r, bool with_jac,
             Residual* weighted, const ForEach& for_each) const {
    if (!r->allFinite()) return false;
    const SqrtInformation* W = sqrt_info_index_ >= 0 ? &sqrt_infos[sqrt_info_index_] : nullptr;
    if (W) {
      *r = ((*W) * (*r)).eval();
    }
    if (sqrt_weight_ != 1.0) *r *= sqrt_weight_;
    if (weighted) *weighted = *r;
    const auto weight = [&](auto& Jk) {
      if (W) Jk = ((*W) * Jk).eval();
      if (sqrt_weight_ != 1.0) Jk *= sqrt_weight_;
    };
    const double s = r->squaredNorm();
    if (loss_.is_trivial()) {
      *cost = 0.5 * s;
      if (with_jac) for_each(weight);
      return std::isfinite(*cost);
    }
    double rho[3];
    loss_.evaluate(s, rho);
    *cost = 0.5 * rho[0];
    if (with_jac) {
      const TriggsCorrector corr(s, rho);
      for_each([&](auto& Jk) {
        weight(Jk);
        corr.correct_jacobian(*r, Jk);
      });
      corr.correct_residual(*r);
    }
    return std::isfinite(*cost);
  }

  Functor functor_;
  RobustLoss loss_;
  double sqrt_weight_ = 1.0;
  int sqrt_info_index_ = -1;
  int id_ = -1;
  States states_;
};

}  // namespace geodrift::solver
