// TetGen meshing through libtet, surface decimation and the analytic shapes.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <Eigen/LU>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/mesh/surface_decimate.hpp"
#include "host/mesh/surface_shapes.hpp"
#include "host/mesh/test/test_paths.hpp"
#include "host/mesh/mesh_quality.hpp"
#include "host/mesh/tetgen_mesher.hpp"

namespace arnav::host {
namespace {

TEST(Shapes, EllipsoidIsClosedOutwardAndConverges) {
  TriMesh s = make_ellipsoid_surface(Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(10, 8, 6), 4);
  EXPECT_EQ(s.tris.size(), 20u * 256u);
  const SurfaceCheck c = validate_closed_surface(s, "ellipsoid");
  EXPECT_FALSE(c.flipped);
  const double exact = 4.0 / 3.0 * std::numbers::pi * 10 * 8 * 6;
  EXPECT_NEAR(c.volume_mm3 / exact, 1.0, 0.01);
  EXPECT_NEAR(winding_number(s, Eigen::Vector3d(1, 2, 3)), 1.0, 1e-9);
  EXPECT_NEAR(winding_number(s, Eigen::Vector3d(20, 2, 3)), 0.0, 1e-9);
}

TEST(TetGen, MeshesEllipsoidKeepingItsSurface) {
  const TriMesh s = make_ellipsoid_surface(Eigen::Vector3d::Zero(), Eigen::Vector3d(20, 15, 10), 3);
  TetGenReport rep;
  const TetMesh m = tetrahedralize_surface(s, {.max_radius_edge_ratio = 1.5, .max_volume_mm3 = 20.0}, "ellipsoid", &rep);
  EXPECT_EQ(rep.switches, "-pQYq1.5a20");
  TriMesh copy = s;
  const double surface_volume = validate_closed_surface(copy, "e").volume_mm3;
  double volume = 0;
  for (const auto& t : m.tets) {
    Eigen::Matrix3d D;
    for (int k = 0; k < 3; ++k) D.col(k) = m.rest_positions_World_mm.col(t[k + 1]) - m.rest_positions_World_mm.col(t[0]);
    ASSERT_GT(D.determinant(), 0.0);
    volume += D.determinant() / 6.0;
  }
  EXPECT_NEAR(volume, surface_volume, 1e-6 * surface_volume);
  // -Y: the input vertices come first, unchanged; the boundary is the input surface.
  EXPECT_TRUE(m.rest_positions_World_mm.leftCols(s.positions_World_mm.cols()).isApprox(s.positions_World_mm));
  EXPECT_EQ(m.surface_tris.size(), s.tris.size());
  EXPECT_GT(m.num_vertices(), s.positions_World_mm.cols());  // interior refined to the size bound
}

TEST(TetGen, OptimisationLevelAndDihedralBoundAreApplied) {
  const TriMesh s = make_ellipsoid_surface(Eigen::Vector3d::Zero(), Eigen::Vector3d(20, 15, 10), 3);
  TetGenReport rep;
  TetGenSettings opt{.max_radius_edge_ratio = 1.5, .min_dihedral_deg = 12.0, .max_volume_mm3 = 20.0};
  opt.optimisation_level = 7;
  const TetMesh m = tetrahedralize_surface(s, opt, "ellipsoid", &rep);
  EXPECT_EQ(rep.switches, "-pQYq1.5/12a20O7/7");
  // Interior tets meet the bound; slivers can only be made of surface vertices (kept by -Y).
  const TetMeshQuality q = tet_mesh_quality(m);
  EXPECT_GT(q.p01_dihedral_deg, 12.0) << describe(q);
  opt.optimisation_level = 11;
  EXPECT_THROW(tetrahedralize_surface(s, opt, "ellipsoid"), LoadError);
}

TEST(TetGen, SelfIntersectingSofaSurfaceIsRejected) {
  // liver-smooth.obj is closed and manifold but 16 face pairs intersect.
  const TriMesh s = load_surface(test::data_meshes() + "liver-smooth.obj");
  try {
    tetrahedralize_surface(s, {}, "liver-smooth.obj");
    FAIL() << "expected a LoadError";
  } catch (const LoadError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("liver-smooth.obj"), std::string::npos) << m;
    EXPECT_NE(m.find("self-intersection"), std::string::npos) << m;
    EXPECT_NE(m.find("Fix:"), std::string::npos) << m;
  }
}

TEST(TetGen, RealLiverAtPaperSize) {
  const TriMesh s = load_surface(test::data_meshes() + "liver.vtk");
  const TetMesh m = tetrahedralize_surface(s, {.max_radius_edge_ratio = 1.8}, "liver.vtk");
  // Paper 000: 6,510 vertices / 24,398 tetrahedra.
  EXPECT_NEAR(m.num_vertices(), 6500, 400);
  EXPECT_NEAR(m.num_tets(), 24400, 1500);
}

TEST(Decimation, KeepsClosedManifoldAndShape) {
  TriMesh s = make_ellipsoid_surface(Eigen::Vector3d::Zero(), Eigen::Vector3d(30, 20, 10), 4);
  TriMesh copy = s;
  const double before = validate_closed_surface(copy, "e").volume_mm3;
  const DecimationReport r = decimate_surface(s, 400);
  EXPECT_EQ(r.input_vertices, 2562);
  EXPECT_EQ(r.output_vertices, 400);
  EXPECT_EQ(s.positions_World_mm.cols(), 400);
  const SurfaceCheck c = validate_closed_surface(s, "decimated");  // throws if open/non-manifold
  EXPECT_FALSE(c.flipped);
  EXPECT_NEAR(c.volume_mm3 / before, 1.0, 0.03);
  EXPECT_THROW(decimate_surface(s, 3), std::invalid_argument);
}

TEST(Decimation, RealLiverCoarseVariantMeshes) {
  TriMesh s = load_surface(test::data_meshes() + "liver.vtk");
  const DecimationReport r = decimate_surface(s, 1000);
  EXPECT_EQ(r.output_vertices, 1000);
  const SurfaceCheck c = validate_closed_surface(s, "decimated liver");
  EXPECT_NEAR(c.volume_mm3, 1.477e6, 0.03e6);
  const TetMesh m = tetrahedralize_surface(s, {.max_radius_edge_ratio = 2.0}, "decimated liver");
  EXPECT_LT(m.num_tets(), 8000);
}

}  // namespace
}  // namespace arnav::host
