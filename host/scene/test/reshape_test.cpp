#include <gtest/gtest.h>

#include <Eigen/LU>

#include <algorithm>
#include <stdexcept>

#include "host/mesh/box_mesh.hpp"
#include "host/scene/reshape.hpp"

namespace arnav::host {
namespace {

// A 100 x 60 x 40 mm box as a scene: the volume, its boundary as the organ surface, one
// vessel segment through it.
Scene box_scene() {
  Scene s;
  s.source = "box";
  s.problem.mesh = make_box_tet_mesh(10, 6, 4, Eigen::Vector3d(100, 60, 40));
  s.organ_surface.positions_World_mm = s.problem.mesh.rest_positions_World_mm;
  s.organ_surface.tris = s.problem.mesh.surface_tris;
  VesselTree v;
  v.nodes_World_mm.resize(3, 2);
  v.nodes_World_mm << 10, 90, 30, 30, 20, 20;
  v.radius_mm = {2.0, 1.5};
  v.segments = {{0, 1}};
  s.problem.vessels = v;
  return s;
}

double total_volume_mm3(const TetMesh& m) {
  double v = 0;
  for (const auto& t : m.tets) {
    Eigen::Matrix3d d;
    for (int s = 0; s < 3; ++s) d.col(s) = m.rest_positions_World_mm.col(t[s + 1]) - m.rest_positions_World_mm.col(t[0]);
    v += d.determinant() / 6.0;
  }
  return v;
}

TEST(SceneReshape, ScaleAloneScalesAboutTheCentroidAndCarriesEverything) {
  const Scene s = box_scene();
  const Scene r = reshaped_scene(s, {.scale = 1.5});
  const Eigen::Matrix3Xd& x0 = s.problem.mesh.rest_positions_World_mm;
  const Eigen::Matrix3Xd& x1 = r.problem.mesh.rest_positions_World_mm;
  const Eigen::Vector3d c = x0.rowwise().mean();
  EXPECT_LT((x1.rowwise().mean() - c).norm(), 1e-9);
  EXPECT_LT(((x1.colwise() - c) - 1.5 * (x0.colwise() - c)).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(total_volume_mm3(r.problem.mesh), 1.5 * 1.5 * 1.5 * 100 * 60 * 40, 1e-6);
  EXPECT_LT((r.organ_surface.positions_World_mm - x1).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(r.problem.vessels->radius_mm[0], 3.0, 1e-12);
  EXPECT_LT((r.problem.vessels->nodes_World_mm.col(0) - (c + 1.5 * (Eigen::Vector3d(10, 30, 20) - c))).norm(), 1e-9);
  EXPECT_EQ(r.problem.mesh.tets, s.problem.mesh.tets);
  EXPECT_NE(r.source.find("scale 1.5"), std::string::npos);
}

TEST(SceneReshape, WarpMovesTheFarthestVertexByItsAmplitudeSmoothlyAndDependsOnTheSeed) {
  const Scene s = box_scene();
  const Scene a = reshaped_scene(s, {.warp_mm = 4.0, .seed = 3});
  const Eigen::Matrix3Xd d = a.problem.mesh.rest_positions_World_mm - s.problem.mesh.rest_positions_World_mm;
  EXPECT_NEAR(d.colwise().norm().maxCoeff(), 4.0, 1e-9);
  // Smooth (a wavelength of half the diagonal): the displacement's change along an edge is a
  // small fraction of the edge's length; noise of this amplitude would reach 0.8 on 10 mm edges.
  double largest_strain = 0.0;
  for (const auto& t : s.problem.mesh.tets)
    for (const auto& e : kTetEdges) {
      const double edge_mm = (s.problem.mesh.rest_positions_World_mm.col(t[e[0]]) - s.problem.mesh.rest_positions_World_mm.col(t[e[1]])).norm();
      largest_strain = std::max(largest_strain, (d.col(t[e[0]]) - d.col(t[e[1]])).norm() / edge_mm);
    }
  EXPECT_LT(largest_strain, 0.3);
  EXPECT_GT(largest_strain, 0.01);
  EXPECT_NEAR(total_volume_mm3(a.problem.mesh), 100 * 60 * 40, 0.1 * 100 * 60 * 40);
  EXPECT_LT((a.organ_surface.positions_World_mm - a.problem.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff(), 1e-9);
  const Scene same = reshaped_scene(s, {.warp_mm = 4.0, .seed = 3});
  EXPECT_EQ(same.problem.mesh.rest_positions_World_mm, a.problem.mesh.rest_positions_World_mm);
  const Scene other = reshaped_scene(s, {.warp_mm = 4.0, .seed = 4});
  EXPECT_GT((other.problem.mesh.rest_positions_World_mm - a.problem.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff(), 0.5);
}

TEST(SceneReshape, OutOfRangeSettingsAndInvertingWarpsAreRefusedNamingTheFix) {
  const Scene s = box_scene();
  EXPECT_THROW(reshaped_scene(s, {.scale = 0.0}), std::invalid_argument);
  EXPECT_THROW(reshaped_scene(s, {.warp_mm = -1.0}), std::invalid_argument);
  try {
    reshaped_scene(s, {.warp_mm = 200.0});
    FAIL() << "a 200 mm warp of a 100 mm box must invert tets";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("smaller warp"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("box"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arnav::host
