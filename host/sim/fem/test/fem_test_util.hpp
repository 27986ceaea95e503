#pragma once
// Helpers shared by the FEM tests: box problems, constant loads and quasi-static solves.
#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/fem/corotational_fem.hpp"

namespace arnav::host::fem_test {

inline SimProblem box_problem(int nx, int ny, int nz, const Eigen::Vector3d& size, double E, double nu) {
  SimProblem p;
  p.mesh = make_box_tet_mesh(nx, ny, nz, size);
  p.region_materials = {Material{.youngs_modulus_kPa = E, .poisson_ratio = nu}};
  p.gravity_World_mm_s2.setZero();
  return p;
}

inline std::vector<int> vertices_where(const TetMesh& mesh, auto predicate) {
  std::vector<int> out;
  for (int i = 0; i < mesh.num_vertices(); ++i)
    if (predicate(Eigen::Vector3d(mesh.rest_positions_World_mm.col(i)))) out.push_back(i);
  return out;
}

// A constant nodal force from the attachment interface: a spring of stiffness |f|/D to a
// target D = 1e6 mm away along f; the force changes by a relative u/D (< 1e-6 here).
inline void add_constant_force(TissueModel& model, int vertex, const Eigen::Vector3d& force_mN) {
  const double D = 1e6;
  const double f = force_mN.norm();
  if (f == 0.0) return;
  const Eigen::Vector3d x = model.positions_World_mm().col(vertex);
  model.add_attachment({.point = {{vertex}, {1.0}}, .target_World_mm = x + D * force_mN / f, .stiffness_mN_per_mm = f / D});
}

// Consistent nodal forces of a uniform traction on the boundary faces selected by `on_face`.
inline void add_traction(TissueModel& model, const TetMesh& mesh, auto on_face, const Eigen::Vector3d& traction_kPa) {
  Eigen::Matrix3Xd nodal = Eigen::Matrix3Xd::Zero(3, mesh.num_vertices());
  for (const auto& tri : mesh.surface_tris) {
    const Eigen::Vector3d a = mesh.rest_positions_World_mm.col(tri[0]), b = mesh.rest_positions_World_mm.col(tri[1]),
                          c = mesh.rest_positions_World_mm.col(tri[2]);
    if (!on_face(a) || !on_face(b) || !on_face(c)) continue;
    const double area = 0.5 * (b - a).cross(c - a).norm();
    for (int v : tri) nodal.col(v) += area / 3.0 * traction_kPa;
  }
  for (int i = 0; i < mesh.num_vertices(); ++i) add_constant_force(model, i, nodal.col(i));
}

// Quasi-static steps until the update is below tol_mm; returns the number of steps.
inline int solve_to_equilibrium(TissueModel& model, int max_steps = 20, double tol_mm = 1e-9) {
  for (int k = 1; k <= max_steps; ++k) {
    const Eigen::Matrix3Xd before = model.positions_World_mm();
    const StepSummary s = model.step(1.0);
    if (!s.healthy) return -1;
    if ((model.positions_World_mm() - before).cwiseAbs().maxCoeff() < tol_mm) return k;
  }
  return max_steps + 1;
}

inline ModelConfig quasi_static_cholmod() {
  return {.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "cholmod"};
}

// 40 x 20 x 20 mm block of soft tissue clamped on its x = 0 face, under gravity from rest:
// it swings down through large rotations, so a lagged factor goes stale quickly.
inline SimProblem hanging_block() {
  SimProblem p = box_problem(8, 4, 4, Eigen::Vector3d(40, 20, 20), 5.0, 0.45);
  p.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  p.fixed_vertices = vertices_where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() == 0.0; });
  return p;
}

}  // namespace arnav::host::fem_test
