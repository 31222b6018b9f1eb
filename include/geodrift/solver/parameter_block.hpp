#pragma once

/// @file
/// ParameterBlock: the solver's record of one caller-owned state (a pose, a point, ...).

#include <typeindex>

namespace geodrift::solver {

/// Non-owning description of one parameter block. The caller owns the state and keeps it alive
/// (at a fixed address) for as long as the Problem refers to it.
///
/// Columns: a free block owns `dof` consecutive columns of J and H starting at `col`; a constant
/// block owns no column (index = col = -1) and its Jacobians are never computed. Fixing the gauge
/// of a pose graph = Problem::set_constant(&first_pose).
struct ParameterBlock {
  void* state = nullptr;  ///< caller's storage (T*, or the first double of a Euclidean<N>)
  std::type_index type = typeid(void);  ///< the Manifold type, checked on every reuse
  int dof = 0;                          ///< tangent size (Manifold<T>::kDoF)
  int ambient = 0;                      ///< Manifold<T>::kAmbient
  bool constant = false;                ///< held fixed (set_constant)
  int index = -1;           ///< block column index in H (after finalize), -1 if constant
  int col = -1;             ///< first scalar column in J/H (after finalize), -1 if constant
  int num_residuals = 0;    ///< residual blocks that use it
  bool eliminable = false;  ///< R^3 block (a BA point): eliminated first by the Schur solver
};

}  // namespace geodrift::solver
