#pragma once

/// @file
/// Seeded test points for the Lie groups (STYLE.md §9): random elements and tangents of SO3,
/// SE3, Sim3 with translations up to 1e4 m, and the hard regions every group test must visit
/// (identity, |ξ| ≈ 1e-9, angle 1e-8, σ = 0 / ±1e-9 with large θ, θ = 0 with large σ,
/// θ = π − 1e-3 and π − 1e-6). Generic over the group type through its kDoF (3, 6, 7).

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/lie/so3.hpp"

#include <Eigen/Core>

#include <cmath>
#include <random>
#include <vector>

namespace geodrift::test {

/// Builds a tangent of Group from its (ω, σ, ν) parts, dropping what the group does not have:
/// SO3 → ω, SE3 → (ω, ν), Sim3 → (ω, σ, ν).
template <class Group>
typename Group::Tangent make_tangent(const Eigen::Vector3d& omega, double sigma,
                                     const Eigen::Vector3d& nu) {
  typename Group::Tangent xi;
  if constexpr (Group::kDoF == 3) {
    xi << omega;
    (void)sigma, (void)nu;
  } else if constexpr (Group::kDoF == 6) {
    xi << omega, nu;
    (void)sigma;
  } else {
    static_assert(Group::kDoF == 7, "make_tangent: SO3, SE3 or Sim3");
    xi << omega, sigma, nu;
  }
  return xi;
}

/// Uniformly distributed unit vector.
inline Eigen::Vector3d random_unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v;
  do {
    v = Eigen::Vector3d(n(rng), n(rng), n(rng));
  } while (v.norm() < 1e-6);
  return v.normalized();
}

/// Translation with log-uniform length in [1e-2, 1e4] m and uniform direction.
inline Eigen::Vector3d random_translation(std::mt19937& rng, double max_norm = 1e4) {
  std::uniform_real_distribution<double> e(-2.0, std::log10(max_norm));
  return std::pow(10.0, e(rng)) * random_unit(rng);
}

/// Uniformly distributed rotation (normalised Gaussian quaternion).
inline lie::SO3d random_so3(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return lie::SO3d(Eigen::Quaterniond(n(rng), n(rng), n(rng), n(rng)));
}

/// Random rigid transform: uniform rotation, translation up to 1e4 m.
inline lie::SE3d random_se3(std::mt19937& rng) {
  const lie::SO3d R = random_so3(rng);
  return lie::SE3d(R, random_translation(rng));
}

/// Random similarity: uniform rotation, translation up to 1e4 m, σ = log s uniform in [−3, 3].
inline lie::Sim3d random_sim3(std::mt19937& rng) {
  std::uniform_real_distribution<double> sig(-3.0, 3.0);
  const lie::SO3d R = random_so3(rng);
  const Eigen::Vector3d t = random_translation(rng);
  return lie::Sim3d(R, t, std::exp(sig(rng)));
}

/// Random element of any of the three groups.
template <class Group>
Group random_element(std::mt19937& rng) {
  if constexpr (Group::kDoF == 3) {
    return random_so3(rng);
  } else if constexpr (Group::kDoF == 6) {
    return random_se3(rng);
  } else {
    return random_sim3(rng);
  }
}

/// Random tangent: rotation angle uniform in [0, π − 1e-3], σ uniform in [−3, 3], ν with
/// log-uniform length in [1e-2, 1e4] (so exp/log stay in the principal branch).
template <class Group>
typename Group::Tangent random_tangent(std::mt19937& rng) {
  std::uniform_real_distribution<double> ang(0.0, M_PI - 1e-3), sig(-3.0, 3.0);
  const Eigen::Vector3d omega = ang(rng) * random_unit(rng);
  const double sigma = sig(rng);
  return make_tangent<Group>(omega, sigma, random_translation(rng));
}

/// The hard-region tangents (deterministic given rng): identity; |ξ| ≈ 1e-9; angle 1e-8 with
/// finite σ, ν; σ = 0 and ±1e-9 with large θ (2.5 rad); θ = 0 with large σ (±2.5); angle
/// π − 1e-3 and π − 1e-6; the series/closed-form switch points of the Sim3 coefficients
/// (θ = 0.5 ± 1e-9, |σ| = 4 ± 1e-9); and each of them with 1e4 m translation parts.
template <class Group>
std::vector<typename Group::Tangent> hard_tangents(std::mt19937& rng) {
  const Eigen::Vector3d a = random_unit(rng), b = random_unit(rng);
  const Eigen::Vector3d nu1 = Eigen::Vector3d(0.3, -1.2, 2.0);
  const Eigen::Vector3d nu4 = 1e4 * b;
  std::vector<typename Group::Tangent> out;
  const auto add = [&](const Eigen::Vector3d& w, double s, const Eigen::Vector3d& n) {
    out.push_back(make_tangent<Group>(w, s, n));
  };
  add(Eigen::Vector3d::Zero(), 0.0, Eigen::Vector3d::Zero());  // identity
  add(1e-9 * a, 1e-9, 1e-9 * b);                               // |ξ| ≈ 1e-9
  add(0.6e-9 * a, -0.8e-9, 0.5e-9 * b);
  for (const Eigen::Vector3d& nu : {nu1, nu4}) {
    add(1e-8 * a, 0.0, nu);  // angle 1e-8
    add(1e-8 * a, 0.7, nu);
    add(1e-8 * a, -1e-9, nu);
    for (double s : {0.0, 1e-9, -1e-9}) add(2.5 * a, s, nu);                // σ ≈ 0, large θ
    for (double s : {2.5, -2.5, 5.0}) add(Eigen::Vector3d::Zero(), s, nu);  // θ = 0, large σ
    add(1e-9 * a, 2.5, nu);
    for (double eps : {1e-3, 1e-6}) {
      add((M_PI - eps) * a, 0.0, nu);  // near π
      add((M_PI - eps) * a, 0.4, nu);
      add((M_PI - eps) * a, -1e-9, nu);
    }
    for (double th : {0.5 - 1e-9, 0.5 + 1e-9, 1e-2 - 1e-12, 1e-2 + 1e-12})
      add(th * a, 0.3, nu);  // branch switches
    for (double s : {4.0 - 1e-9, 4.0 + 1e-9, -4.0 - 1e-9}) add(0.2 * a, s, nu);
  }
  return out;
}

/// Hard-region group elements: exp of hard_tangents().
template <class Group>
std::vector<Group> hard_samples(std::mt19937& rng) {
  std::vector<Group> out;
  for (const auto& xi : hard_tangents<Group>(rng)) out.push_back(Group::exp(xi));
  return out;
}

/// n group elements: all hard samples first, then random ones up to n in total.
template <class Group>
std::vector<Group> group_samples(std::mt19937& rng, int n) {
  std::vector<Group> out = hard_samples<Group>(rng);
  while (static_cast<int>(out.size()) < n) out.push_back(random_element<Group>(rng));
  return out;
}

/// n tangents: all hard tangents first, then random ones up to n in total.
template <class Group>
std::vector<typename Group::Tangent> tangent_samples(std::mt19937& rng, int n) {
  std::vector<typename Group::Tangent> out = hard_tangents<Group>(rng);
  while (static_cast<int>(out.size()) < n) out.push_back(random_tangent<Group>(rng));
  return out;
}

}  // namespace geodrift::test
