// drift_phases: where one fresh-memory solve of bench_solver's Sim(3) drift graph spends its CPU,
// phase by phase: problem construction, finalize (column layout, pattern), H's first touch,
// the geodesic-acceleration store's first touch, a linearisation with and without keeping that
// store, a cost-only evaluation and one acceleration right-hand side. Every round releases the
// solver's kept large arrays first (release_large_array_cache(), as BM_Sim3Drift_Paired's
// fresh_memory:1), so the two first touches are those of a fresh process. Not a Google
// Benchmark: the interesting numbers are the first touches, which repetitions would hide.
//
// usage: drift_phases [keyframes = 10000] [rounds = 5] [seed = 7, the benchmark's]
//   prints one line per round, CPU milliseconds per phase (std::clock, the whole process).
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include "support/bench_options.hpp"
#include "support/drift_graph.hpp"
#include "support/our_problems.hpp"

int main(int argc, char** argv) {
  namespace gb = geodrift::bench;
  namespace solver = geodrift::solver;
  const int n = argc > 1 ? std::atoi(argv[1]) : 10000;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 5;
  const long seed = argc > 3 ? std::atol(argv[3]) : static_cast<long>(gb::kSeed);
  if (n < 10 || n > 1000000 || rounds < 1 || rounds > 100 || seed < 0) {
    std::fprintf(stderr,
                 "usage: drift_phases [keyframes in 10..1000000] [rounds in 1..100] [seed >= 0]\n");
    return 2;
  }
  const gb::DriftGraph g = gb::make_drift_graph(n, static_cast<unsigned>(seed));
  const auto cpu_ms = [] { return 1e3 * static_cast<double>(std::clock()) / CLOCKS_PER_SEC; };
  for (int r = 0; r < rounds; ++r) {
    solver::release_large_array_cache();
    double t = cpu_ms();
    const auto lap = [&](const char* name) {
      const double now = cpu_ms();
      std::printf("%s %.1f  ", name, now - t);
      t = now;
    };
    gb::OurDriftGraph p(g);
    lap("build");
    p.problem.finalize(false);
    lap("finalize");
    solver::BlockSparseMatrix H;
    H.reset(&p.problem.structure());
    lap("H_first_touch");
    const int cols = p.problem.structure().num_cols();
    Eigen::VectorXd grad(cols), v = Eigen::VectorXd::Constant(cols, 1e-4), rhs(cols);
    p.problem.reserve_acceleration(true);
    lap("accel_store_first_touch");
    solver::LinearizeTimes lt;
    double cost = 0.0;
    bool ok = p.problem.linearize(&H, grad.data(), &cost, &lt, nullptr, true);
    lap("linearize_1st");
    ok = ok && p.problem.linearize(&H, grad.data(), &cost, &lt, nullptr, true);
    lap("linearize_keep_store");
    ok = ok && p.problem.linearize(&H, grad.data(), &cost, &lt, nullptr, false);
    lap("linearize_no_store");
    ok = ok && p.problem.evaluate_cost(&cost);
    lap("cost_only");
    ok = ok && p.problem.acceleration_rhs(v.data(), 0.1, rhs.data());
    lap("acceleration_rhs");
    std::printf("\n");
    if (!ok) {
      std::fprintf(stderr, "drift_phases: an evaluation failed\n");
      return 1;
    }
  }
  return 0;
}
