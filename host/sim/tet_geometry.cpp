#include "host/sim/tet_geometry.hpp"

#include <Eigen/LU>
#include <stdexcept>
#include <string>

namespace arnav::host {

Eigen::Matrix3d edge_matrix(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet) {
  Eigen::Matrix3d D;
  const Eigen::Vector3d x0 = x_World_mm.col(tet[0]);
  for (int k = 0; k < 3; ++k) D.col(k) = x_World_mm.col(tet[k + 1]) - x0;
  return D;
}

double signed_volume_mm3(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet) {
  return edge_matrix(x_World_mm, tet).determinant() / 6.0;
}

Eigen::VectorXd lumped_masses_kg(const TetMesh& mesh, const std::vector<Material>& region_materials) {
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(mesh.num_vertices());
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const double volume = signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[t]);
    if (!(volume > 0.0)) {
      throw std::invalid_argument("tet " + std::to_string(t) + " has non-positive rest volume " +
                                  std::to_string(volume) + " mm^3: fix its orientation or remove it");
    }
    const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
    if (region < 0 || region >= static_cast<int>(region_materials.size())) {
      throw std::invalid_argument("tet " + std::to_string(t) + " refers to region " + std::to_string(region) +
                                  " which has no material");
    }
    const double quarter = 0.25 * volume * region_materials[region].density_kg_per_mm3;
    for (int v : mesh.tets[t]) mass[v] += quarter;
  }
  return mass;
}

Lame lame_from(const Material& material) {
  const double E = material.youngs_modulus_kPa;
  const double nu = material.poisson_ratio;
  if (!(E > 0.0) || !(nu > -1.0 && nu < 0.5)) {
    throw std::invalid_argument("material needs E > 0 and -1 < nu < 0.5 (got E=" + std::to_string(E) +
                                " kPa, nu=" + std::to_string(nu) + ")");
  }
  return {E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))};
}

}  // namespace arnav::host
