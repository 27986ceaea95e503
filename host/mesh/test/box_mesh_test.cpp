#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "host/mesh/box_mesh.hpp"

namespace arnav::host {
namespace {

TEST(BoxMesh, VolumesPositiveAndSumToBox) {
  const TetMesh mesh = make_box_tet_mesh(3, 2, 5, Eigen::Vector3d(30, 20, 100));
  EXPECT_EQ(mesh.num_vertices(), 4 * 3 * 6);
  EXPECT_EQ(mesh.num_tets(), 6 * 3 * 2 * 5);
  double total = 0;
  for (const auto& t : mesh.tets) {
    Eigen::Matrix3d D;
    for (int s = 0; s < 3; ++s) D.col(s) = mesh.rest_positions_World_mm.col(t[s + 1]) - mesh.rest_positions_World_mm.col(t[0]);
    ASSERT_GT(D.determinant(), 0.0);
    total += D.determinant() / 6.0;
  }
  EXPECT_NEAR(total, 30.0 * 20.0 * 100.0, 1e-6);
}

TEST(BoxMesh, SurfaceIsClosedAndOutward) {
  const TetMesh mesh = make_box_tet_mesh(2, 2, 2, Eigen::Vector3d(1, 1, 1));
  // Each boundary square face of the 2x2x2 grid is split in two: 6 sides * 4 squares * 2.
  EXPECT_EQ(mesh.surface_tris.size(), 48u);
  // Divergence theorem: sum over faces of (centroid . n) * area / 3 = volume.
  double volume = 0;
  for (const auto& f : mesh.surface_tris) {
    const Eigen::Vector3d a = mesh.rest_positions_World_mm.col(f[0]);
    const Eigen::Vector3d b = mesh.rest_positions_World_mm.col(f[1]);
    const Eigen::Vector3d c = mesh.rest_positions_World_mm.col(f[2]);
    volume += a.dot(b.cross(c)) / 6.0;
  }
  EXPECT_NEAR(volume, 1.0, 1e-12);
}

}  // namespace
}  // namespace arnav::host
