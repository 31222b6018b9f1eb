#pragma once

/// @file
/// InitSimilarityResidual: INIT's residual r = A(p') − y (metres, W) for a levelled map point p'
/// and its geo-tag y, with A the 4-parameter horizontal similarity plus a height offset,
/// parameters (a, b, σ, θ, c) in metres / log-scale / radians / metres (a Euclidean block:
/// the update is x ← x + δ).

#include <Eigen/Core>
#include <cmath>

namespace geodrift::correction {

/// INIT's 4-parameter horizontal similarity plus a height offset (paper Sec. 3.4, eq. (1);
/// DESIGN.md "Correction" step 1), acting on a LEVELLED map point p' (map rotated so that the
/// camera-centre plane normal is W's +z):
///
///     A(p') = [ s·cosθ  −s·sinθ  0 ] p' + [ a ]        s = exp(σ) > 0 by construction
///             [ s·sinθ   s·cosθ  0 ]      [ b ]
///             [   0        0     s ]      [ c ]
///
/// Parameters x = (a, b, σ, θ, c) in metres / log-scale / radians. Residual r = A(p') − y
/// (metres, W). The paper writes the plane as xz with y up; W has z up (DESIGN.md).
struct InitSimilarityResidual {
  static constexpr int kNumResiduals = 3;
  using Params = Eigen::Matrix<double, 5, 1>;
  using Vec3 = Eigen::Matrix<double, 3, 1>;
  using Jacobian = Eigen::Matrix<double, 3, 5>;

  Eigen::Vector3d p_levelled;  ///< p' (levelled map frame, map units)
  Eigen::Vector3d y_w;         ///< geo-tag position in W (metres)

  /// Applies A to p'.
  static Eigen::Vector3d apply(const Params& x, const Eigen::Vector3d& p) {
    const double s = std::exp(x[2]), c = std::cos(x[3]), sn = std::sin(x[3]);
    return {s * (c * p.x() - sn * p.y()) + x[0], s * (sn * p.x() + c * p.y()) + x[1],
            s * p.z() + x[4]};
  }

  /// r = A(p') − y; J_r_x (3x5) in (a, b, σ, θ, c) order. Always evaluable.
  bool operator()(const Params& x, Vec3* r, Jacobian* J_r_x = nullptr) const {
    const double s = std::exp(x[2]), c = std::cos(x[3]), sn = std::sin(x[3]);
    const Eigen::Vector3d& p = p_levelled;
    const double rx = s * (c * p.x() - sn * p.y()), ry = s * (sn * p.x() + c * p.y());
    *r << rx + x[0] - y_w.x(), ry + x[1] - y_w.y(), s * p.z() + x[4] - y_w.z();
    if (J_r_x) {
      // d/dσ of s·f = s·f; d/dθ rotates the horizontal part by +90°.
      *J_r_x << 1, 0, rx, -ry, 0,  //
          0, 1, ry, rx, 0,         //
          0, 0, s * p.z(), 0, 1;
    }
    return true;
  }
};

}  // namespace geodrift::correction
