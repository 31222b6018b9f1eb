#pragma once

/// @file
/// Ceres 2.1 twin of geodrift's SE(3) pose-graph problem (issue 3): the same states, residual,
/// weights, gauge and start as our solver, with analytic Jacobians.
///
///  - states: T_iw (world -> body) = inverse of the g2o vertex pose T_wi, stored in Ceres as
///    7 doubles [qx qy qz qw tx ty tz];
///  - edge residual: r = L·log(Z_ij⁻¹·T_i·T_j⁻¹) in (omega, nu) order, with L the square-root
///    weight of g2o's information reordered to (omega, nu)
///    (io::G2oEdgeSE3::sqrt_information_omega_nu()); cost ½ Σ ‖r‖² = ½ Σ rᵀΩr;
///  - manifold: Plus(x, d) = exp(d)·x (left perturbation). The cost function returns the
///    Jacobian w.r.t. the 6-dof left perturbation padded with a zero 7th column, and
///    PlusJacobian is [I6; 0], so Ceres' product J_ambient·PlusJacobian is exactly the tangent
///    Jacobian (no quaternion chain rule);
///  - gauge: the first vertex in file order is constant.

#include <ceres/ceres.h>

#include <memory>
#include <string>
#include <vector>

#include "geodrift/io/g2o.hpp"
#include "support/ref_se3.hpp"

namespace geodrift::bench {

/// Left-perturbation SE(3) manifold on [qx qy qz qw tx ty tz] storage.
class CeresSE3LeftManifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 7; }
  int TangentSize() const override { return 6; }

  static ref::SE3 load(const double* x) {
    ref::SE3 T;
    T.q = Eigen::Quaterniond(x[3], x[0], x[1], x[2]);
    T.t = Eigen::Vector3d(x[4], x[5], x[6]);
    return T;
  }
  static void store(const ref::SE3& T, double* x) {
    x[0] = T.q.x();
    x[1] = T.q.y();
    x[2] = T.q.z();
    x[3] = T.q.w();
    x[4] = T.t.x();
    x[5] = T.t.y();
    x[6] = T.t.z();
  }

  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    ref::SE3 T = ref::SE3::exp(Eigen::Map<const ref::Vec6>(delta)) * load(x);
    T.q.normalize();
    store(T, x_plus_delta);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.topRows<6>().setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<ref::Vec6> out(y_minus_x);
    out = (load(y) * load(x).inverse()).log();
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.leftCols<6>().setIdentity();
    return true;
  }
};

/// r = L·log(Z⁻¹·T_i·T_j⁻¹), analytic Jacobians (see ref::relative_pose_residual).
class CeresSE3EdgeCost final : public ceres::SizedCostFunction<6, 7, 7> {
 public:
  CeresSE3EdgeCost(const ref::SE3& Z_ij, const ref::Mat6& sqrt_information)
      : Z_inv_(Z_ij.inverse()), L_(sqrt_information) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const ref::SE3 T_i = CeresSE3LeftManifold::load(parameters[0]);
    const ref::SE3 T_j = CeresSE3LeftManifold::load(parameters[1]);
    const bool want_i = jacobians && jacobians[0], want_j = jacobians && jacobians[1];
    ref::Mat6 J_i, J_j;
    const ref::Vec6 r = ref::relative_pose_residual(Z_inv_, T_i, T_j, want_i ? &J_i : nullptr,
                                                    want_j ? &J_j : nullptr);
    Eigen::Map<ref::Vec6> res(residuals);
    res = L_ * r;
    if (want_i) write(L_ * J_i, jacobians[0]);
    if (want_j) write(L_ * J_j, jacobians[1]);
    return true;
  }

 private:
  static void write(const ref::Mat6& J, double* out) {
    Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> M(out);
    M.leftCols<6>() = J;
    M.col(6).setZero();
  }
  ref::SE3 Z_inv_;
  ref::Mat6 L_;
};

/// g2o vertex / edge as ref::SE3.
inline ref::SE3 to_ref_se3(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) {
  ref::SE3 T;
  T.q = q.normalized();
  T.t = t;
  return T;
}

/// Initial states T_iw (= T_wi⁻¹ from the file), in vertex order.
inline std::vector<ref::SE3> initial_states_T_iw(const io::G2oPoseGraph3D& g) {
  std::vector<ref::SE3> out;
  out.reserve(g.vertices.size());
  for (const io::G2oVertexSE3& v : g.vertices) out.push_back(to_ref_se3(v.q_wi, v.t_wi).inverse());
  return out;
}

/// The pose graph as a Ceres problem over `storage` (7 doubles per vertex, filled from
/// `states`). The problem does not own the manifold (one shared instance, kept alive by the
/// returned holder).
struct CeresSE3Graph {
  std::vector<double> storage;
  std::unique_ptr<CeresSE3LeftManifold> manifold = std::make_unique<CeresSE3LeftManifold>();
  std::unique_ptr<ceres::Problem> problem;

  CeresSE3Graph(const io::G2oPoseGraph3D& g, const std::vector<ref::SE3>& states) {
    storage.resize(7 * g.vertices.size());
    for (std::size_t k = 0; k < states.size(); ++k) {
      CeresSE3LeftManifold::store(states[k], &storage[7 * k]);
    }
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(po);
    for (std::size_t k = 0; k < g.vertices.size(); ++k) {
      problem->AddParameterBlock(&storage[7 * k], 7, manifold.get());
    }
    for (const io::G2oEdgeSE3& e : g.edges) {
      auto* cost = new CeresSE3EdgeCost(to_ref_se3(e.q_ij, e.t_ij), e.sqrt_information_omega_nu());
      problem->AddResidualBlock(cost, nullptr, &storage[7 * static_cast<std::size_t>(g.index(e.i))],
                                &storage[7 * static_cast<std::size_t>(g.index(e.j))]);
    }
    problem->SetParameterBlockConstant(&storage[0]);
  }

  std::vector<ref::SE3> states() const {
    std::vector<ref::SE3> out(storage.size() / 7);
    for (std::size_t k = 0; k < out.size(); ++k)
      out[k] = CeresSE3LeftManifold::load(&storage[7 * k]);
    return out;
  }
};

/// Cost ½ Σ ‖L·r‖² of the graph at `states` (T_iw), evaluated without Ceres.
inline double se3_graph_cost(const io::G2oPoseGraph3D& g, const std::vector<ref::SE3>& states) {
  double cost = 0.0;
  for (const io::G2oEdgeSE3& e : g.edges) {
    const ref::Vec6 r = e.sqrt_information_omega_nu() *
                        ref::relative_pose_residual(to_ref_se3(e.q_ij, e.t_ij).inverse(),
                                                    states[static_cast<std::size_t>(g.index(e.i))],
                                                    states[static_cast<std::size_t>(g.index(e.j))],
                                                    nullptr, nullptr);
    cost += 0.5 * r.squaredNorm();
  }
  return cost;
}

/// Ceres options for pose graphs: LM, SPARSE_NORMAL_CHOLESKY on SuiteSparse (CHOLMOD).
inline ceres::Solver::Options ceres_pose_graph_options(int threads, int max_iterations,
                                                       double function_tolerance,
                                                       double gradient_tolerance,
                                                       double parameter_tolerance) {
  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  o.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  o.num_threads = threads;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = function_tolerance;
  o.gradient_tolerance = gradient_tolerance;
  o.parameter_tolerance = parameter_tolerance;
  o.minimizer_progress_to_stdout = false;
  o.logging_type = ceres::SILENT;
  return o;
}

}  // namespace geodrift::bench
