// XPBD converging toward the static solution of the co-rotational FEM (issue 3, section 3):
// a cantilever under gravity, same mesh and material; the FEM's quasi-static solve gives
// the reference, XPBD's steady state approaches it as its iterations grow. Both energies
// agree with linear elasticity at small strain, so on the same mesh the distance shrinks
// to what the solver leaves. Skipped in builds without the FEM.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

constexpr int kNx = 4, kNy = 2, kNz = 2;

SimProblem cantilever() {
  SimProblem p;
  p.mesh = make_box_tet_mesh(kNx, kNy, kNz, {40, 20, 20});
  p.region_materials = {Material{.youngs_modulus_kPa = 50.0, .poisson_ratio = 0.3, .damping_mass_per_s = 30.0}};
  for (int k = 0; k <= kNz; ++k)
    for (int j = 0; j <= kNy; ++j) p.fixed_vertices.push_back(box_vertex_index(kNx, kNy, 0, j, k));
  return p;
}

TEST(XpbdAgainstFem, SteadyStateApproachesFemStaticSolutionAsIterationsGrow) {
  const auto kinds = available_model_kinds();
  if (std::find(kinds.begin(), kinds.end(), "corotational_fem") == kinds.end()) {
    GTEST_SKIP() << "this build has no corotational_fem";
  }
  const SimProblem problem = cantilever();
  ModelConfig fem_config;
  fem_config.kind = "corotational_fem";
  fem_config.integrator = "quasi_static";
  fem_config.linear_solver = "eigen_ldlt";
  auto fem = make_tissue_model(problem, fem_config);
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(fem->step(1.0 / 60.0).healthy);
  const Eigen::Matrix3Xd reference = fem->positions_World_mm();
  const int tip = box_vertex_index(kNx, kNy, kNx, 1, 1);
  const double tip_deflection = problem.mesh.rest_positions_World_mm(2, tip) - reference(2, tip);
  RecordProperty("fem_tip_deflection_mm", std::to_string(tip_deflection));
  ASSERT_GT(tip_deflection, 0.1);

  double previous = 1e9;
  for (int iterations : {1, 4, 16, 64}) {
    ModelConfig c;
    c.kind = "xpbd";
    c.substeps = 4;
    c.iterations = iterations;
    c.tolerance = 0.0;
    auto xpbd = make_tissue_model(problem, c);
    for (int k = 0; k < 120; ++k) xpbd->step(1.0 / 60.0);
    const double rms_mm = std::sqrt((xpbd->positions_World_mm() - reference).colwise().squaredNorm().mean());
    RecordProperty("rms_distance_mm_at_" + std::to_string(iterations), std::to_string(rms_mm));
    std::printf("[xpbd-vs-fem] iterations %d: RMS nodal distance %.4f mm (FEM tip deflection %.3f mm)\n", iterations,
                rms_mm, tip_deflection);
    EXPECT_LT(rms_mm, previous) << iterations << " iterations";
    previous = rms_mm;
  }
  EXPECT_LT(previous, 0.01 * tip_deflection);
}

}  // namespace
}  // namespace arnav::host
