// Element-level checks: rotation extraction (also for inverted elements), the pattern /
// scatter machinery, and the assembled stiffness against finite differences of the force.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <random>

#include "host/sim/fem/rotation_extraction.hpp"
#include "host/sim/fem/symmetric_pattern.hpp"
#include "host/sim/fem/test/fem_test_util.hpp"

namespace arnav::host {
namespace {

TEST(RotationExtraction, RecoversPolarRotationFromColdStart) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    const Eigen::Quaterniond q = Eigen::Quaterniond(u(rng), u(rng), u(rng), u(rng)).normalized();
    Eigen::Matrix3d Sym;
    Sym << 1.2, 0.1, 0.05, 0.1, 0.8, -0.1, 0.05, -0.1, 1.1;  // SPD stretch
    const Eigen::Matrix3d F = q.toRotationMatrix() * Sym;
    int it = 0;
    const Eigen::Quaterniond r = extract_rotation(F, Eigen::Quaterniond::Identity(), {.max_iterations = 200}, &it);
    EXPECT_LT((r.toRotationMatrix() - q.toRotationMatrix()).norm(), 1e-7) << trial << " iterations " << it;
  }
}

TEST(RotationExtraction, InvertedElementGivesProperRotation) {
  // F = diag(1, 1, -0.5): flattened through itself. A polar decomposition would give a
  // reflection; we need a rotation (det +1) that is the closest one: the identity here.
  Eigen::Matrix3d F = Eigen::Vector3d(1.0, 1.0, -0.5).asDiagonal();
  const Eigen::Matrix3d R = extract_rotation(F, Eigen::Quaterniond::Identity()).toRotationMatrix();
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_LT((R - Eigen::Matrix3d::Identity()).norm(), 1e-9);
  // Rotated inverted element: the rotation is recovered.
  const Eigen::Matrix3d Q = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Matrix3d R2 = extract_rotation(Q * F, Eigen::Quaterniond::Identity(), {.max_iterations = 200}).toRotationMatrix();
  EXPECT_LT((R2 - Q).norm(), 1e-7);
  // Degenerate (zero volume) and NaN inputs do not produce NaN rotations.
  F.setZero();
  EXPECT_TRUE(extract_rotation(F, Eigen::Quaterniond::Identity()).coeffs().allFinite());
}

TEST(SymmetricPattern, BlockMapsTransposeIntoLowerTriangle) {
  const SymmetricPattern p(4, {{0, 2, 3}, {1, 3}});
  // Vertex pair (3, 0) is present, (1, 0) and (2, 1) are not.
  EXPECT_GE(p.index(9, 0), 0);
  EXPECT_EQ(p.index(3, 0), -1);
  EXPECT_EQ(p.index(6, 3), -1);
  EXPECT_TRUE(p.covers({0, 2, 3}));
  EXPECT_FALSE(p.covers({0, 1}));
  const std::vector<int> map = p.block_map({3, 0});
  ASSERT_EQ(map.size(), 27u);  // pairs (3,3), (3,0), (0,0)
  // Block (a=0 -> vertex 3, b=1 -> vertex 0): entry (r, c) lands at (9 + r, c).
  EXPECT_EQ(map[9 + 3 * 2 + 1], p.index(11, 1));
  // Diagonal block: upper entries skipped.
  EXPECT_EQ(map[0 + 1], -1);
  EXPECT_EQ(map[3 + 0], p.index(10, 9));
}

TEST(SymmetricPattern, PartitionKeepsPartsVertexDisjoint) {
  const TetMesh mesh = make_box_tet_mesh(12, 3, 3, Eigen::Vector3d(12, 3, 3));
  std::vector<std::vector<int>> elements;
  for (const auto& t : mesh.tets) elements.emplace_back(t.begin(), t.end());
  const ElementPartition p = partition_elements(mesh.rest_positions_World_mm, elements, 2);
  ASSERT_EQ(p.parts.size(), 2u);
  std::vector<int> seen(mesh.num_vertices(), -1);
  std::size_t total = p.shared.size();
  for (int part = 0; part < 2; ++part) {
    total += p.parts[part].size();
    for (int e : p.parts[part])
      for (int v : elements[e]) {
        EXPECT_TRUE(seen[v] == -1 || seen[v] == part) << "vertex " << v << " in two parts";
        seen[v] = part;
      }
  }
  EXPECT_EQ(total, elements.size());
  EXPECT_LT(p.shared.size(), elements.size() / 4);  // a thin slab at the cut
  EXPECT_GT(p.parts[0].size(), elements.size() / 3);
}

// Force of the model at positions x (quasi-static assembly of f), via one step's summary:
// not exposed, so compare K against finite differences of the elastic energy instead.
TEST(CorotationalFem, AssembledStiffnessMatchesEnergyHessianAtRest) {
  SimProblem problem = fem_test::box_problem(2, 1, 1, Eigen::Vector3d(2, 1, 1), 10.0, 0.3);
  problem.fixed_vertices = fem_test::vertices_where(problem.mesh, [](const Eigen::Vector3d& p) { return p.x() == 0.0; });
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  // At rest sigma = 0, so the warped stiffness equals the Hessian of the elastic energy.
  model.step(1.0);
  const Eigen::MatrixXd K = Eigen::MatrixXd(model.system_matrix()).selfadjointView<Eigen::Lower>();
  const int n = static_cast<int>(K.rows());
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::VectorXd d(n);
  for (int i = 0; i < n; ++i) d[i] = problem.mesh.rest_positions_World_mm(0, i / 3) == 0.0 ? 0.0 : g(rng);
  const double h = 1e-4;
  auto energy = [&](double s) {
    CorotationalFem m(problem, fem_test::quasi_static_cholmod());
    Eigen::Matrix3Xd x = problem.mesh.rest_positions_World_mm;
    Eigen::Map<Eigen::VectorXd>(x.data(), x.size()) += s * d;
    m.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
    return m.step(1.0).elastic_energy;  // energy is evaluated before the update
  };
  const double second = (energy(h) - 2 * energy(0) + energy(-h)) / (h * h);
  EXPECT_NEAR(second, d.dot(K * d), 1e-5 * d.dot(K * d));
}

}  // namespace
}  // namespace arnav::host
