// bench_solver: geodrift's LM against its Ceres 2.1 twins on identical problems (issue 3).
//
// Cases (each: same start, same residual maths with analytic Jacobians, same stopping rule):
//   Se3Graph/<graph>/<threads>     the g2o SE(3) graphs (sphere2500, parking-garage, torus3D,
//                                  cubicle) from the file's initial values; Ceres
//                                  SPARSE_NORMAL_CHOLESKY on SuiteSparse
//   Sim3Drift/<keyframes>/<threads> the synthetic monocular-drift Sim(3) graph (1k, 10k, 50k)
//   Ba/<synthetic|kitti>/<threads> BA: 500 cameras × 50,000 points × 5 observations, and the
//                                  real KITTI 00 tracks; Ceres SPARSE_SCHUR
//   Floor_*                         one bare CHOLMOD numeric factorisation of the same H, the
//                                  faster of supernodal and simplicial (AMD, symbolic excluded,
//                                  median of 5); for BA of the reduced camera system
// Counters: lm_iterations, time_per_iteration [ms], final_cost, initial_cost; ours also
// ceres_ratio = Ceres time / our time (Ceres cases run first) and cost_vs_ceres = our final
// cost / Ceres' − 1; reach_* against the Ceres row with the same damping and, for the
// low-damping rows, reach_default_* against Ceres' defaults. Run and tabulate: see BENCHMARKS.md.
//
//   Sim3Drift_Paired/<keyframes>/<fresh_memory>
//                                  the drift target against the host's noise: Ceres' defaults and
//                                  our accelerated low-damping LM alternately, GEODRIFT_BENCH_PAIRS
//                                  rounds (default 5), the median of the per-round ratios; with
//                                  fresh_memory:1 ours first-touches all its memory every round
//
// GEODRIFT_BENCH_DRIFT_SEED=<seed> generates the drift graph from another seed (default 7, the
// seed of every other problem); the JSON context records it as drift_seed.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "geodrift/io/g2o.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "support/ba_data.hpp"
#include "support/bench_options.hpp"
#include "support/drift_graph.hpp"
#include "support/our_problems.hpp"
#if GEODRIFT_HAVE_CERES
#include "support/ceres_se3_graph.hpp"
#include "support/ceres_twins.hpp"
#endif

namespace gb = geodrift::bench;
namespace solver = geodrift::solver;

namespace {

// ---- the shared stopping rule, seed and our options (support/bench_options.hpp) -------------
using gb::accel_options;
using gb::kFunctionTolerance;
using gb::kGradientTolerance;
using gb::kLowDampingLambda;
using gb::kMaxIterations;
using gb::kParameterTolerance;
using gb::kSeed;
using gb::our_options;

const char* const kGraphs[] = {"sphere2500", "parking-garage", "torus3D", "cubicle"};
const int kDriftSizes[] = {1000, 10000, 50000};

// ---- data, generated once per process (outside timed regions) -----------------------------
const geodrift::io::G2oPoseGraph3D& graph(int k) {
  static std::map<int, geodrift::io::G2oPoseGraph3D> cache;
  auto it = cache.find(k);
  if (it == cache.end()) {
    it = cache
             .emplace(k, geodrift::io::read_g2o_se3(std::string(GEODRIFT_DATA_DIR) +
                                                    "/pose_graphs_g2o/" + kGraphs[k] + ".g2o"))
             .first;
  }
  return it->second;
}
/// Seed of the drift graph: GEODRIFT_BENCH_DRIFT_SEED if set (checked in main), else kSeed.
unsigned drift_seed() {
  const char* s = std::getenv("GEODRIFT_BENCH_DRIFT_SEED");
  return s ? static_cast<unsigned>(std::strtoul(s, nullptr, 10)) : kSeed;
}
const gb::DriftGraph& drift(int n) {
  static std::map<int, gb::DriftGraph> cache;
  auto it = cache.find(n);
  if (it == cache.end()) it = cache.emplace(n, gb::make_drift_graph(n, drift_seed())).first;
  return it->second;
}
const gb::BaData& ba(int which) {
  static std::map<int, gb::BaData> cache;
  auto it = cache.find(which);
  if (it == cache.end()) {
    it = cache
             .emplace(which, which == 0 ? gb::make_synthetic_ba(500, 50000, 5, kSeed)
                                        : gb::make_kitti_ba(std::string(GEODRIFT_DATA_DIR) +
                                                                "/gtsam_examples_data",
                                                            kSeed))
             .first;
  }
  return it->second;
}
const char* ba_name(int which) { return which == 0 ? "synthetic" : "kitti"; }

// Ceres results by case key, read by our benchmarks for the ratio counters.
struct Reference {
  double seconds = 0.0, cpu_seconds = 0.0, final_cost = 0.0;
};
std::map<std::string, Reference>& ceres_results() {
  static std::map<std::string, Reference> m;
  return m;
}

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// Time-to-reach rule of the target: the first record of our trace whose cost is
/// ≤ (1 + kReachTolerance) × Ceres' final cost from the same start in the same run.
constexpr double kReachTolerance = 1e-3;

/// The first record of `s`'s trace at or below (1 + kReachTolerance)·cost, or null.
const solver::IterationRecord* first_reach(const solver::Summary& s, double cost) {
  const double target = (1.0 + kReachTolerance) * cost;
  for (const solver::IterationRecord& r : s.trace)
    if (r.cost <= target) return &r;
  return nullptr;
}

/// Runs `solve` (returns the summary) once per benchmark iteration, with `make` (untimed)
/// building a fresh problem from the start values before each solve.
template <typename Make, typename Solve>
void run_ours(benchmark::State& state, const std::string& key, Make make, Solve solve) {
  solver::Summary s;
  double total = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    auto problem = make();
    state.ResumeTiming();
    const double t0 = now();
    s = solve(problem.get());
    const double t = now() - t0;
    total += t;
    state.SetIterationTime(t);
  }
  const double mean = total / static_cast<double>(state.iterations());
  state.counters["lm_iterations"] = s.iterations;
  state.counters["time_per_iteration_ms"] = 1e3 * s.time_total / std::max(1, s.iterations);
  state.counters["cpu_per_iteration_ms"] = 1e3 * s.time_total_cpu / std::max(1, s.iterations);
  // Per iteration without what comes once before the first step (trace[0]: finalize, symbolic
  // analysis and buffers, which repeated solves of one structure reuse, and the initial
  // linearisation).
  if (!s.trace.empty())
    state.counters["cpu_per_step_ms"] =
        1e3 * (s.time_total_cpu - s.trace.front().time_cpu) / std::max(1, s.iterations);
  state.counters["final_cost"] = s.final_cost;
  state.counters["initial_cost"] = s.initial_cost;
  state.counters["evaluate_ms"] = 1e3 * s.time_evaluate;
  state.counters["assemble_ms"] = 1e3 * s.time_assemble;
  state.counters["analyze_ms"] = 1e3 * s.time_analyze;
  state.counters["factorize_ms"] = 1e3 * s.time_factorize;
  state.counters["solve_ms"] = 1e3 * s.time_solve;
  state.counters["converged"] = s.converged() ? 1 : 0;
  const auto it = ceres_results().find(key);
  state.counters["total_cpu_ms"] = 1e3 * s.time_total_cpu;
  if (it != ceres_results().end()) {
    state.counters["ceres_ratio"] = it->second.seconds / mean;
    state.counters["ceres_ratio_cpu"] = it->second.cpu_seconds / s.time_total_cpu;
    state.counters["cost_vs_ceres"] = s.final_cost / it->second.final_cost - 1.0;
    if (const solver::IterationRecord* r = first_reach(s, it->second.final_cost)) {
      state.counters["reach_iterations"] = r->iteration;
      state.counters["reach_ms"] = 1e3 * r->time_wall;
      state.counters["reach_cpu_ms"] = 1e3 * r->time_cpu;
      state.counters["reach_ratio"] = it->second.seconds / r->time_wall;
      state.counters["reach_ratio_cpu"] = it->second.cpu_seconds / r->time_cpu;
    }
  }
  // Low-damping rows also against Ceres' defaults (same problem, key without "-low-damping"):
  // the first record at or below that row's final cost, for runs without CeresLowDamping.
  const std::string low = "-low-damping";
  const std::size_t at = key.find(low);
  const auto def = at == std::string::npos
                       ? ceres_results().end()
                       : ceres_results().find(key.substr(0, at) + key.substr(at + low.size()));
  if (def != ceres_results().end()) {
    if (const solver::IterationRecord* r = first_reach(s, def->second.final_cost)) {
      state.counters["reach_default_iterations"] = r->iteration;
      state.counters["reach_default_cpu_ms"] = 1e3 * r->time_cpu;
      state.counters["reach_default_ratio_cpu"] = def->second.cpu_seconds / r->time_cpu;
    }
  }
  state.SetLabel(s.linear_solver + ": " + solver::to_string(s.termination));
}

#if GEODRIFT_HAVE_CERES
template <typename Make>
void run_ceres(benchmark::State& state, const std::string& key, Make make,
               ceres::Solver::Options options) {
  ceres::Solver::Summary s;
  double total = 0.0, total_cpu = 0.0;
  if (std::getenv("GEODRIFT_BENCH_VERBOSE")) {
    options.minimizer_progress_to_stdout = true;
  }
  for (auto _ : state) {
    state.PauseTiming();
    auto problem = make();
    state.ResumeTiming();
    const double t0 = now();
    const std::clock_t c0 = std::clock();
    ceres::Solve(options, problem->problem.get(), &s);
    total_cpu += static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    const double t = now() - t0;
    total += t;
    state.SetIterationTime(t);
  }
  const int iterations = s.num_successful_steps + s.num_unsuccessful_steps;
  state.counters["lm_iterations"] = iterations;
  state.counters["time_per_iteration_ms"] = 1e3 * s.total_time_in_seconds / std::max(1, iterations);
  state.counters["final_cost"] = s.final_cost;
  state.counters["initial_cost"] = s.initial_cost;
  state.counters["evaluate_ms"] =
      1e3 * (s.residual_evaluation_time_in_seconds + s.jacobian_evaluation_time_in_seconds);
  state.counters["linear_solver_ms"] = 1e3 * s.linear_solver_time_in_seconds;
  state.counters["converged"] = s.termination_type == ceres::CONVERGENCE ? 1 : 0;
  const double reps = static_cast<double>(state.iterations());
  state.counters["total_cpu_ms"] = 1e3 * total_cpu / reps;
  ceres_results()[key] = {total / reps, total_cpu / reps, s.final_cost};
  state.SetLabel(ceres::TerminationTypeToString(s.termination_type));
}
#endif

std::string key(const char* kind, const std::string& which, int threads) {
  return std::string(kind) + "/" + which + "/" + std::to_string(threads);
}

// ---- SE(3) g2o graphs ----------------------------------------------------------------------
void BM_Se3Graph_Ours(benchmark::State& state) {
  const int g = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("se3", kGraphs[g], threads),
      [&] { return std::make_unique<gb::OurSe3Graph>(graph(g)); },
      [&](gb::OurSe3Graph* p) {
        solver::LevenbergMarquardt lm(our_options(solver::LinearSolverType::kAuto, threads));
        return lm.solve(&p->problem);
      });
}
#if GEODRIFT_HAVE_CERES
void BM_Se3Graph_Ceres(benchmark::State& state) {
  const int g = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ceres(
      state, key("se3", kGraphs[g], threads),
      [&] {
        return std::make_unique<gb::CeresSE3Graph>(graph(g), gb::initial_states_T_iw(graph(g)));
      },
      gb::ceres_pose_graph_options(threads, kMaxIterations, kFunctionTolerance, kGradientTolerance,
                                   kParameterTolerance));
}
#endif
/// Counters of a floor row: the bare CHOLMOD factorisation `f`, geodrift's CholmodSolver::
/// factorize on the same H (its gather into P·H·Pᵀ, lower, and CHOLMOD's factorisation of that in
/// natural order, cholmod_solver.hpp) and the block Cholesky where it applies.
void floor_counters(benchmark::State& state, const gb::FactorFloor& f, solver::Problem* problem) {
  state.counters["factor_ms"] = 1e3 * f.median_seconds;
  state.counters["factor_cpu_ms"] = 1e3 * f.median_cpu_seconds;
  state.counters["nnz_L"] = f.nnz_factor;
  state.counters["gflops"] = f.flops / f.median_seconds * 1e-9;
  state.counters["simplicial"] = f.simplicial;
  const gb::FactorFloor c = gb::solver_floor<solver::CholmodSolver>(problem);
  state.counters["cholmod_solver_factor_ms"] = 1e3 * c.median_seconds;
  const gb::FactorFloor b = gb::block_cholesky_floor(problem);
  if (b.median_seconds > 0.0) {
    state.counters["block_factor_ms"] = 1e3 * b.median_seconds;
    state.counters["block_nnz_L"] = b.nnz_factor;
    state.counters["block_gflops"] = b.flops / b.median_seconds * 1e-9;
  }
}

void BM_Floor_Se3Graph(benchmark::State& state) {
  const int g = static_cast<int>(state.range(0));
  gb::OurSe3Graph p(graph(g));
  gb::FactorFloor f;
  for (auto _ : state) {
    f = gb::cholmod_floor(&p.problem);
    state.SetIterationTime(f.median_seconds);
  }
  floor_counters(state, f, &p.problem);
}

// ---- Sim(3) drift graph ----------------------------------------------------------------------
/// Our LM with kAuto (the block Cholesky on this chain-shaped graph) ...
void BM_Sim3Drift_Ours(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("drift", std::to_string(n), threads),
      [&] { return std::make_unique<gb::OurDriftGraph>(drift(n)); },
      [&](gb::OurDriftGraph* p) {
        solver::LevenbergMarquardt lm(our_options(solver::LinearSolverType::kAuto, threads));
        return lm.solve(&p->problem);
      });
}
/// ... and forced onto CHOLMOD (the "≤ 1.5 × bare CHOLMOD factorisation per iteration" target).
void BM_Sim3Drift_OursCholmod(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("drift", std::to_string(n), threads),
      [&] { return std::make_unique<gb::OurDriftGraph>(drift(n)); },
      [&](gb::OurDriftGraph* p) {
        solver::LevenbergMarquardt lm(our_options(solver::LinearSolverType::kCholmod, threads));
        return lm.solve(&p->problem);
      });
}
#if GEODRIFT_HAVE_CERES
void BM_Sim3Drift_Ceres(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ceres(
      state, key("drift", std::to_string(n), threads),
      [&] { return std::make_unique<gb::CeresDriftGraph>(drift(n), drift(n).initial); },
      gb::ceres_lm_options(ceres::SPARSE_NORMAL_CHOLESKY, threads, kMaxIterations,
                           kFunctionTolerance, kGradientTolerance, kParameterTolerance));
}
#endif
void BM_Floor_Sim3Drift(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  gb::OurDriftGraph p(drift(n));
  gb::FactorFloor f;
  for (auto _ : state) {
    f = gb::cholmod_floor(&p.problem);
    state.SetIterationTime(f.median_seconds);
  }
  floor_counters(state, f, &p.problem);
}

/// One linearisation (residuals, Jacobians, H and g) of the drift graph at its start values:
/// the per-edge cost of our evaluation, without the solver around it (counter time_per_edge).
void BM_Linearize_Sim3Drift(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  gb::OurDriftGraph p(drift(n));
  p.problem.finalize(false);
  solver::BlockSparseMatrix H(&p.problem.structure());
  std::vector<double> g(static_cast<std::size_t>(p.problem.structure().num_cols()));
  for (auto _ : state) {
    double cost = 0.0;
    solver::LinearizeTimes times;
    if (!p.problem.linearize(&H, g.data(), &cost, &times)) state.SkipWithError("linearize failed");
    benchmark::DoNotOptimize(cost);
  }
  state.counters["time_per_edge"] = benchmark::Counter(
      static_cast<double>(drift(n).edges.size()),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

// ---- geodesic acceleration and the initial damping (Options::geodesic_acceleration) --------
// (accel_options() and kLowDampingLambda: support/bench_options.hpp)
template <typename Make>
void drift_variant(benchmark::State& state, const char* kind, solver::Options o, Make make) {
  const int n = static_cast<int>(state.range(0));
  o.num_threads = static_cast<int>(state.range(1));
  run_ours(state, key(kind, std::to_string(n), o.num_threads), make, [o](gb::OurDriftGraph* p) {
    solver::LevenbergMarquardt lm(o);
    return lm.solve(&p->problem);
  });
}
void BM_Sim3Drift_OursAccel(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  drift_variant(state, "drift", accel_options(solver::LinearSolverType::kAuto, 1, 1e-4),
                [n] { return std::make_unique<gb::OurDriftGraph>(drift(n)); });
}
void BM_Sim3Drift_OursLowDamping(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  solver::Options o = our_options(solver::LinearSolverType::kAuto, 1);
  o.initial_lambda = kLowDampingLambda;
  drift_variant(state, "drift-low-damping", o,
                [n] { return std::make_unique<gb::OurDriftGraph>(drift(n)); });
}
void BM_Sim3Drift_OursAccelLowDamping(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  drift_variant(state, "drift-low-damping",
                accel_options(solver::LinearSolverType::kAuto, 1, kLowDampingLambda),
                [n] { return std::make_unique<gb::OurDriftGraph>(drift(n)); });
}
void BM_Sim3Drift_OursAccelLowDampingCholmod(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  drift_variant(state, "drift-low-damping",
                accel_options(solver::LinearSolverType::kCholmod, 1, kLowDampingLambda),
                [n] { return std::make_unique<gb::OurDriftGraph>(drift(n)); });
}
#if GEODRIFT_HAVE_CERES
void BM_Sim3Drift_CeresLowDamping(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  ceres::Solver::Options o =
      gb::ceres_lm_options(ceres::SPARSE_NORMAL_CHOLESKY, threads, kMaxIterations,
                           kFunctionTolerance, kGradientTolerance, kParameterTolerance);
  o.initial_trust_region_radius = 1.0 / kLowDampingLambda;
  run_ceres(
      state, key("drift-low-damping", std::to_string(n), threads),
      [&] { return std::make_unique<gb::CeresDriftGraph>(drift(n), drift(n).initial); }, o);
}
#endif
// ---- paired rounds: the drift target against the host's noise --------------------------------
/// Rounds per BM_Sim3Drift_Paired case: GEODRIFT_BENCH_PAIRS (checked in main), default 5.
int drift_pairs() {
  const char* s = std::getenv("GEODRIFT_BENCH_PAIRS");
  return s ? std::atoi(s) : 5;
}
double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

#if GEODRIFT_HAVE_CERES
/// The drift target measured so that the host's noise hits both sides alike: `pairs`
/// rounds, each one Ceres solve with its defaults (to its convergence) and one of our
/// accelerated low-damping solves (accel_options) back to back on fresh problems from the same
/// start, the order alternating between rounds. Per round, ratio = Ceres' CPU time to
/// convergence / our CPU time to reach that round's Ceres final cost (kReachTolerance).
/// Counters: median, min and max of the per-round ratios; medians of both CPU times and of our
/// iterations to reach; reached_all = 0 if a round of ours never got there (its ratio is 0).
/// fresh_memory = 1: the solver's kept large-array mappings are released before each of our
/// solves (release_large_array_cache()), so every solve first-touches all of its memory as in a
/// fresh process; 0: they are reused from the previous round, as by a user's repeated solves.
void BM_Sim3Drift_Paired(benchmark::State& state) {
  const int n = static_cast<int>(state.range(0));
  const bool fresh = state.range(1) != 0;
  const int pairs = drift_pairs();
  const ceres::Solver::Options co =
      gb::ceres_lm_options(ceres::SPARSE_NORMAL_CHOLESKY, 1, kMaxIterations, kFunctionTolerance,
                           kGradientTolerance, kParameterTolerance);
  const solver::Options oo = accel_options(solver::LinearSolverType::kAuto, 1, kLowDampingLambda);
  std::vector<double> ratio, ceres_cpu, reach_cpu, reach_iterations;
  bool reached_all = true, ceres_converged_all = true;
  double ceres_cost = 0.0, our_cost = 0.0;
  for (auto _ : state) {
    ratio.clear();
    ceres_cpu.clear();
    reach_cpu.clear();
    reach_iterations.clear();
    for (int round = 0; round < pairs; ++round) {
      ceres::Solver::Summary cs;
      solver::Summary os;
      double ceres_seconds = 0.0;
      auto run_ceres_once = [&] {
        auto problem = std::make_unique<gb::CeresDriftGraph>(drift(n), drift(n).initial);
        const std::clock_t c0 = std::clock();
        ceres::Solve(co, problem->problem.get(), &cs);
        ceres_seconds = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
      };
      auto run_ours_once = [&] {
        if (fresh) solver::release_large_array_cache();
        gb::OurDriftGraph problem(drift(n));
        solver::LevenbergMarquardt lm(oo);
        os = lm.solve(&problem.problem);
      };
      if (round % 2 == 0) {
        run_ceres_once();
        run_ours_once();
      } else {
        run_ours_once();
        run_ceres_once();
      }
      ceres_converged_all = ceres_converged_all && cs.termination_type == ceres::CONVERGENCE;
      ceres_cost = cs.final_cost;
      our_cost = os.final_cost;
      ceres_cpu.push_back(1e3 * ceres_seconds);
      if (const solver::IterationRecord* r = first_reach(os, cs.final_cost)) {
        reach_cpu.push_back(1e3 * r->time_cpu);
        reach_iterations.push_back(r->iteration);
        ratio.push_back(ceres_seconds / r->time_cpu);
      } else {
        reached_all = false;
        ratio.push_back(0.0);
      }
    }
    state.SetIterationTime(1e-3 * median(reach_cpu));
  }
  state.counters["pairs"] = pairs;
  state.counters["ratio_median"] = median(ratio);
  state.counters["ratio_min"] = *std::min_element(ratio.begin(), ratio.end());
  state.counters["ratio_max"] = *std::max_element(ratio.begin(), ratio.end());
  state.counters["ceres_cpu_ms_median"] = median(ceres_cpu);
  state.counters["reach_cpu_ms_median"] = median(reach_cpu);
  state.counters["reach_iterations_median"] = median(reach_iterations);
  state.counters["ceres_final_cost"] = ceres_cost;
  state.counters["final_cost"] = our_cost;
  state.counters["reached_all"] = reached_all ? 1 : 0;
  state.counters["ceres_converged_all"] = ceres_converged_all ? 1 : 0;
  std::string ratios;
  for (double r : ratio) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%s%.2f", ratios.empty() ? "" : " ", r);
    ratios += buf;
  }
  state.SetLabel("ratios " + ratios);
}
#endif
void BM_Se3Graph_OursAccel(benchmark::State& state) {
  const int g = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("se3", kGraphs[g], threads),
      [&] { return std::make_unique<gb::OurSe3Graph>(graph(g)); },
      [&](gb::OurSe3Graph* p) {
        solver::LevenbergMarquardt lm(
            accel_options(solver::LinearSolverType::kAuto, threads, 1e-4));
        return lm.solve(&p->problem);
      });
}
void BM_Ba_OursAccel(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("ba", ba_name(which), threads),
      [&] { return std::make_unique<gb::OurBa>(ba(which)); },
      [&](gb::OurBa* p) {
        solver::LevenbergMarquardt lm(
            accel_options(solver::LinearSolverType::kSchur, threads, 1e-4));
        return lm.solve(&p->problem);
      });
}

// ---- bundle adjustment -----------------------------------------------------------------------
void BM_Ba_Ours(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  run_ours(
      state, key("ba", ba_name(which), threads),
      [&] { return std::make_unique<gb::OurBa>(ba(which)); },
      [&](gb::OurBa* p) {
        solver::LevenbergMarquardt lm(our_options(solver::LinearSolverType::kSchur, threads));
        return lm.solve(&p->problem);
      });
}
#if GEODRIFT_HAVE_CERES
void BM_Ba_Ceres(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0)), threads = static_cast<int>(state.range(1));
  std::shared_ptr<ceres::ParameterBlockOrdering> ordering;
  ceres::Solver::Options options =
      gb::ceres_lm_options(ceres::SPARSE_SCHUR, threads, kMaxIterations, kFunctionTolerance,
                           kGradientTolerance, kParameterTolerance);
  run_ceres(
      state, key("ba", ba_name(which), threads),
      [&] {
        auto p = std::make_unique<gb::CeresBa>(ba(which));
        options.linear_solver_ordering = p->ordering();
        return p;
      },
      options);
}
#endif
void BM_Floor_Ba(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  gb::FactorFloor f;
  for (auto _ : state) {
    f = gb::cholmod_floor_reduced_camera_system(ba(which));
    state.SetIterationTime(f.median_seconds);
  }
  state.counters["factor_ms"] = 1e3 * f.median_seconds;
  state.counters["factor_cpu_ms"] = 1e3 * f.median_cpu_seconds;
  state.counters["nnz_L"] = f.nnz_factor;
  state.counters["gflops"] = f.flops / f.median_seconds * 1e-9;
}

void graph_args(benchmark::internal::Benchmark* b) {
  for (int g = 0; g < 4; ++g)
    for (int t : {1, 2}) b->Args({g, t});
  b->ArgNames({"graph", "threads"});
}
void drift_args(benchmark::internal::Benchmark* b) {
  for (int n : kDriftSizes)
    for (int t : {1, 2}) b->Args({n, t});
  b->ArgNames({"keyframes", "threads"});
}
void ba_args(benchmark::internal::Benchmark* b) {
  for (int w : {0, 1})
    for (int t : {1, 2}) b->Args({w, t});
  b->ArgNames({"synthetic0_kitti1", "threads"});
}

}  // namespace

// Ceres twins are registered first: Google Benchmark runs in registration order, and ours read
// Ceres' times for the ratio counters.
#if GEODRIFT_HAVE_CERES
BENCHMARK(BM_Se3Graph_Ceres)
    ->Apply(graph_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#endif
BENCHMARK(BM_Se3Graph_Ours)
    ->Apply(graph_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Se3Graph_OursAccel)
    ->Apply(graph_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Floor_Se3Graph)
    ->DenseRange(0, 3)
    ->ArgName("graph")
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#if GEODRIFT_HAVE_CERES
BENCHMARK(BM_Sim3Drift_Ceres)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#endif
BENCHMARK(BM_Sim3Drift_Ours)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Sim3Drift_OursCholmod)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Sim3Drift_OursAccel)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#if GEODRIFT_HAVE_CERES
BENCHMARK(BM_Sim3Drift_CeresLowDamping)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#endif
BENCHMARK(BM_Sim3Drift_OursLowDamping)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Sim3Drift_OursAccelLowDamping)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Sim3Drift_OursAccelLowDampingCholmod)
    ->Apply(drift_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#if GEODRIFT_HAVE_CERES
BENCHMARK(BM_Sim3Drift_Paired)
    ->Args({10000, 1})
    ->Args({10000, 0})
    ->Args({50000, 1})
    ->Args({50000, 0})
    ->ArgNames({"keyframes", "fresh_memory"})
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#endif
BENCHMARK(BM_Linearize_Sim3Drift)->Arg(10000)->ArgName("keyframes")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Floor_Sim3Drift)
    ->Arg(1000)
    ->Arg(10000)
    ->Arg(50000)
    ->ArgName("keyframes")
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#if GEODRIFT_HAVE_CERES
BENCHMARK(BM_Ba_Ceres)
    ->Apply(ba_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
#endif
BENCHMARK(BM_Ba_Ours)
    ->Apply(ba_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Ba_OursAccel)
    ->Apply(ba_args)
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Floor_Ba)
    ->Arg(0)
    ->Arg(1)
    ->ArgName("synthetic0_kitti1")
    ->UseManualTime()
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

int main(int argc, char** argv) {
  if (const char* s = std::getenv("GEODRIFT_BENCH_DRIFT_SEED")) {
    const std::string v(s);
    if (v.empty() || v.size() > 9 || v.find_first_not_of("0123456789") != std::string::npos) {
      std::fprintf(stderr,
                   "bench_solver: GEODRIFT_BENCH_DRIFT_SEED must be a decimal integer in "
                   "0..999999999, got '%s'\n",
                   s);
      return 2;
    }
  }
  if (const char* s = std::getenv("GEODRIFT_BENCH_PAIRS")) {
    const std::string v(s);
    if (v.empty() || v.size() > 3 || v.find_first_not_of("0123456789") != std::string::npos ||
        std::atoi(s) < 1) {
      std::fprintf(
          stderr, "bench_solver: GEODRIFT_BENCH_PAIRS must be an integer in 1..999, got '%s'\n", s);
      return 2;
    }
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::AddCustomContext("drift_seed", std::to_string(drift_seed()));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
