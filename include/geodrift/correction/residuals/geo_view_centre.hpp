#pragma once

/// @file
/// GeoViewCentreResidual: the BA geo term (paper eq. (9)), r = c_view − y_w in metres (W), the
/// geo view's camera centre tied to its keyframe's metric pose T_kw (world -> camera, SE(3)).
/// Jacobian w.r.t. the LEFT perturbation T ← exp(δ)·T, tangent (ω, ν).

#include <Eigen/Core>

#include "geodrift/lie/se3.hpp"
#include "geodrift/lie/so3.hpp"

namespace geodrift::correction {

/// BA geo term (paper Sec. 3.6, eq. (9); DESIGN.md "Correction" step 3): the geo view's camera
/// centre minus its geo-tag position, with the view tied to its keyframe through the fixed
/// keyframe→view pose, so the term acts on the keyframe:
///
///     c_view = (T_vk · T_kw)⁻¹ · 0 = T_kw⁻¹ · c_vk,   c_vk = T_vk⁻¹ · 0 (view centre in the
///     keyframe's camera frame, metres);   r = c_view − y_w   (metres, W).
///
/// T_kw is the keyframe's metric world→camera pose (SE3, LEFT perturbation T ← exp(δ)·T,
/// tangent (ω, ν)). With T⁻¹ ← T⁻¹·exp(−δ) and exp(−δ)·p ≈ p − ω×p − ν:
///
///     J_r_T (3x6) = R_kwᵀ · [ [c_vk]× | −I ].
struct GeoViewCentreResidual {
  static constexpr int kNumResiduals = 3;
  using Vec = Eigen::Matrix<double, 3, 1>;
  using Mat = Eigen::Matrix<double, 3, 6>;

  Eigen::Vector3d c_vk = Eigen::Vector3d::Zero();  ///< view centre in the keyframe frame [m]
  Eigen::Vector3d y_w = Eigen::Vector3d::Zero();   ///< geo-tag position in W [m]

  bool operator()(const lie::SE3d& T_kw, Vec* r, Mat* J_r_T = nullptr) const {
    const lie::SE3d T_wk = T_kw.inverse();
    *r = T_wk.act(c_vk) - y_w;
    if (J_r_T) {
      const Eigen::Matrix3d Rt = T_wk.rotation().matrix();
      J_r_T->leftCols<3>() = Rt * lie::skew<double>(c_vk);
      J_r_T->rightCols<3>() = -Rt;
    }
    return true;
  }
};

}  // namespace geodrift::correction
