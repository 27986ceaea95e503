// Verification of the co-rotational FEM against analytic references
// (docs/reference-figures.md): patch test, uniaxial traction, rigid-motion
// invariance, cantilever convergence under end load and gravity.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "host/sim/fem/test/fem_test_util.hpp"

namespace arnav::host {
namespace {

using fem_test::box_problem;
using fem_test::vertices_where;

TEST(FemVerification, PatchTestAffineBoundaryMotionIsReproducedInside) {
  // Boundary vertices moved by a large affine map (rotation 40 deg + 8% stretch + shear):
  // a uniform F is an equilibrium of the co-rotational model, so the interior must follow.
  SimProblem problem = box_problem(4, 4, 4, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  Eigen::Matrix3d A = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  Eigen::Matrix3d U;
  U << 1.08, 0.03, 0.0, 0.03, 0.97, 0.02, 0.0, 0.02, 1.01;
  A = A * U;
  const Eigen::Vector3d t(3, -2, 1);
  const Eigen::Matrix3Xd& X = problem.mesh.rest_positions_World_mm;
  auto on_boundary = [](const Eigen::Vector3d& p) { return (p.array() == 0.0).any() || (p.array() == 10.0).any(); };
  Eigen::Matrix3Xd x = X;
  for (int i = 0; i < x.cols(); ++i)
    if (on_boundary(X.col(i))) x.col(i) = A * X.col(i) + t;
  model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  model.set_fixed_vertices(vertices_where(problem.mesh, on_boundary));
  ASSERT_GT(fem_test::solve_to_equilibrium(model, 50, 1e-11), 0);
  double worst = 0.0;
  int interior = 0;
  for (int i = 0; i < x.cols(); ++i) {
    if (on_boundary(X.col(i))) continue;
    ++interior;
    worst = std::max(worst, (model.positions_World_mm().col(i) - (A * X.col(i) + t)).norm());
  }
  EXPECT_EQ(interior, 27);
  EXPECT_LT(worst, 1e-8);
}

TEST(FemVerification, UniaxialTractionGivesAxialAndLateralStrain) {
  // Both end faces pulled by +-p (no other support): uniform uniaxial stress p.
  const double E = 5.0, nu = 0.45, p = 0.05, L = 20.0, W = 8.0;
  SimProblem problem = box_problem(5, 2, 2, Eigen::Vector3d(L, W, W), E, nu);
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  fem_test::add_traction(model, problem.mesh, [&](const Eigen::Vector3d& q) { return q.x() == L; }, Eigen::Vector3d(p, 0, 0));
  fem_test::add_traction(model, problem.mesh, [&](const Eigen::Vector3d& q) { return q.x() == 0.0; }, Eigen::Vector3d(-p, 0, 0));
  ASSERT_GT(fem_test::solve_to_equilibrium(model, 30, 1e-11), 0);
  const Eigen::Matrix3Xd& x = model.positions_World_mm();
  const Eigen::Matrix3Xd& X = problem.mesh.rest_positions_World_mm;
  // Corner-to-corner measures of the deformed box.
  const int a = box_vertex_index(5, 2, 0, 0, 0), b = box_vertex_index(5, 2, 5, 2, 2);
  const Eigen::Vector3d d = x.col(b) - x.col(a), D = X.col(b) - X.col(a);
  const double axial = d.x() / D.x() - 1.0, lateral_y = d.y() / D.y() - 1.0, lateral_z = d.z() / D.z() - 1.0;
  EXPECT_NEAR(axial, p / E, 1e-5 * p / E + 1e-9);
  EXPECT_NEAR(lateral_y, -nu * p / E, 1e-4 * p / E);
  EXPECT_NEAR(lateral_z, -nu * p / E, 1e-4 * p / E);
  // The stress is uniform: every element reports von Mises = p.
  for (const ElementMeasure& m : model.element_measures()) EXPECT_NEAR(m.von_mises_stress_kPa, p, 1e-4 * p);
}

TEST(FemVerification, RotatedRestStateGivesZeroForce) {
  SimProblem problem = box_problem(3, 2, 2, Eigen::Vector3d(9, 6, 6), 5.0, 0.45);
  for (const double angle : {0.3, 2.0, 3.1}) {
    const Eigen::Matrix3d Q = Eigen::AngleAxisd(angle, Eigen::Vector3d(0.2, -1, 0.5).normalized()).toRotationMatrix();
    const Eigen::Matrix3Xd x = (Q * problem.mesh.rest_positions_World_mm).colwise() + Eigen::Vector3d(5, 7, -3);
    for (const char* integrator : {"implicit_euler", "quasi_static"}) {
      CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = integrator, .linear_solver = "cholmod"});
      model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
      // Quasi-static needs a support: the vertices of tet 0, held at their rotated places.
      const auto& t0 = problem.mesh.tets[0];
      model.set_fixed_vertices({t0[0], t0[1], t0[2], t0[3]});
      StepSummary s;
      for (int k = 0; k < 3; ++k) s = model.step(0.01);
      EXPECT_TRUE(s.healthy) << s.warning;
      EXPECT_LT(s.elastic_energy, 1e-18) << integrator << " angle " << angle;
      EXPECT_LT((model.positions_World_mm() - x).cwiseAbs().maxCoeff(), 1e-9) << integrator << " angle " << angle;
    }
  }
}

// Cantilever along x, clamped at x = 0, section b x h (h along z), loaded along -z.
struct CantileverResult {
  double tip_mm;
  int tets;
};

CantileverResult cantilever(int n_cross, int n_len, bool end_load, double E, double nu, double L, double b) {
  SimProblem problem = box_problem(n_len, n_cross, n_cross, Eigen::Vector3d(L, b, b), E, nu);
  problem.fixed_vertices = vertices_where(problem.mesh, [](const Eigen::Vector3d& p) { return p.x() == 0.0; });
  if (!end_load) problem.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  if (end_load) {
    const double P = 1.0;  // mN, total
    fem_test::add_traction(model, problem.mesh, [&](const Eigen::Vector3d& q) { return q.x() == L; },
                           Eigen::Vector3d(0, 0, -P / (b * b)));
  }
  EXPECT_GT(fem_test::solve_to_equilibrium(model, 20, 1e-12), 0);
  // Tip deflection: mean z displacement of the end face.
  double sum = 0;
  int count = 0;
  for (int i = 0; i < problem.mesh.num_vertices(); ++i)
    if (problem.mesh.rest_positions_World_mm(0, i) == L) {
      sum += problem.mesh.rest_positions_World_mm(2, i) - model.positions_World_mm()(2, i);
      ++count;
    }
  return {sum / count, problem.mesh.num_tets()};
}

TEST(FemVerification, CantileverConvergesMonotonicallyTowardTimoshenko) {
  // Linear P1 tets lock in bending: we check monotone convergence from below and the
  // level reached (reference-figures.md: 5x5x30 nodes ~0.75, 9x9x60 ~0.92 at nu = 0.3).
  const double E = 1.0e5, nu = 0.3, L = 100.0, b = 10.0;
  const double I = b * b * b * b / 12.0, A = b * b, G = E / (2 * (1 + nu)), k = 5.0 / 6.0;
  const double P = 1.0, q = 1.06e-6 * 9810.0 * A;
  const double ref_end = P * L * L * L / (3 * E * I) + P * L / (k * G * A);
  const double ref_gravity = q * L * L * L * L / (8 * E * I) + q * L * L / (2 * k * G * A);
  for (const bool end_load : {true, false}) {
    double previous = 0.0;
    for (const int n : {1, 2, 3, 4}) {
      const CantileverResult r = cantilever(n, 10 * n, end_load, E, nu, L, b);
      const double ratio = r.tip_mm / (end_load ? ref_end : ref_gravity);
      RecordProperty((std::string(end_load ? "end_" : "gravity_") + std::to_string(n)).c_str(), std::to_string(ratio));
      std::printf("cantilever %s %dx%dx%d cells (%d tets): tip/reference = %.4f\n", end_load ? "end load" : "gravity",
                  n, n, 10 * n, r.tets, ratio);
      EXPECT_GT(ratio, previous) << "not monotone at n = " << n;
      EXPECT_LT(ratio, 1.0);
      previous = ratio;
    }
    EXPECT_GT(previous, 0.70);  // 4x4x40 cells = 5x5x41 nodes
  }
}

}  // namespace
}  // namespace arnav::host
