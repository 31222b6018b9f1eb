#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "geodrift/map/camera.hpp"

namespace geodrift::sim::detail {

/// Result of refine_pose_lm().
struct PnpResult {
  Eigen::Isometry3d T_cw = Eigen::Isometry3d::Identity();  ///< world -> camera
  double rms_px = 0.0;                                     ///< reprojection RMS at the solution
  int iterations = 0;
  bool converged = false;
};

/// Levenberg–Marquardt refinement of a camera pose from 3D–2D correspondences, minimising
/// Σ |π(T_cw·X_i) − u_i|² (pixels). A small self-contained solver for the simulator (the
/// geo view's PnP+LM step of the paper, Sec. 3.2), so that sim/ does not depend on solver/.
/// Update T ← (Exp(ω)·R, Exp(ω)·t + ν): a retraction with the same first order as the left
/// perturbation exp(δ)·T, δ = (ω, ν); ∂(T·X)/∂δ = [−[p]x | I], p = T·X.
/// Points behind the camera during an iteration make the step rejected.
inline PnpResult refine_pose_lm(const std::vector<Eigen::Vector3d>& X,
                                const std::vector<Eigen::Vector2d>& u, const map::Camera& cam,
                                const Eigen::Isometry3d& T_init, int max_iterations = 30) {
  const auto cost_of = [&](const Eigen::Isometry3d& T, bool* ok) {
    double c = 0.0;
    *ok = true;
    for (std::size_t i = 0; i < X.size(); ++i) {
      const Eigen::Vector3d p = T * X[i];
      if (p.z() <= 1e-9) {
        *ok = false;
        return 0.0;
      }
      c += (cam.project(p) - u[i]).squaredNorm();
    }
    return c;
  };
  PnpResult res;
  Eigen::Isometry3d T = T_init;
  bool ok = false;
  double cost = cost_of(T, &ok);
  double lambda = 1e-4;
  for (int it = 0; it < max_iterations && ok; ++it) {
    res.iterations = it + 1;
    Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t i = 0; i < X.size(); ++i) {
      const Eigen::Vector3d p = T * X[i];
      const double iz = 1.0 / p.z();
      Eigen::Matrix<double, 2, 3> J_uv_p;
      J_uv_p << cam.fx * iz, 0.0, -cam.fx * p.x() * iz * iz, 0.0, cam.fy * iz,
          -cam.fy * p.y() * iz * iz;
      Eigen::Matrix<double, 3, 6> J_p_d;
      J_p_d << 0.0, p.z(), -p.y(), 1.0, 0.0, 0.0,  //
          -p.z(), 0.0, p.x(), 0.0, 1.0, 0.0,       //
          p.y(), -p.x(), 0.0, 0.0, 0.0, 1.0;
      const Eigen::Matrix<double, 2, 6> J = J_uv_p * J_p_d;
      const Eigen::Vector2d r = cam.project(p) - u[i];
      H.noalias() += J.transpose() * J;
      g.noalias() += J.transpose() * r;
    }
    bool accepted = false;
    for (int tries = 0; tries < 10 && !accepted; ++tries) {
      Eigen::Matrix<double, 6, 6> A = H;
      A.diagonal() += lambda * H.diagonal().cwiseMax(1e-9);
      const Eigen::Matrix<double, 6, 1> d = -A.ldlt().solve(g);
      const Eigen::Vector3d w = d.head<3>();
      const double angle = w.norm();
      const Eigen::Matrix3d dR = angle > 0 ? Eigen::AngleAxisd(angle, w / angle).toRotationMatrix()
                                           : Eigen::Matrix3d::Identity();
      Eigen::Isometry3d Tn = Eigen::Isometry3d::Identity();
      Tn.linear() = dR * T.linear();
      Tn.translation() = dR * T.translation() + d.tail<3>();
      bool ok_n = false;
      const double cn = cost_of(Tn, &ok_n);
      if (ok_n && cn <= cost) {
        const double rel = (cost - cn) / std::max(cost, 1e-300);
        T = Tn;
        cost = cn;
        lambda = std::max(lambda / 10.0, 1e-12);
        accepted = true;
        if (rel < 1e-12 || d.norm() < 1e-12) res.converged = true;
      } else {
        lambda *= 10.0;
      }
    }
    if (!accepted) {
      res.converged = true;  // no descent left at this precision
      break;
    }
    if (res.converged) break;
  }
  res.T_cw = T;
  res.rms_px = X.empty() ? 0.0 : std::sqrt(cost / static_cast<double>(X.size()));
  return res;
}

}  // namespace geodrift::sim::detail
