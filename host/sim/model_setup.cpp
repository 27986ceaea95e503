#include "host/sim/model_setup.hpp"

#include <stdexcept>
#include <string>

#include "host/sim/tet_geometry.hpp"

namespace arnav::host {

void check_iterative_config(const ModelConfig& config, std::string_view model) {
  const std::string m(model);
  if (config.substeps < 1) throw std::invalid_argument(m + ": substeps must be >= 1");
  if (config.iterations < 1) throw std::invalid_argument(m + ": iterations must be >= 1");
  if (config.threads < 1) throw std::invalid_argument(m + ": threads must be >= 1");
  if (!(config.tolerance >= 0.0)) throw std::invalid_argument(m + ": tolerance must be >= 0");
}

Eigen::VectorXd checked_masses_kg(const SimProblem& problem, std::string_view model) {
  const TetMesh& mesh = problem.mesh;
  if (mesh.num_vertices() == 0 || mesh.num_tets() == 0) {
    throw std::invalid_argument(std::string(model) + ": the mesh has no tetrahedra");
  }
  Eigen::VectorXd mass = lumped_masses_kg(mesh, problem.region_materials);  // validates volumes and regions
  for (int i = 0; i < mesh.num_vertices(); ++i) {
    if (!(mass[i] > 0.0)) {
      throw std::invalid_argument(std::string(model) + ": vertex " + std::to_string(i) +
                                  " belongs to no tetrahedron (zero mass): remove unused vertices from the mesh");
    }
  }
  return mass;
}

}  // namespace arnav::host
