// Ceres 2.1 reference solve of the SE(3) g2o pose graphs (issue 3): prints a summary whose
// `final_cost` line tests/solver_data compares our solver against. Built by the standalone
// CMake project in this folder (bench/reference/regenerate.sh), only where Ceres is installed.
//
// usage: ceres_reference <graph.g2o> [threads] [max_iterations] [tolerance]
// (function, gradient and parameter tolerance; default 1e-14)
#include <ceres/ceres.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "geodrift/io/g2o.hpp"
#include "geodrift/version.hpp"
#include "support/ceres_se3_graph.hpp"

namespace {
std::string base_name(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
  const std::size_t dot = name.rfind(".g2o");
  return dot == std::string::npos ? name : name.substr(0, dot);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s <graph.g2o> [threads]\n", argv[0]);
    return 2;
  }
  try {
    namespace gb = geodrift::bench;
    const int threads = argc > 2 ? std::atoi(argv[2]) : 1;
    const int max_iterations = argc > 3 ? std::atoi(argv[3]) : 200;
    const double tolerance = argc > 4 ? std::atof(argv[4]) : 1e-14;
    const geodrift::io::G2oPoseGraph3D g = geodrift::io::read_g2o_se3(argv[1]);
    const std::vector<gb::ref::SE3> start = gb::initial_states_T_iw(g);
    gb::CeresSE3Graph problem(g, start);
    // Tight tolerances: the final cost is the optimum the tests compare against, not a
    // benchmark stopping rule.
    const ceres::Solver::Options options =
        gb::ceres_pose_graph_options(threads, max_iterations, tolerance, tolerance, tolerance);
    ceres::Solver::Summary summary;
    const auto t0 = std::chrono::steady_clock::now();
    ceres::Solve(options, problem.problem.get(), &summary);
    const double wall =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double check_initial = gb::se3_graph_cost(g, start);
    const double check_final = gb::se3_graph_cost(g, problem.states());

    std::printf(
        "# Ceres %s reference solve of %s.g2o for geodrift (bench/reference/regenerate.sh)\n",
        CERES_VERSION_STRING, base_name(argv[1]).c_str());
    std::printf(
        "# states T_iw (world->body) = inverse g2o vertex poses; r = L log(Z_ij^-1 T_i T_j^-1)\n"
        "# in (omega, nu) order, L = sqrt of g2o information reordered to (omega, nu)\n"
        "# (nearest PSD where indefinite); cost = 1/2 sum |r|^2; first vertex fixed;\n"
        "# LM, SPARSE_NORMAL_CHOLESKY, SUITE_SPARSE, analytic Jacobians, tolerances %g,\n"
        "# max %d iterations, start = the file's vertex values.\n",
        tolerance, max_iterations);
    std::printf("graph %s\n", base_name(argv[1]).c_str());
    std::printf("vertices %zu\nedges %zu\nindefinite_information %d\n", g.vertices.size(),
                g.edges.size(), g.num_indefinite_information);
    std::printf("threads %d\n", threads);
    std::printf("initial_cost %.17g\n", summary.initial_cost);
    std::printf("final_cost %.17g\n", summary.final_cost);
    std::printf("initial_cost_recomputed %.17g\n", check_initial);
    std::printf("final_cost_recomputed %.17g\n", check_final);
    std::printf("iterations %d\n", summary.num_successful_steps + summary.num_unsuccessful_steps);
    std::printf("successful_steps %d\nunsuccessful_steps %d\n", summary.num_successful_steps,
                summary.num_unsuccessful_steps);
    std::printf("termination %s\n", ceres::TerminationTypeToString(summary.termination_type));
    std::printf("message %s\n", summary.message.c_str());
    std::printf("total_time_s %.4f\nwall_time_s %.4f\n", summary.total_time_in_seconds, wall);
    std::printf(
        "linear_solver_time_s %.4f\nresidual_jacobian_time_s %.4f\n",
        summary.linear_solver_time_in_seconds,
        summary.residual_evaluation_time_in_seconds + summary.jacobian_evaluation_time_in_seconds);
    std::printf("\n# iteration cost gradient_max_norm step_norm trust_region_radius step_ok\n");
    for (const ceres::IterationSummary& it : summary.iterations) {
      std::printf("trace %d %.17g %.6e %.6e %.6e %d\n", it.iteration, it.cost, it.gradient_max_norm,
                  it.step_norm, it.trust_region_radius, it.step_is_successful ? 1 : 0);
    }
    std::printf("\n%s\n", summary.FullReport().c_str());
    return summary.IsSolutionUsable() ? 0 : 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
