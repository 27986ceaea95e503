// Vessel beams coupled into the co-rotational FEM (K = Kp + J^T Kb J): stiffening of a
// soft cantilever by an embedded stiff rod, and what the stiffness contrast does to the
// conditioning and to PCG iterations.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "host/sim/fem/test/fem_test_util.hpp"

namespace arnav::host {
namespace {

constexpr double kL = 60.0, kB = 20.0, kEt = 1.0e3, kNu = 0.45, kRod = 3.0, kClamp = 5.0;

SimProblem rod_block(double contrast) {
  SimProblem p = fem_test::box_problem(12, 4, 4, Eigen::Vector3d(kL, kB, kB), kEt, kNu);
  p.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  // Clamp the first cell layer (x <= 5 mm): the tets holding the rod's root node are then
  // fixed, so the rod is clamped like the tissue (cantilever length kL - 5 for both).
  p.fixed_vertices = fem_test::vertices_where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() <= kClamp; });
  if (contrast > 0.0) {
    VesselTree tree;
    tree.nodes_World_mm.resize(3, 2);
    tree.nodes_World_mm << 0.5, kL - 0.5, 10.2, 10.2, 10.3, 10.3;  // along the axis, off the grid planes
    tree.radius_mm = {kRod, kRod};
    tree.segments = {{0, 1}};
    p.vessels = tree;
    p.vessel_material = Material{.youngs_modulus_kPa = contrast * kEt, .poisson_ratio = kNu};
  }
  return p;
}

FemOptions rod_options() {
  FemOptions o;
  o.beams.wall_thickness_mm = kRod;  // solid rod: a clear bending stiffness to compare with
  o.beams.max_element_length_mm = 5.0;
  return o;
}

double tip_sag(const CorotationalFem& model, const TetMesh& mesh) {
  double sum = 0;
  int n = 0;
  for (int i = 0; i < mesh.num_vertices(); ++i)
    if (mesh.rest_positions_World_mm(0, i) == kL) {
      sum += mesh.rest_positions_World_mm(2, i) - model.positions_World_mm()(2, i);
      ++n;
    }
  return sum / n;
}

double sag_with_contrast(double contrast) {
  const SimProblem p = rod_block(contrast);
  CorotationalFem model(p, fem_test::quasi_static_cholmod(), rod_options());
  EXPECT_EQ(model.num_beam_elements(), contrast > 0.0 ? 12 : 0);
  EXPECT_GT(fem_test::solve_to_equilibrium(model, 20, 1e-10), 0);
  return tip_sag(model, p.mesh);
}

TEST(FemVessels, EmbeddedRodStiffensTheTissueLikeParallelBeams) {
  const double tissue = sag_with_contrast(0.0);
  double previous = tissue;
  for (const double contrast : {1.0, 10.0, 100.0, 1000.0}) {
    const double sag = sag_with_contrast(contrast);
    std::printf("contrast %6.0f: tip sag %.5f mm (tissue alone %.5f)\n", contrast, sag, tissue);
    EXPECT_LT(sag, previous) << contrast;
    previous = sag;
  }
  // Rod and tissue bend together: stiffnesses add, 1/sag ~ 1/sag_tissue + 1/sag_rod, with
  // the rod carrying the tissue weight as a clamped Timoshenko cantilever.
  const double E_rod = 1000.0 * kEt, I = std::numbers::pi * std::pow(kRod, 4) / 4.0, A = std::numbers::pi * kRod * kRod;
  const double q = 1.06e-6 * 9810.0 * kB * kB, Lc = kL - kClamp;
  const double rod = q * std::pow(Lc, 4) / (8 * E_rod * I) + q * Lc * Lc / (2 * 0.9 * E_rod / (2 * (1 + kNu)) * A);
  const double expected = 1.0 / (1.0 / tissue + 1.0 / rod);
  std::printf("contrast 1000: parallel estimate %.5f mm, rod alone %.5f mm\n", expected, rod);
  EXPECT_GT(previous, 0.7 * expected);
  EXPECT_LT(previous, 1.6 * expected);
}

TEST(FemVessels, ContrastDegradesJacobiPcgButNotTheFactorPreconditioner) {
  std::vector<int> iterations;
  std::vector<double> kappa;
  for (const double contrast : {1.0, 100.0, 1000.0, 10000.0}) {
    const SimProblem p = rod_block(contrast);
    CorotationalFem jacobi(p, {.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "pcg_jacobi",
                               .iterations = 20000, .tolerance = 1e-8}, rod_options());
    jacobi.set_estimate_condition(true);
    const StepSummary s = jacobi.step(1.0);
    ASSERT_EQ(s.termination, "converged") << contrast;
    CorotationalFem factor(p, {.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "pcg",
                               .iterations = 100, .tolerance = 1e-8}, rod_options());
    const StepSummary f = factor.step(1.0);
    std::printf("contrast %6.0f: Jacobi-PCG %d iterations (kappa >= %.3g), factor-PCG %d\n", contrast, s.iterations,
                jacobi.last_linear_solve().condition_estimate, f.iterations);
    EXPECT_LE(f.iterations, 2);  // fresh factor of the same matrix: exact up to round-off
    iterations.push_back(s.iterations);
    kappa.push_back(jacobi.last_linear_solve().condition_estimate);
  }
  // Up to ~100 the rod is no stiffer than the tissue around it; beyond, kappa grows with it.
  EXPECT_GT(kappa[3], 1.5 * kappa[0]);
  EXPECT_GT(kappa[3], kappa[2]);
  EXPECT_GT(iterations[3], iterations[0] * 3 / 2);
}

}  // namespace
}  // namespace arnav::host
