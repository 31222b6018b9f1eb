#pragma once

/// @file
/// Pose-graph residuals on a Lie group (SE3d or Sim3d; any group with log(J*), adjoint(),
/// inverse(), operator*, times_inverse(), times_adjoint(), times_adjoint_into()). All Jacobians are
/// w.r.t. LEFT perturbations X ← exp(δ)·X, in the group's tangent order (SE3: (ω, ν); Sim3: (ω, σ,
/// ν)).

#include <Eigen/Core>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/sim3.hpp"

namespace geodrift::solver {

/// Relative-pose edge  r = log(dS_ij · S_i · S_j⁻¹) ∈ R^kDoF.
///
/// With world→body poses S_i = S_iw (DESIGN.md's S_cw), the measurement is
/// dS_ij = (S_i·S_j⁻¹)⁻¹ at the optimum, i.e. dS_ij = S_jw·S_iw⁻¹ frozen before optimisation
/// (the paper's e1/e2). For a g2o edge Z_ij = T_wi⁻¹·T_wj with vertices stored as T_iw = T_wi⁻¹:
/// dS_ij = Z_ij⁻¹, so r = log(Z_ij⁻¹·T_iw·T_jw⁻¹), and the information matrix must be in
/// (ω, ν) order.
///
///   J_r_Si = Jl⁻¹(r)·Ad(dS_ij)       (dS·exp(d)·S_i·S_j⁻¹ = exp(Ad(dS)·d)·E)
///   J_r_Sj = −Jl⁻¹(r)·Ad(E)          (E·exp(−d) = exp(−Ad(E)·d)·E),  E = dS_ij·S_i·S_j⁻¹
///          = −J_r_Si·Ad(G),  G = S_i·S_j⁻¹   (Ad(E) = Ad(dS_ij)·Ad(G))
/// The last form is declared to ResidualBlock (LinkGroup, linked()): H_ij, H_jj and g_j are
/// then accumulated from J̃_i alone (residual_block.hpp, "Linked Jacobians").
template <typename Group>
struct RelativePoseResidual {
  static constexpr int kNumResiduals = Group::kDoF;
  using Vec = Eigen::Matrix<double, Group::kDoF, 1>;
  using Mat = Eigen::Matrix<double, Group::kDoF, Group::kDoF>;
  using LinkGroup = Group;

  Group dS_ij;  ///< measurement (see above)

  bool operator()(const Group& S_i, const Group& S_j, Vec* r, Mat* J_r_Si = nullptr,
                  Mat* J_r_Sj = nullptr) const {
    const Group E = dS_ij * S_i.times_inverse(S_j);
    if (!J_r_Si && !J_r_Sj) {
      *r = E.log();
      return true;
    }
    Mat Jl_inv;
    *r = E.log(&Jl_inv);
    if (J_r_Si) *J_r_Si = dS_ij.times_adjoint(Jl_inv);  // Jl⁻¹·Ad(dS_ij)
    if (J_r_Sj) *J_r_Sj = -E.times_adjoint(Jl_inv);     // −Jl⁻¹·Ad(E)
    return true;
  }

  /// r and J_r_Si as operator(), and the link G = S_i·S_j⁻¹ with J_r_Sj = −J_r_Si·Ad(G).
  bool linked(const Group& S_i, const Group& S_j, Vec* r, Mat* J_r_Si, Group* G) const {
    *G = S_i.times_inverse(S_j);
    const Group E = dS_ij * (*G);
    Mat Jl_inv;
    *r = E.log(&Jl_inv);
    dS_ij.times_adjoint_into(Jl_inv, dS_ij.rotation().matrix(), J_r_Si);
    return true;
  }
};

/// Sim(3) relative-pose edge whose log-scale also sees a local scale offset per keyframe:
///   r = log(dS_ij · S_i · S_j⁻¹) − (u_i − u_j)·e_σ,
/// u_k ∈ R a log-scale offset of keyframe k (e_σ: the σ axis of the tangent (ω, σ, ν)). The
/// edge then charges only the part of the relative scale change that is not explained by the
/// offsets, whose own prior (LocalScaleLinkResidual) says how they vary along the path: a
/// random walk (this edge's σ information) plus a local, mean-reverting scale error (the
/// offsets), as correction/corrector.hpp's CorrectorOptions::local_scale_sd describes.
///   J_r_Si, J_r_Sj as RelativePoseResidual;  J_r_ui = −e_σ,  J_r_uj = +e_σ.
struct RelativeSim3LocalScaleResidual {
  static constexpr int kNumResiduals = 7;
  using Vec = Eigen::Matrix<double, 7, 1>;
  using Mat = Eigen::Matrix<double, 7, 7>;
  using MatU = Eigen::Matrix<double, 7, 1>;

  lie::Sim3d dS_ij;  ///< measurement, as RelativePoseResidual::dS_ij

  template <typename U>
  bool operator()(const lie::Sim3d& S_i, const lie::Sim3d& S_j, const U& u_i, const U& u_j, Vec* r,
                  Mat* J_r_Si = nullptr, Mat* J_r_Sj = nullptr, MatU* J_r_ui = nullptr,
                  MatU* J_r_uj = nullptr) const {
    if (!RelativePoseResidual<lie::Sim3d>{dS_ij}(S_i, S_j, r, J_r_Si, J_r_Sj)) return false;
    (*r)[3] -= u_i[0] - u_j[0];
    if (J_r_ui) *J_r_ui = -MatU::Unit(3);
    if (J_r_uj) *J_r_uj = MatU::Unit(3);
    return true;
  }
};

/// A first-order Gauss–Markov (Ornstein–Uhlenbeck) link between consecutive local scale
/// offsets: r = u_k − ρ·u_{k−1}, ρ = exp(−d/L) for keyframes d apart and a correlation length
/// L; with information 1/(s²·(1 − ρ²)) the offsets are stationary with SD s.
///   J_r_uprev = −ρ,  J_r_u = 1.
struct LocalScaleLinkResidual {
  static constexpr int kNumResiduals = 1;
  using Vec = Eigen::Matrix<double, 1, 1>;
  using Mat = Eigen::Matrix<double, 1, 1>;

  double rho = 0.0;  ///< exp(−d/L), in [0, 1)

  template <typename U>
  bool operator()(const U& u_prev, const U& u, Vec* r, Mat* J_r_uprev = nullptr,
                  Mat* J_r_u = nullptr) const {
    (*r)[0] = u[0] - rho * u_prev[0];
    if (J_r_uprev) (*J_r_uprev)(0, 0) = -rho;
    if (J_r_u) (*J_r_u)(0, 0) = 1.0;
    return true;
  }
};

/// Zero-mean prior on one local scale offset (the first keyframe's): r = u,  J_r_u = 1.
struct LocalScalePriorResidual {
  static constexpr int kNumResiduals = 1;
  using Vec = Eigen::Matrix<double, 1, 1>;
  using Mat = Eigen::Matrix<double, 1, 1>;

  template <typename U>
  bool operator()(const U& u, Vec* r, Mat* J_r_u = nullptr) const {
    (*r)[0] = u[0];
    if (J_r_u) (*J_r_u)(0, 0) = 1.0;
    return true;
  }
};

/// Prior on one pose  r = log(S · S_prior⁻¹),  J_r_S = Jl⁻¹(r).
template <typename Group>
struct PosePriorResidual {
  static constexpr int kNumResiduals = Group::kDoF;
  using Vec = Eigen::Matrix<double, Group::kDoF, 1>;
  using Mat = Eigen::Matrix<double, Group::kDoF, Group::kDoF>;

  Group S_prior;

  bool operator()(const Group& S, Vec* r, Mat* J_r_S = nullptr) const {
    const Group E = S.times_inverse(S_prior);
    *r = E.log(J_r_S);
    return true;
  }
};

/// Camera-centre prior for a world→camera pose S_cw (SE3 or Sim3):
/// r = c(S) − y, c = S⁻¹·0 = −(1/s)·Rᵀ·t (DESIGN.md), y a position in W (metres).
/// Left perturbation S ← exp(δ)·S gives c ← S⁻¹·exp(−δ)·0, so
///   J_r_S = −J_{S⁻¹·p}/∂p · ∂(exp(−δ)·0)/∂δ = −(R_S⁻¹·s⁻¹) · [0 (| 0) | I]   (the ν block).
template <typename Group>
struct CameraCentrePriorResidual {
  static constexpr int kNumResiduals = 3;
  using Vec = Eigen::Matrix<double, 3, 1>;
  using Mat = Eigen::Matrix<double, 3, Group::kDoF>;

  Eigen::Vector3d y;  ///< target position in W

  bool operator()(const Group& S, Vec* r, Mat* J_r_S = nullptr) const {
    const Group S_inv = S.inverse();
    Eigen::Matrix<double, 3, 3> J_p;
    const Eigen::Vector3d c = S_inv.act(Eigen::Vector3d::Zero(), nullptr, &J_p);
    *r = c - y;
    if (J_r_S) {
      // exp(δ)·0 to first order = ν (the translation part of δ).
      J_r_S->setZero();
      J_r_S->template rightCols<3>() = -J_p;
    }
    return true;
  }
};

}  // namespace geodrift::solver
