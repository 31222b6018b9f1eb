// drift_trace: one accelerated LM solve of bench_solver's Sim(3) drift graph in a fresh process,
// with its per-iteration trace (cost, accepted, λ, wall and CPU seconds since solve() started).
// Where bench_solver's rows follow each other in one process (and reuse or inherit each other's
// memory), this is the solve a user runs once: the fresh-process A/B of round 7 of
// BENCHMARKS.md's history (`git show 3d5878d:BENCHMARKS.md`).
//
// usage: drift_trace [keyframes = 10000] [lambda0 = 1e-8] [seed = 7, the benchmark's]
//   GEODRIFT_HUGE_PAGES=1 puts the solver's large arrays on huge pages (large_array_allocator.hpp).
#include <cstdio>
#include <cstdlib>
#include <string>

#include "support/bench_options.hpp"
#include "support/drift_graph.hpp"
#include "support/our_problems.hpp"

int main(int argc, char** argv) {
  namespace gb = geodrift::bench;
  namespace solver = geodrift::solver;
  const int n = argc > 1 ? std::atoi(argv[1]) : 10000;
  const double lambda0 = argc > 2 ? std::atof(argv[2]) : gb::kLowDampingLambda;
  const long seed = argc > 3 ? std::atol(argv[3]) : static_cast<long>(gb::kSeed);
  if (n < 10 || n > 1000000 || !(lambda0 > 0.0) || seed < 0) {
    std::fprintf(stderr,
                 "usage: drift_trace [keyframes in 10..1000000] [lambda0 > 0] [seed >= 0]\n");
    return 2;
  }
  gb::OurDriftGraph p(gb::make_drift_graph(n, static_cast<unsigned>(seed)));
  solver::LevenbergMarquardt lm(gb::accel_options(solver::LinearSolverType::kAuto, 1, lambda0));
  const solver::Summary s = lm.solve(&p.problem);
  std::printf("%s\nhuge pages: %s\n", s.brief_report().c_str(),
              solver::large_array_huge_pages_enabled() ? "yes" : "no");
  for (const solver::IterationRecord& r : s.trace)
    std::printf("iteration %2d  cost %.10g  %s  lambda %.3g  wall %.3f s  cpu %.3f s\n",
                r.iteration, r.cost, r.accepted ? "accepted" : "rejected", r.lambda, r.time_wall,
                r.time_cpu);
  return s.converged() ? 0 : 1;
}
