#pragma once
// Geometry of linear tetrahedra shared by all tissue models. Frame: World, units mm, kg.
#include <Eigen/Core>

#include <array>
#include <vector>

#include "host/mesh/tet_mesh.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// Edge matrix [x1-x0, x2-x0, x3-x0] of tet t for the given vertex positions.
Eigen::Matrix3d edge_matrix(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet);

// Signed volume (mm^3): det(edge_matrix)/6; positive for a correctly oriented tet.
double signed_volume_mm3(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet);

// Lumped (row-sum) vertex masses in kg: each tet gives a quarter of its mass to each vertex.
// Throws std::invalid_argument naming the tet if a rest volume is not positive.
Eigen::VectorXd lumped_masses_kg(const TetMesh& mesh, const std::vector<Material>& region_materials);

// Lame parameters (kPa) from Young's modulus (kPa) and Poisson ratio.
struct Lame {
  double mu_kPa;
  double lambda_kPa;
};
Lame lame_from(const Material& material);

}  // namespace arnav::host
