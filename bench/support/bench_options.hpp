#pragma once

/// @file
/// What every geodrift row of bench_solver (and bench/drift_trace, its fresh-process twin) solves
/// with: the shared stopping rule (Ceres' defaults, which both solvers implement the same way),
/// the problems' seed and our LM options.

#include "geodrift/solver/levenberg_marquardt.hpp"

namespace geodrift::bench {

inline constexpr int kMaxIterations = 200;
inline constexpr double kFunctionTolerance = 1e-6;
inline constexpr double kGradientTolerance = 1e-10;
inline constexpr double kParameterTolerance = 1e-8;
/// Seed of the generated problems (drift graph, synthetic BA, start perturbations).
inline constexpr unsigned kSeed = 7;
/// λ0 = 1e-8 on both sides (Ceres: initial trust-region radius 1e8): the drift graph's first
/// iterations are limited by λ0 = 1e-4 (its soft directions, fixed by 1 m priors against 1e5
/// edges, are damped ~60x), so the low-damping rows show each solver with that limit removed.
inline constexpr double kLowDampingLambda = 1e-8;

/// Our LM with the shared stopping rule.
inline solver::Options our_options(solver::LinearSolverType type, int threads) {
  solver::Options o;
  o.linear_solver = type;
  o.num_threads = threads;
  o.max_iterations = kMaxIterations;
  o.function_tolerance = kFunctionTolerance;
  o.gradient_tolerance = kGradientTolerance;
  o.parameter_tolerance = kParameterTolerance;
  o.lambda_decrease_limit = 0.1;  // Marquardt's factor as the limit of Nielsen's rule (see Options)
  return o;
}

/// our_options() with geodesic acceleration (Options::geodesic_acceleration) and backtracking
/// along rejected steps (Options::backtracking) from λ0.
inline solver::Options accel_options(solver::LinearSolverType type, int threads, double lambda0) {
  solver::Options o = our_options(type, threads);
  o.geodesic_acceleration = true;
  o.backtracking = true;
  o.initial_lambda = lambda0;
  return o;
}

}  // namespace geodrift::bench
