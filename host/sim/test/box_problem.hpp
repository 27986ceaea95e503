// Test problems on a box mesh (make_box_tet_mesh), shared by the model and cut tests.
#pragma once

#include <Eigen/Core>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host::test {

// nx x ny x nz cells over size_mm, one material; gravity the SimProblem default or off.
inline SimProblem box_problem(int nx, int ny, int nz, const Eigen::Vector3d& size_mm, const Material& m, bool gravity = true) {
  SimProblem p;
  p.mesh = make_box_tet_mesh(nx, ny, nz, size_mm);
  p.region_materials = {m};
  if (!gravity) p.gravity_World_mm_s2.setZero();
  return p;
}

// The soft tissue of the cut tests: E as given, nu 0.4, mass damping 5 /s.
inline Material soft_tissue(double youngs_kPa) {
  Material m;
  m.youngs_modulus_kPa = youngs_kPa;
  m.poisson_ratio = 0.4;
  m.damping_mass_per_s = 5.0;
  return m;
}

// Holds the vertices of the box's x = 0 face.
inline void clamp_x0_face(SimProblem& p) {
  for (int v = 0; v < p.mesh.num_vertices(); ++v)
    if (p.mesh.rest_positions_World_mm(0, v) < 1e-9) p.fixed_vertices.push_back(v);
}

}  // namespace arnav::host::test
