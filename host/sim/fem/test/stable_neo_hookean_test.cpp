// The stable Neo-Hookean material of the implicit FEM (stable_neo_hookean_fem.hpp):
// energy, gradient and Hessian against finite differences (inverted elements included),
// the projected Hessian, the small-strain limit (linear elasticity, the co-rotational FEM),
// a patch test, recovery of an inverted element, convergence under refinement.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "host/sim/fem/stable_neo_hookean_fem.hpp"
#include "host/sim/fem/test/fem_test_util.hpp"

namespace arnav::host {
namespace {

namespace snh = stable_neo_hookean;
using fem_test::box_problem;
using fem_test::vertices_where;

constexpr double kMu = 1.7, kLambda = 8.3;

std::vector<Eigen::Matrix3d> sample_gradients() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  std::vector<Eigen::Matrix3d> out;
  for (int k = 0; k < 20; ++k) {
    Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
    for (int i = 0; i < 9; ++i) F.data()[i] += u(rng);
    if (k % 2) F.col(2) *= -1.0;  // every other one inverted (det < 0)
    out.push_back(F);
  }
  out.push_back(Eigen::Vector3d(1.0, 1.0, 0.0).asDiagonal());    // flat
  out.push_back(Eigen::Vector3d(1.2, 0.9, -0.4).asDiagonal());   // inverted, diagonal
  return out;
}

TEST(StableNeoHookean, EnergyGradientAndHessianMatchFiniteDifferences) {
  int inverted = 0;
  for (const Eigen::Matrix3d& F : sample_gradients()) {
    inverted += F.determinant() < 0;
    const Eigen::Matrix3d P = snh::first_piola(F, kMu, kLambda);
    const snh::Matrix9d H = snh::hessian(F, kMu, kLambda, false);
    const double h = 1e-6;
    for (int i = 0; i < 9; ++i) {
      Eigen::Matrix3d Fp = F, Fm = F;
      Fp.data()[i] += h;
      Fm.data()[i] -= h;
      const double dpsi = (snh::energy_density(Fp, kMu, kLambda) - snh::energy_density(Fm, kMu, kLambda)) / (2 * h);
      EXPECT_NEAR(dpsi, P.data()[i], 1e-6 * (1 + std::abs(P.data()[i])));
      const Eigen::Matrix3d dP = (snh::first_piola(Fp, kMu, kLambda) - snh::first_piola(Fm, kMu, kLambda)) / (2 * h);
      for (int j = 0; j < 9; ++j) EXPECT_NEAR(dP.data()[j], H(j, i), 1e-6 * (1 + H.cwiseAbs().maxCoeff()));
    }
    EXPECT_LT((H - H.transpose()).norm(), 1e-12);
  }
  EXPECT_GE(inverted, 10);
}

TEST(StableNeoHookean, RestIsStressFreeAndProjectionIsSemiDefinite) {
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  EXPECT_NEAR(snh::energy_density(I, kMu, kLambda), 0.0, 1e-14);
  EXPECT_LT(snh::first_piola(I, kMu, kLambda).norm(), 1e-14);
  int projected = 0;
  for (const Eigen::Matrix3d& F : sample_gradients()) {
    bool was_projected = false;
    const snh::Matrix9d Hp = snh::hessian(F, kMu, kLambda, true, &was_projected);
    const snh::Matrix9d H = snh::hessian(F, kMu, kLambda, false);
    const Eigen::SelfAdjointEigenSolver<snh::Matrix9d> eig(H);
    const Eigen::SelfAdjointEigenSolver<snh::Matrix9d> eigp(Hp);
    EXPECT_GE(eigp.eigenvalues().minCoeff(), -1e-9 * kMu);
    if (eig.eigenvalues().minCoeff() < -1e-6) {
      EXPECT_TRUE(was_projected);
      ++projected;
      // The analytic eigensystem gives the same projection as the numerical 9x9 one.
      EXPECT_LT((Hp - snh::project_numerically(H)).norm(), 1e-8 * H.norm());
    } else if (!was_projected) {
      EXPECT_LT((Hp - H).norm(), 1e-12);
    }
  }
  EXPECT_GE(projected, 5);  // inverted and compressed elements are indefinite
}

TEST(StableNeoHookean, SmallStrainIsLinearElasticity) {
  Eigen::Matrix3d G;
  G << 0.3, -0.2, 0.5, 0.1, -0.4, 0.2, 0.7, 0.05, 0.25;
  const double eps = 1e-6;
  const Eigen::Matrix3d e = 0.5 * (G + G.transpose());
  const Eigen::Matrix3d sigma = 2 * kMu * e + kLambda * e.trace() * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d P = snh::first_piola(Eigen::Matrix3d::Identity() + eps * G, kMu, kLambda) / eps;
  EXPECT_LT((P - sigma).norm(), 1e-4 * sigma.norm());
  // Energy: mu |e|^2 + lambda/2 tr(e)^2 (per eps^2).
  const double psi = snh::energy_density(Eigen::Matrix3d::Identity() + eps * G, kMu, kLambda) / (eps * eps);
  EXPECT_NEAR(psi, kMu * e.squaredNorm() + 0.5 * kLambda * e.trace() * e.trace(), 1e-3 * psi);
}

ModelConfig snh_config(const std::string& integrator, int newton = 20) {
  ModelConfig c;
  c.kind = "corotational_fem";
  c.material_model = "stable_neo_hookean";
  c.integrator = integrator;
  c.linear_solver = "cholmod";
  c.iterations = newton;
  c.tolerance = 1e-10;
  return c;
}

TEST(StableNeoHookeanFem, FactoryAndConfigErrors) {
  const SimProblem p = box_problem(1, 1, 1, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  const auto m = make_corotational_fem(p, snh_config("implicit_euler"));
  EXPECT_NE(m->name().find("stable_neo_hookean"), std::string::npos);
  ModelConfig bad = snh_config("implicit_euler");
  bad.material_model = "mooney";
  EXPECT_THROW(make_corotational_fem(p, bad), std::invalid_argument);
  bad = snh_config("verlet");
  EXPECT_THROW(make_corotational_fem(p, bad), std::invalid_argument);
  bad = snh_config("implicit_euler");
  bad.refactor_in_background = true;
  bad.linear_solver = "pcg";
  EXPECT_THROW(make_corotational_fem(p, bad), std::invalid_argument);
}

// Patch test: boundary vertices on an affine deformation (large, non-rotational), the
// interior vertex displaced; equilibrium puts it back on the affine field exactly.
TEST(StableNeoHookeanFem, PatchTestReproducesHomogeneousDeformation) {
  SimProblem p = box_problem(2, 2, 2, Eigen::Vector3d(20, 20, 20), 5.0, 0.45);
  Eigen::Matrix3d A;
  A << 1.3, 0.2, 0.0, 0.0, 0.8, 0.1, 0.05, 0.0, 1.1;
  const Eigen::Vector3d t(3, -2, 1);
  std::vector<int> boundary;
  int interior = -1;
  for (int i = 0; i < p.mesh.num_vertices(); ++i) {
    const Eigen::Vector3d q = p.mesh.rest_positions_World_mm.col(i);
    const bool on_boundary = (q.array() == 0.0).any() || (q.array() == 20.0).any();
    if (on_boundary) boundary.push_back(i); else interior = i;
  }
  ASSERT_GE(interior, 0);
  p.fixed_vertices = boundary;
  StableNeoHookeanFem m(p, snh_config("quasi_static"));
  Eigen::Matrix3Xd x = (A * p.mesh.rest_positions_World_mm).colwise() + t;
  const Eigen::Vector3d expected = x.col(interior);
  x.col(interior) += Eigen::Vector3d(2.0, -1.0, 1.5);
  m.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  ASSERT_GT(fem_test::solve_to_equilibrium(m, 20, 1e-12), 0);
  EXPECT_LT((m.positions_World_mm().col(interior) - expected).norm(), 1e-8);
}

// Small load: the stable Neo-Hookean and the co-rotational FEM agree (both are linear
// elasticity for small strain); the same Lame parameters go in.
TEST(StableNeoHookeanFem, SmallLoadMatchesCorotationalFem) {
  SimProblem p = box_problem(8, 2, 2, Eigen::Vector3d(40, 10, 10), 2000.0, 0.45);
  p.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  p.fixed_vertices = vertices_where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() == 0.0; });
  StableNeoHookeanFem snh_model(p, snh_config("quasi_static"));
  CorotationalFem corot(p, fem_test::quasi_static_cholmod());
  ASSERT_GT(fem_test::solve_to_equilibrium(snh_model, 20, 1e-10), 0);
  ASSERT_GT(fem_test::solve_to_equilibrium(corot, 50, 1e-10), 0);
  const Eigen::Matrix3Xd u_snh = snh_model.positions_World_mm() - p.mesh.rest_positions_World_mm;
  const Eigen::Matrix3Xd u_cr = corot.positions_World_mm() - p.mesh.rest_positions_World_mm;
  const double tip = u_cr.colwise().norm().maxCoeff();
  EXPECT_GT(tip, 0.05);   // a real deflection
  EXPECT_LT(tip, 1.0);    // small strain (bar 40 mm)
  EXPECT_LT((u_snh - u_cr).colwise().norm().maxCoeff(), 0.01 * tip);
}

// A tet pushed through its opposite face (inverted) recovers to the rest shape.
TEST(StableNeoHookeanFem, InvertedElementRecoversToRest) {
  SimProblem p = box_problem(1, 1, 1, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  p.region_materials[0].damping_mass_per_s = 5.0;
  StableNeoHookeanFem m(p, snh_config("implicit_euler", 10));
  const Eigen::Matrix3Xd X = p.mesh.rest_positions_World_mm;
  int corner = 0;
  for (int i = 0; i < X.cols(); ++i)
    if (X.col(i).sum() == 30.0) corner = i;
  Eigen::Matrix3Xd x = X;
  x.col(corner) = Eigen::Vector3d(-2.0, -2.0, -2.0);  // through the opposite corner: inverted tets
  m.set_state(x, Eigen::Matrix3Xd::Zero(3, X.cols()));
  int inverted0 = 0;
  for (const auto& e : m.element_measures()) inverted0 += e.volume_ratio <= 0.0;
  ASSERT_GE(inverted0, 1);
  for (int k = 0; k < 300; ++k) ASSERT_TRUE(m.step(1.0 / 60).healthy) << "step " << k;
  for (const auto& e : m.element_measures()) EXPECT_NEAR(e.volume_ratio, 1.0, 1e-3);
  // Rest shape up to a rigid motion: every pairwise distance as at rest.
  const Eigen::Matrix3Xd& y = m.positions_World_mm();
  for (int i = 0; i < X.cols(); ++i)
    for (int j = i + 1; j < X.cols(); ++j)
      EXPECT_NEAR((y.col(i) - y.col(j)).norm(), (X.col(i) - X.col(j)).norm(), 1e-2);
  EXPECT_EQ(m.inversions().peak_inverted(), 0);  // counted at the end of steps: none after the first
}

// Cantilever under gravity, large deflection: the tip converges as the mesh is refined.
TEST(StableNeoHookeanFem, ConvergesUnderRefinement) {
  auto tip_deflection = [](int n) {
    SimProblem p = box_problem(4 * n, n, n, Eigen::Vector3d(40, 10, 10), 20.0, 0.4);
    p.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
    p.fixed_vertices = vertices_where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() == 0.0; });
    StableNeoHookeanFem m(p, snh_config("quasi_static", 50));
    EXPECT_GT(fem_test::solve_to_equilibrium(m, 50, 1e-8), 0) << "n = " << n;
    const auto tip = vertices_where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() == 40.0; });
    double dz = 0;
    for (int v : tip) dz += m.positions_World_mm()(2, v) - p.mesh.rest_positions_World_mm(2, v);
    return dz / static_cast<double>(tip.size());
  };
  const double d1 = tip_deflection(1), d2 = tip_deflection(2), d4 = tip_deflection(4), d8 = tip_deflection(8);
  EXPECT_LT(d8, -2.0);  // a large deflection of the 40 mm bar
  const double e1 = std::abs(d1 - d8), e2 = std::abs(d2 - d8), e4 = std::abs(d4 - d8);
  EXPECT_LT(e2, e1);
  EXPECT_LT(e4, e2);
  EXPECT_LT(e4, 0.2 * std::abs(d8));
}

// The hanging soft block (large rotations): implicit Euler stays healthy, energy bounded.
TEST(StableNeoHookeanFem, HangingBlockStaysHealthy) {
  SimProblem p = fem_test::hanging_block();
  p.region_materials[0].damping_mass_per_s = 1.0;
  StableNeoHookeanFem m(p, snh_config("implicit_euler", 5));
  for (int k = 0; k < 60; ++k) {
    const StepSummary s = m.step(1.0 / 60);
    ASSERT_TRUE(s.healthy) << "step " << k << ": " << s.warning;
  }
  EXPECT_TRUE(m.positions_World_mm().allFinite());
  EXPECT_LT((m.positions_World_mm() - p.mesh.rest_positions_World_mm).colwise().norm().maxCoeff(), 80.0);
}

}  // namespace
}  // namespace arnav::host
