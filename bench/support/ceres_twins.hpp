#pragma once

/// @file
/// Ceres 2.1 twins of the Sim(3) drift graph and of bundle adjustment. Each Ceres cost function
/// evaluates geodrift's own residual functor (solver::RelativePoseResidual<lie::Sim3d>,
/// solver::CameraCentrePriorResidual<lie::Sim3d>, solver::ReprojectionResidual) with its
/// analytic Jacobians, so both solvers minimise exactly the same function from the same start.
///
/// Storage and manifolds: Sim(3) as [qx qy qz qw tx ty tz s] (8), SE(3) as [qx qy qz qw tx ty tz]
/// (7); Plus(x, d) = exp(d)·x (left perturbation); cost functions return the tangent Jacobian
/// padded with zero columns and PlusJacobian is [I; 0], so Ceres' J·PlusJacobian is the tangent
/// Jacobian. Points are plain R^3 blocks.

#include <ceres/ceres.h>

#include <memory>
#include <vector>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"
#include "geodrift/solver/residuals/relative_pose.hpp"
#include "geodrift/solver/residuals/reprojection.hpp"
#include "support/ba_data.hpp"
#include "support/drift_graph.hpp"

namespace geodrift::bench {

/// Left-perturbation manifold for a group G stored as [q (4, xyzw) t (3) (s)].
template <typename G>
class CeresLeftManifold final : public ceres::Manifold {
 public:
  static constexpr bool kSim3 = std::is_same<G, lie::Sim3d>::value;
  static constexpr int kAmbient = kSim3 ? 8 : 7;
  static constexpr int kDoF = G::kDoF;

  int AmbientSize() const override { return kAmbient; }
  int TangentSize() const override { return kDoF; }

  static G load(const double* x) {
    const lie::SO3d R(Eigen::Quaterniond(x[3], x[0], x[1], x[2]));
    const Eigen::Vector3d t(x[4], x[5], x[6]);
    if constexpr (kSim3) {
      return G(R, t, x[7]);
    } else {
      return G(R, t);
    }
  }
  static void store(const G& X, double* x) {
    const Eigen::Quaterniond& q = X.rotation().quaternion();
    x[0] = q.x();
    x[1] = q.y();
    x[2] = q.z();
    x[3] = q.w();
    x[4] = X.translation().x();
    x[5] = X.translation().y();
    x[6] = X.translation().z();
    if constexpr (kSim3) x[7] = X.scale();
  }

  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    const typename G::Tangent d = Eigen::Map<const typename G::Tangent>(delta);
    store(G::exp(d) * load(x), x_plus_delta);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, kAmbient, kDoF, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.template topRows<kDoF>().setIdentity();
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    Eigen::Map<typename G::Tangent> out(y_minus_x);
    out = (load(y) * load(x).inverse()).log();
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    Eigen::Map<Eigen::Matrix<double, kDoF, kAmbient, Eigen::RowMajor>> J(jacobian);
    J.setZero();
    J.template leftCols<kDoF>().setIdentity();
    return true;
  }
};

using CeresSim3Manifold = CeresLeftManifold<lie::Sim3d>;
using CeresSE3Manifold = CeresLeftManifold<lie::SE3d>;

/// √w·log(dS_ij·S_i·S_j⁻¹) on Sim(3).
class CeresSim3EdgeCost final : public ceres::SizedCostFunction<7, 8, 8> {
 public:
  CeresSim3EdgeCost(const lie::Sim3d& dS, double weight) : f_{dS}, w_(std::sqrt(weight)) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const lie::Sim3d Si = CeresSim3Manifold::load(p[0]), Sj = CeresSim3Manifold::load(p[1]);
    Eigen::Matrix<double, 7, 1> r;
    Eigen::Matrix<double, 7, 7> Ji, Jj;
    const bool want_i = jac && jac[0], want_j = jac && jac[1];
    if (!f_(Si, Sj, &r, want_i ? &Ji : nullptr, want_j ? &Jj : nullptr)) return false;
    Eigen::Map<Eigen::Matrix<double, 7, 1>> res(residuals);
    res = w_ * r;
    if (want_i) write(Ji, jac[0]);
    if (want_j) write(Jj, jac[1]);
    return true;
  }

 private:
  void write(const Eigen::Matrix<double, 7, 7>& J, double* out) const {
    Eigen::Map<Eigen::Matrix<double, 7, 8, Eigen::RowMajor>> M(out);
    M.leftCols<7>() = w_ * J;
    M.col(7).setZero();
  }
  solver::RelativePoseResidual<lie::Sim3d> f_;
  double w_;
};

/// √w·(c(S) − y) on Sim(3).
class CeresSim3CentrePriorCost final : public ceres::SizedCostFunction<3, 8> {
 public:
  CeresSim3CentrePriorCost(const Eigen::Vector3d& y, double weight) : w_(std::sqrt(weight)) {
    f_.y = y;
  }
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const lie::Sim3d S = CeresSim3Manifold::load(p[0]);
    Eigen::Vector3d r;
    Eigen::Matrix<double, 3, 7> J;
    const bool want = jac && jac[0];
    if (!f_(S, &r, want ? &J : nullptr)) return false;
    Eigen::Map<Eigen::Vector3d> res(residuals);
    res = w_ * r;
    if (want) {
      Eigen::Map<Eigen::Matrix<double, 3, 8, Eigen::RowMajor>> M(jac[0]);
      M.leftCols<7>() = w_ * J;
      M.col(7).setZero();
    }
    return true;
  }

 private:
  solver::CameraCentrePriorResidual<lie::Sim3d> f_;
  double w_;
};

/// π(T_cw·X) − uv.
class CeresReprojectionCost final : public ceres::SizedCostFunction<2, 7, 3> {
 public:
  explicit CeresReprojectionCost(const solver::ReprojectionResidual& f) : f_(f) {}
  bool Evaluate(double const* const* p, double* residuals, double** jac) const override {
    const lie::SE3d T = CeresSE3Manifold::load(p[0]);
    const Eigen::Vector3d X(p[1][0], p[1][1], p[1][2]);
    Eigen::Vector2d r;
    Eigen::Matrix<double, 2, 6> JT;
    Eigen::Matrix<double, 2, 3> JX;
    const bool want_T = jac && jac[0], want_X = jac && jac[1];
    if (!f_(T, X, &r, want_T ? &JT : nullptr, want_X ? &JX : nullptr)) return false;
    residuals[0] = r[0];
    residuals[1] = r[1];
    if (want_T) {
      Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> M(jac[0]);
      M.leftCols<6>() = JT;
      M.col(6).setZero();
    }
    if (want_X) {
      Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> M(jac[1]);
      M = JX;
    }
    return true;
  }

 private:
  solver::ReprojectionResidual f_;
};

/// The drift graph as a Ceres problem (states copied from `start`).
struct CeresDriftGraph {
  std::vector<double> storage;
  std::unique_ptr<CeresSim3Manifold> manifold = std::make_unique<CeresSim3Manifold>();
  std::unique_ptr<ceres::Problem> problem;

  CeresDriftGraph(const DriftGraph& g, const std::vector<lie::Sim3d>& start) {
    storage.resize(8 * start.size());
    for (std::size_t k = 0; k < start.size(); ++k)
      CeresSim3Manifold::store(start[k], &storage[8 * k]);
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(po);
    for (std::size_t k = 0; k < start.size(); ++k) {
      problem->AddParameterBlock(&storage[8 * k], 8, manifold.get());
    }
    for (const DriftGraph::Edge& e : g.edges) {
      problem->AddResidualBlock(new CeresSim3EdgeCost(e.dS_ij, g.edge_weight), nullptr,
                                &storage[8 * static_cast<std::size_t>(e.i)],
                                &storage[8 * static_cast<std::size_t>(e.j)]);
    }
    for (const DriftGraph::Prior& p : g.priors) {
      problem->AddResidualBlock(new CeresSim3CentrePriorCost(p.y, g.prior_weight), nullptr,
                                &storage[8 * static_cast<std::size_t>(p.i)]);
    }
  }
};

/// A BA problem in Ceres (states copied from the data's start values).
struct CeresBa {
  std::vector<double> cams, pts;
  std::unique_ptr<CeresSE3Manifold> manifold = std::make_unique<CeresSE3Manifold>();
  std::unique_ptr<ceres::Problem> problem;

  explicit CeresBa(const BaData& d) {
    cams.resize(7 * d.poses.size());
    pts.resize(3 * d.points.size());
    for (std::size_t k = 0; k < d.poses.size(); ++k)
      CeresSE3Manifold::store(d.poses[k], &cams[7 * k]);
    for (std::size_t k = 0; k < d.points.size(); ++k) {
      for (int a = 0; a < 3; ++a) pts[3 * k + static_cast<std::size_t>(a)] = d.points[k][a];
    }
    ceres::Problem::Options po;
    po.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    po.loss_function_ownership = ceres::TAKE_OWNERSHIP;
    problem = std::make_unique<ceres::Problem>(po);
    for (std::size_t k = 0; k < d.poses.size(); ++k) {
      problem->AddParameterBlock(&cams[7 * k], 7, manifold.get());
    }
    for (const BaData::Obs& o : d.observations) {
      solver::ReprojectionResidual f;
      f.fx = d.fx;
      f.fy = d.fy;
      f.cx = d.cx;
      f.cy = d.cy;
      f.uv = o.uv;
      problem->AddResidualBlock(new CeresReprojectionCost(f),
                                d.huber > 0 ? new ceres::HuberLoss(d.huber) : nullptr,
                                &cams[7 * static_cast<std::size_t>(o.camera)],
                                &pts[3 * static_cast<std::size_t>(o.point)]);
    }
    for (const int c : d.fixed_cameras) {
      problem->SetParameterBlockConstant(&cams[7 * static_cast<std::size_t>(c)]);
    }
  }

  /// Ceres SPARSE_SCHUR ordering: points (group 0) eliminated first, cameras second.
  std::shared_ptr<ceres::ParameterBlockOrdering> ordering() {
    auto o = std::make_shared<ceres::ParameterBlockOrdering>();
    for (std::size_t k = 0; k < pts.size(); k += 3) o->AddElementToGroup(&pts[k], 0);
    for (std::size_t k = 0; k < cams.size(); k += 7) o->AddElementToGroup(&cams[k], 1);
    return o;
  }
};

/// Ceres LM options with a stopping rule shared with our LM (bench_solver.cpp).
inline ceres::Solver::Options ceres_lm_options(ceres::LinearSolverType type, int threads,
                                               int max_iterations, double function_tolerance,
                                               double gradient_tolerance,
                                               double parameter_tolerance) {
  ceres::Solver::Options o;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.linear_solver_type = type;
  o.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  o.num_threads = threads;
  o.max_num_iterations = max_iterations;
  o.function_tolerance = function_tolerance;
  o.gradient_tolerance = gradient_tolerance;
  o.parameter_tolerance = parameter_tolerance;
  o.logging_type = ceres::SILENT;
  return o;
}

}  // namespace geodrift::bench
