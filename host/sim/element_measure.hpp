#pragma once
// Per-element measures shared by the tissue models: von Mises stress, Green strain and
// det(F) from a tet's deformation gradient. Units: stresses kPa (mN/mm^2), strains 1.
#include <Eigen/Core>

#include "host/sim/tet_geometry.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// Deformation gradient F = Ds * Dm^-1 of tet `tet` (Dm^-1 precomputed from the rest state).
Eigen::Matrix3d deformation_gradient(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet,
                                     const Eigen::Matrix3d& Dm_inv);

// von Mises equivalent of a (symmetrised) stress tensor, same unit as the input.
double von_mises(const Eigen::Matrix3d& stress);

// Largest eigenvalue of the Green strain E = (F^T F - I) / 2.
double max_green_strain(const Eigen::Matrix3d& F);

// Co-rotated linear (Hooke) stress, kPa: rotation R from the polar decomposition F = R S
// (reflection-safe), strain S - I, stress 2 mu eps + lambda tr(eps) I. Invariant to
// rigid motion; used where a model has no stress of its own (mass-spring).
Eigen::Matrix3d corotated_linear_stress_kPa(const Eigen::Matrix3d& F, const Lame& lame);

// Measure from F and a stress tensor (kPa) that the caller computed for F.
ElementMeasure element_measure_from(const Eigen::Matrix3d& F, const Eigen::Matrix3d& stress_kPa);

// Rotation of the polar decomposition of F (proper rotation, det = +1, also for det F <= 0).
Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F);

}  // namespace arnav::host
