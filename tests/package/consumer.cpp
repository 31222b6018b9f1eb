// Uses the installed core the way a downstream project would: a Sim3 pose graph solved by the
// CHOLMOD-backed LM, a UTM local frame through GeographicLib, the version and error types.
#include <cmath>
#include <cstdio>
#include <geodrift/error.hpp>
#include <geodrift/geo/local_frame.hpp>
#include <geodrift/lie/sim3.hpp>
#include <geodrift/solver/levenberg_marquardt.hpp>
#include <geodrift/solver/problem.hpp>
#include <geodrift/solver/residuals/relative_pose.hpp>
#include <geodrift/version.hpp>
#include <vector>

int main() {
  using geodrift::lie::Sim3d;
  using geodrift::lie::SO3d;
  // A chain of 4 poses with one wrong initial value; the edges say "identity steps".
  std::vector<Sim3d> S(4);
  S[2] = Sim3d(SO3d::exp(Eigen::Vector3d(0.1, 0.0, 0.2)), Eigen::Vector3d(1, 2, 3), 1.3);
  geodrift::solver::Problem problem;
  for (int i = 0; i + 1 < 4; ++i)
    problem.add_residual_block(geodrift::solver::RelativePoseResidual<Sim3d>{Sim3d()},
                               geodrift::solver::RobustLoss(), 1.0, &S[i], &S[i + 1]);
  problem.set_constant(&S[0]);
  geodrift::solver::Options options;
  options.linear_solver = geodrift::solver::LinearSolverType::kCholmod;
  const auto summary = geodrift::solver::LevenbergMarquardt(options).solve(&problem);

  const auto frame = geodrift::geo::LocalFrame::from_geodetic(49.011, 8.417, 160.0);
  const Eigen::Vector3d p = frame.to_world(49.012, 8.418, 161.0);
  const auto back = frame.to_geodetic(p);

  std::printf("geodrift %s consumer: %s; final cost %.3g; UTM zone %s, round trip %.3g deg\n",
              geodrift::kVersion, summary.brief_report().c_str(), summary.final_cost,
              frame.zone_string().c_str(), std::abs(back.latitude_deg - 49.012));
  const bool ok = summary.converged() && summary.final_cost < 1e-20 &&
                  std::abs(back.latitude_deg - 49.012) < 1e-9 && frame.zone() == 32;
  return ok ? 0 : 1;
}
