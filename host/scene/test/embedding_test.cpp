// Barycentric embedding: exact for affine motion of the volume (inside and slightly
// outside the mesh), refuses points far outside.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

#include "host/mesh/box_mesh.hpp"
#include "host/scene/embedding.hpp"
#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

TEST(Embedding, ReproducesAffineDeformationsExactly) {
  const TetMesh mesh = make_box_tet_mesh(4, 3, 5, Eigen::Vector3d(40, 30, 50));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::Matrix3Xd points(3, 200);
  for (int i = 0; i < points.cols(); ++i) points.col(i) = Eigen::Vector3d(40 * u(rng), 30 * u(rng), 50 * u(rng));
  // A few points just outside the box (within tolerance): weights extrapolate.
  points.col(0) = Eigen::Vector3d(-0.3, 15, 25);
  points.col(1) = Eigen::Vector3d(40.2, 30.1, 50.2);
  const Embedding e = embed_points(mesh, points, 0.5, "test points");
  EXPECT_GT(e.max_outside_mm, 0.2);
  EXPECT_LE(e.max_outside_mm, 0.5);
  for (int trial = 0; trial < 5; ++trial) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) A(r, c) += 0.6 * (u(rng) - 0.5);  // stretch, shear, rotation-ish
    const Eigen::Vector3d b(100 * u(rng), -50 * u(rng), 20 * u(rng));
    const Eigen::Matrix3Xd x = (A * mesh.rest_positions_World_mm).colwise() + b;
    const Eigen::Matrix3Xd expected = (A * points).colwise() + b;
    EXPECT_LT((e.apply(mesh, x) - expected).cwiseAbs().maxCoeff(), 1e-9);
  }
  for (int i = 0; i < e.size(); ++i) EXPECT_NEAR(e.weights.col(i).sum(), 1.0, 1e-12);
  const MaterialPoint p = e.material_point(mesh, 5);
  ASSERT_EQ(p.vertices.size(), 4u);
  Eigen::Vector3d q = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) q += p.weights[k] * mesh.rest_positions_World_mm.col(p.vertices[k]);
  EXPECT_LT((q - points.col(5)).norm(), 1e-9);
}

TEST(Embedding, VerticesEmbedOnThemselves) {
  const TetMesh mesh = make_box_tet_mesh(3, 3, 3, Eigen::Vector3d(1, 1, 1));
  const Embedding e = embed_points(mesh, mesh.rest_positions_World_mm, 0.0, "vertices");
  EXPECT_EQ(e.max_outside_mm, 0.0);
  EXPECT_LT((e.apply(mesh, mesh.rest_positions_World_mm) - mesh.rest_positions_World_mm).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(Embedding, PointFarOutsideIsAnError) {
  const TetMesh mesh = make_box_tet_mesh(2, 2, 2, Eigen::Vector3d(10, 10, 10));
  Eigen::Matrix3Xd points(3, 2);
  points << 5, 5, 5, 13, 5, 5;  // columns (5,5,13) ... (5,5,5)
  points.col(0) = Eigen::Vector3d(5, 5, 5);
  points.col(1) = Eigen::Vector3d(5, 5, 13);
  try {
    embed_points(mesh, points, 1.0, "tumour.obj");
    FAIL() << "expected a LoadError";
  } catch (const LoadError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("tumour.obj"), std::string::npos) << m;
    EXPECT_NE(m.find("point 1"), std::string::npos) << m;
    EXPECT_NE(m.find("3 mm outside"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace arnav::host
