// The synthetic monocular-drift Sim(3) graph of the benchmarks (bench/support/drift_graph.hpp):
// the block Cholesky (kAuto's choice here) and CHOLMOD reach the same optimum from the same
// start, with and without speculative linearisation.

#include "support/drift_graph.hpp"

#include <algorithm>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/levenberg_marquardt.hpp"
#include "geodrift/solver/problem.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"

using namespace geodrift;

namespace {

bool reduced_run() {
  const char* ci = std::getenv("CI");
  const char* r = std::getenv("GEODRIFT_REDUCED");
  return (ci && std::string(ci) == "true") || (r && std::string(r) == "1");
}

struct Solved {
  solver::Summary summary;
  std::vector<lie::Sim3d> poses;
};

Solved solve(const bench::DriftGraph& g, solver::LinearSolverType type, bool speculative) {
  Solved out;
  out.poses = g.initial;
  solver::Problem p;
  for (const auto& e : g.edges)
    p.add_residual_block(solver::RelativePoseResidual<lie::Sim3d>{e.dS_ij}, solver::RobustLoss(),
                         g.edge_weight, &out.poses[static_cast<std::size_t>(e.i)],
                         &out.poses[static_cast<std::size_t>(e.j)]);
  for (const auto& pr : g.priors) {
    solver::CameraCentrePriorResidual<lie::Sim3d> f;
    f.y = pr.y;
    p.add_residual_block(f, solver::RobustLoss(), g.prior_weight,
                         &out.poses[static_cast<std::size_t>(pr.i)]);
  }
  solver::Options o;
  o.linear_solver = type;
  o.speculative_linearization = speculative;
  o.max_iterations = 100;
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-12;
  solver::LevenbergMarquardt lm(o);
  out.summary = lm.solve(&p);
  return out;
}

}  // namespace

TEST_CASE("Drift graph: block Cholesky and CHOLMOD reach the same optimum",
          "[solver_data][block_cholesky][slow]") {
  const int n = reduced_run() ? 300 : 2000;
  const bench::DriftGraph g = bench::make_drift_graph(n, 7);
  const Solved chol = solve(g, solver::LinearSolverType::kCholmod, true);
  const Solved block = solve(g, solver::LinearSolverType::kAuto, true);
  const Solved block_plain = solve(g, solver::LinearSolverType::kBlockCholesky, false);
  INFO(chol.summary.brief_report() << "\n"
                                   << block.summary.brief_report() << "\n"
                                   << block_plain.summary.brief_report());
  CHECK(block.summary.linear_solver == "block-cholesky");
  for (const Solved* s : {&chol, &block, &block_plain}) {
    CHECK(s->summary.converged());
    // 2000 kf: 20002 -> 5415; 300 kf (reduced): 1113 -> 763
    CHECK(s->summary.final_cost < 0.7 * s->summary.initial_cost);
  }
  CHECK(block.summary.final_cost == Approx(chol.summary.final_cost).epsilon(1e-10));
  CHECK(block_plain.summary.final_cost == Approx(chol.summary.final_cost).epsilon(1e-10));
  // Camera centres (metres; the trajectory spans kilometres) and log-scales agree.
  double worst_c = 0.0, worst_s = 0.0;
  for (std::size_t k = 0; k < chol.poses.size(); ++k) {
    const auto centre = [](const lie::Sim3d& S) { return S.inverse().translation(); };
    worst_c = std::max(worst_c, (centre(block.poses[k]) - centre(chol.poses[k])).norm());
    worst_c = std::max(worst_c, (centre(block_plain.poses[k]) - centre(chol.poses[k])).norm());
    worst_s = std::max(worst_s, std::abs(std::log(block.poses[k].scale() / chol.poses[k].scale())));
  }
  // 1e-5 m: where the function-tolerance stops of the three runs land (measured 3e-6 m at 300 kf);
  // a wrong factorisation or step is off by far more than a millimetre.
  CHECK(worst_c < 1e-5);
  CHECK(worst_s < 1e-8);  // the two stops (function / parameter tolerance) differ by ~2e-9
}
