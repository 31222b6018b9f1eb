#pragma once

/// @file
/// Manifold traits: how the solver updates a parameter block of a given type.
///
/// `Manifold<T>` gives, for a parameter state type T:
///   - `kDoF`      tangent (column) size, the number of columns the block owns in J and H;
///   - `kAmbient`  number of doubles in T's natural coordinates (used for the parameter
///                 tolerance |x| only; Euclidean: N, SO3: 4 (quaternion), SE3: 7, Sim3: 8);
///   - `Tangent`   Eigen::Matrix<double, kDoF, 1>;
///   - `State`     the type the caller owns (T, or `double` for Euclidean<N> arrays);
///   - `Argument`  the type a residual functor receives as `const Argument&`;
///   - `plus(x, delta)` the retraction: exp(delta)·x for Lie groups (LEFT perturbation,
///                 DESIGN.md), x + delta for R^n;
///   - `ambient_squared_norm(x)`;
///   - `Storage`, `save(x, s)`, `restore(s, x)`: a copy of the state for rolling back a step.
///
/// Specialised here for Eigen fixed-size column vectors (R^N), raw `double` arrays of size N
/// (`Euclidean<N>`, registered with `solver::euclidean<N>(ptr)`), and geodrift's Lie groups
/// SO3d, SE3d, Sim3d. Any other type with `kDoF`, `Tangent`, `static exp(Tangent)` and
/// `operator*` is treated as a Lie group with left retraction (kAmbient = kDoF). The solver
/// never names a group: it only uses these traits.

#include <Eigen/Core>
#include <type_traits>

namespace geodrift::lie {
template <typename Scalar>
class SO3;
template <typename Scalar>
class SE3;
template <typename Scalar>
class Sim3;
}  // namespace geodrift::lie

namespace geodrift::solver {

/// Tag for a caller-owned array of N doubles (e.g. a BAL point `double[3]`). Functors receive
/// it as `Eigen::Map<const Eigen::Matrix<double, N, 1>>`.
template <int N>
struct Euclidean {};

/// A `double*` tagged with its size N, as passed to Problem::add_residual_block.
template <int N>
struct EuclideanPtr {
  double* ptr = nullptr;
};

/// Tags `ptr` (N doubles owned by the caller) as an R^N parameter block.
template <int N>
EuclideanPtr<N> euclidean(double* ptr) {
  return EuclideanPtr<N>{ptr};
}

template <typename T, typename Enable = void>
struct Manifold;  // undefined: the type is not a parameter block type

/// R^N as an Eigen fixed-size column vector; plus(x, d) = x + d.
template <int N>
struct Manifold<Eigen::Matrix<double, N, 1>> {
  static_assert(N > 0, "Euclidean parameter blocks need a fixed size N > 0");
  static constexpr int kDoF = N;
  static constexpr int kAmbient = N;
  using State = Eigen::Matrix<double, N, 1>;
  using Argument = State;
  using Tangent = Eigen::Matrix<double, N, 1>;

  using Storage = State;  ///< a copy of the state (LM's rollback buffer)

  static const Argument& view(const State* x) { return *x; }
  static State plus(const State& x, const Tangent& delta) { return x + delta; }
  static void save(const State* x, Storage* s) { *s = *x; }
  static void restore(const Storage& s, State* x) { *x = s; }
  /// In place: *x ← *x + delta (delta points at kDoF doubles).
  static void plus_in_place(State* x, const double* delta) {
    *x += Eigen::Map<const Tangent>(delta);
  }
  static double ambient_squared_norm(const State& x) { return x.squaredNorm(); }
};

/// R^N as a caller-owned `double[N]`; plus(x, d) = x + d.
template <int N>
struct Manifold<Euclidean<N>> {
  static_assert(N > 0, "Euclidean parameter blocks need a fixed size N > 0");
  static constexpr int kDoF = N;
  static constexpr int kAmbient = N;
  using State = double;  ///< the first of N contiguous doubles
  using Argument = Eigen::Map<const Eigen::Matrix<double, N, 1>>;
  using Tangent = Eigen::Matrix<double, N, 1>;

  using Storage = Eigen::Matrix<double, N, 1>;

  static Argument view(const State* x) { return Argument(x); }
  static void save(const State* x, Storage* s) { *s = Eigen::Map<const Storage>(x); }
  static void restore(const Storage& s, State* x) {
    Eigen::Map<Storage> m(x);
    m = s;
  }
  static void plus_in_place(State* x, const double* delta) {
    for (int i = 0; i < N; ++i) x[i] += delta[i];
  }
  static double ambient_squared_norm(const State& x) {
    return Eigen::Map<const Tangent>(&x).squaredNorm();
  }
};

namespace detail {
template <typename T, typename = void>
struct IsLieGroupLike : std::false_type {};
template <typename T>
struct IsLieGroupLike<T, std::void_t<decltype(T::kDoF), typename T::Tangent,
                                     decltype(T::exp(std::declval<const typename T::Tangent&>()) *
                                              std::declval<const T&>())>> : std::true_type {};

/// Lie group G with the LEFT retraction plus(x, d) = exp(d)·x.
template <typename G, int Ambient>
struct LieGroupManifold {
  static constexpr int kDoF = G::kDoF;
  static constexpr int kAmbient = Ambient;
  using State = G;
  using Argument = G;
  using Tangent = Eigen::Matrix<double, kDoF, 1>;

  using Storage = G;

  static const Argument& view(const State* x) { return *x; }
  static State plus(const State& x, const Tangent& delta) { return G::exp(delta) * x; }
  static void save(const State* x, Storage* s) { *s = *x; }
  static void restore(const Storage& s, State* x) { *x = s; }
  static void plus_in_place(State* x, const double* delta) {
    const Tangent d = Eigen::Map<const Tangent>(delta);
    *x = G::exp(d) * (*x);
  }
  static double ambient_squared_norm(const State& x) {
    if constexpr (Ambient == 4) {
      return 1.0;  // unit quaternion
    } else if constexpr (Ambient == 7) {
      return 1.0 + x.translation().squaredNorm();
    } else if constexpr (Ambient == 8) {
      return 1.0 + x.translation().squaredNorm() + x.scale() * x.scale();
    } else {
      return static_cast<double>(kDoF);  // unknown group: a neutral magnitude
    }
  }
};
}  // namespace detail

namespace detail {
template <typename T>
struct IsGeodriftGroup : std::false_type {};
template <typename S>
struct IsGeodriftGroup<lie::SO3<S>> : std::true_type {};
template <typename S>
struct IsGeodriftGroup<lie::SE3<S>> : std::true_type {};
template <typename S>
struct IsGeodriftGroup<lie::Sim3<S>> : std::true_type {};
}  // namespace detail

/// SO(3): plus(R, ω) = exp(ω)·R.
template <typename S>
struct Manifold<lie::SO3<S>> : detail::LieGroupManifold<lie::SO3<S>, 4> {};
/// SE(3), tangent (ω, ν): plus(T, δ) = exp(δ)·T.
template <typename S>
struct Manifold<lie::SE3<S>> : detail::LieGroupManifold<lie::SE3<S>, 7> {};
/// Sim(3), tangent (ω, σ, ν): plus(S, δ) = exp(δ)·S.
template <typename S>
struct Manifold<lie::Sim3<S>> : detail::LieGroupManifold<lie::Sim3<S>, 8> {};

/// Any other Lie-group-like type (kDoF, Tangent, exp, operator*), e.g. a test group.
template <typename G>
struct Manifold<
    G, std::enable_if_t<!detail::IsGeodriftGroup<G>::value && detail::IsLieGroupLike<G>::value &&
                        !std::is_base_of_v<Eigen::MatrixBase<G>, G>>>
    : detail::LieGroupManifold<G, G::kDoF> {};

}  // namespace geodrift::solver
