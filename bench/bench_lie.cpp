// Google Benchmark of the Lie groups: exp, log, compose, act for SO3 / SE3 / Sim3, each with and
// without its Jacobians. Inputs: 256 elements / tangents / points from a fixed seed, built
// outside the timed loop and cycled through (rotation angles up to π, translations up to 1e3 m,
// σ in [−1, 1]), so both the series and closed-form branches are exercised.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <cmath>
#include <random>
#include <vector>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"

namespace {

namespace lie = geodrift::lie;
constexpr int kPool = 256;

template <class Group>
typename Group::Tangent make_tangent(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  std::uniform_real_distribution<double> ang(0.0, M_PI - 1e-3), sig(-1.0, 1.0), len(-2.0, 3.0);
  Eigen::Vector3d axis(n(rng), n(rng), n(rng));
  axis.normalize();
  Eigen::Vector3d dir(n(rng), n(rng), n(rng));
  dir.normalize();
  const Eigen::Vector3d omega = ang(rng) * axis;
  const Eigen::Vector3d nu = std::pow(10.0, len(rng)) * dir;
  typename Group::Tangent xi;
  if constexpr (Group::kDoF == 3) {
    xi << omega;
  } else if constexpr (Group::kDoF == 6) {
    xi << omega, nu;
  } else {
    xi << omega, sig(rng), nu;
  }
  return xi;
}

template <class Group>
struct Inputs {
  std::vector<typename Group::Tangent> xi;
  std::vector<Group> x, y;
  std::vector<Eigen::Vector3d> p;
  Inputs() {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(-100.0, 100.0);
    for (int i = 0; i < kPool; ++i) {
      xi.push_back(make_tangent<Group>(rng));
      x.push_back(Group::exp(make_tangent<Group>(rng)));
      y.push_back(Group::exp(make_tangent<Group>(rng)));
      p.emplace_back(u(rng), u(rng), u(rng));
    }
  }
};

template <class Group>
const Inputs<Group>& inputs() {
  static const Inputs<Group> in;
  return in;
}

template <class Group>
void BM_Exp(benchmark::State& state) {
  const auto& in = inputs<Group>();
  int i = 0;
  for (auto _ : state) {
    Group X = Group::exp(in.xi[i++ & (kPool - 1)]);
    benchmark::DoNotOptimize(X);
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_ExpJacobian(benchmark::State& state) {
  const auto& in = inputs<Group>();
  typename Group::Jacobian J;
  int i = 0;
  for (auto _ : state) {
    Group X = Group::exp(in.xi[i++ & (kPool - 1)], &J);
    benchmark::DoNotOptimize(X);
    benchmark::DoNotOptimize(J.data());
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_Log(benchmark::State& state) {
  const auto& in = inputs<Group>();
  int i = 0;
  for (auto _ : state) {
    typename Group::Tangent xi = in.x[i++ & (kPool - 1)].log();
    benchmark::DoNotOptimize(xi.data());
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_LogJacobian(benchmark::State& state) {
  const auto& in = inputs<Group>();
  typename Group::Jacobian J;
  int i = 0;
  for (auto _ : state) {
    typename Group::Tangent xi = in.x[i++ & (kPool - 1)].log(&J);
    benchmark::DoNotOptimize(xi.data());
    benchmark::DoNotOptimize(J.data());
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_Compose(benchmark::State& state) {
  const auto& in = inputs<Group>();
  int i = 0;
  for (auto _ : state) {
    const int k = i++ & (kPool - 1);
    Group Z = in.x[k] * in.y[k];
    benchmark::DoNotOptimize(Z);
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_ComposeJacobian(benchmark::State& state) {
  const auto& in = inputs<Group>();
  typename Group::Jacobian Ja, Jb;
  int i = 0;
  for (auto _ : state) {
    const int k = i++ & (kPool - 1);
    Group Z = in.x[k].compose(in.y[k], &Ja, &Jb);
    benchmark::DoNotOptimize(Z);
    benchmark::DoNotOptimize(Ja.data());
    benchmark::DoNotOptimize(Jb.data());
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_Act(benchmark::State& state) {
  const auto& in = inputs<Group>();
  int i = 0;
  for (auto _ : state) {
    const int k = i++ & (kPool - 1);
    Eigen::Vector3d q = in.x[k].act(in.p[k]);
    benchmark::DoNotOptimize(q.data());
  }
  state.SetItemsProcessed(state.iterations());
}

template <class Group>
void BM_ActJacobian(benchmark::State& state) {
  const auto& in = inputs<Group>();
  Eigen::Matrix<double, 3, Group::kDoF> J_X;
  Eigen::Matrix3d J_p;
  int i = 0;
  for (auto _ : state) {
    const int k = i++ & (kPool - 1);
    Eigen::Vector3d q = in.x[k].act(in.p[k], &J_X, &J_p);
    benchmark::DoNotOptimize(q.data());
    benchmark::DoNotOptimize(J_X.data());
    benchmark::DoNotOptimize(J_p.data());
  }
  state.SetItemsProcessed(state.iterations());
}

/// Near-identity inputs, the regime of a pose-graph residual E = dS_ij·S_i·S_j⁻¹ (θ ≤ 0.05 rad,
/// |σ| ≤ 0.05, |ν| ≤ 2 m) and its measurement / pose pair.
template <class Group>
struct NearIdentity {
  std::vector<Group> E, dS;
  NearIdentity() {
    std::mt19937 rng(11);
    std::normal_distribution<double> n(0.0, 1.0);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < kPool; ++i) {
      typename Group::Tangent xi;
      const Eigen::Vector3d w(0.03 * u(rng), 0.03 * u(rng), 0.03 * u(rng));
      const Eigen::Vector3d v(u(rng), u(rng), u(rng));
      if constexpr (Group::kDoF == 6) {
        xi << w, v;
      } else {
        xi << w, 0.05 * u(rng), v;
      }
      E.push_back(Group::exp(xi));
      dS.push_back(Group::exp(make_tangent<Group>(rng)));
    }
  }
};

template <class Group>
const NearIdentity<Group>& near_identity() {
  static const NearIdentity<Group> in;
  return in;
}

template <class Group>
void BM_LogJacobianNearIdentity(benchmark::State& state) {
  const auto& in = near_identity<Group>();
  typename Group::Jacobian J;
  int i = 0;
  for (auto _ : state) {
    typename Group::Tangent xi = in.E[i++ & (kPool - 1)].log(&J);
    benchmark::DoNotOptimize(xi.data());
    benchmark::DoNotOptimize(J.data());
  }
  state.SetItemsProcessed(state.iterations());
}

/// What a relative-pose residual needs per edge: r = log E with Jl⁻¹(r), and the two Jacobians
/// Jl⁻¹·Ad(dS), −Jl⁻¹·Ad(E); argument 0: dense products with adjoint(), 1: times_adjoint().
template <class Group>
void BM_RelativePoseJacobiansNearIdentity(benchmark::State& state) {
  const auto& in = near_identity<Group>();
  typename Group::Jacobian J, Ji, Jj;
  int i = 0;
  for (auto _ : state) {
    const int k = i++ & (kPool - 1);
    typename Group::Tangent xi = in.E[k].log(&J);
    if (state.range(0) == 0) {  // dense 7x7 products with the formed adjoints
      Ji.noalias() = J * in.dS[k].adjoint();
      Jj.noalias() = -J * in.E[k].adjoint();
    } else {  // what RelativePoseResidual does
      Ji = in.dS[k].times_adjoint(J);
      Jj = -in.E[k].times_adjoint(J);
    }
    benchmark::DoNotOptimize(xi.data());
    benchmark::DoNotOptimize(Ji.data());
    benchmark::DoNotOptimize(Jj.data());
  }
  state.SetItemsProcessed(state.iterations());
}

}  // namespace

BENCHMARK_TEMPLATE(BM_LogJacobianNearIdentity, lie::SE3d);
BENCHMARK_TEMPLATE(BM_LogJacobianNearIdentity, lie::Sim3d);
BENCHMARK_TEMPLATE(BM_RelativePoseJacobiansNearIdentity, lie::SE3d)->Arg(0)->Arg(1);
BENCHMARK_TEMPLATE(BM_RelativePoseJacobiansNearIdentity, lie::Sim3d)->Arg(0)->Arg(1);

#define GEODRIFT_LIE_BENCH(Group)                \
  BENCHMARK_TEMPLATE(BM_Exp, Group);             \
  BENCHMARK_TEMPLATE(BM_ExpJacobian, Group);     \
  BENCHMARK_TEMPLATE(BM_Log, Group);             \
  BENCHMARK_TEMPLATE(BM_LogJacobian, Group);     \
  BENCHMARK_TEMPLATE(BM_Compose, Group);         \
  BENCHMARK_TEMPLATE(BM_ComposeJacobian, Group); \
  BENCHMARK_TEMPLATE(BM_Act, Group);             \
  BENCHMARK_TEMPLATE(BM_ActJacobian, Group)

GEODRIFT_LIE_BENCH(lie::SO3d);
GEODRIFT_LIE_BENCH(lie::SE3d);
GEODRIFT_LIE_BENCH(lie::Sim3d);

BENCHMARK_MAIN();
