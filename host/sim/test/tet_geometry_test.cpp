#include <gtest/gtest.h>

#include "host/sim/tet_geometry.hpp"

namespace arnav::host {
namespace {

TetMesh unit_tet() {
  TetMesh mesh;
  mesh.rest_positions_World_mm.resize(3, 4);
  mesh.rest_positions_World_mm << 0, 1, 0, 0,  //
      0, 0, 1, 0,                             //
      0, 0, 0, 1;
  mesh.tets = {{0, 1, 2, 3}};
  return mesh;
}

TEST(TetGeometry, VolumeAndMass) {
  const TetMesh mesh = unit_tet();
  EXPECT_NEAR(signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[0]), 1.0 / 6.0, 1e-15);
  Material m;
  m.density_kg_per_mm3 = 6.0;
  const Eigen::VectorXd mass = lumped_masses_kg(mesh, {m});
  EXPECT_NEAR(mass.sum(), 1.0, 1e-12);
  EXPECT_NEAR(mass[3], 0.25, 1e-12);
}

TEST(TetGeometry, InvertedRestTetIsRejectedByIndex) {
  TetMesh mesh = unit_tet();
  std::swap(mesh.tets[0][1], mesh.tets[0][2]);
  try {
    lumped_masses_kg(mesh, {Material{}});
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tet 0"), std::string::npos);
  }
}

TEST(TetGeometry, LameParameters) {
  const Lame l = lame_from(Material{.youngs_modulus_kPa = 10.0, .poisson_ratio = 0.25});
  EXPECT_NEAR(l.mu_kPa, 4.0, 1e-12);
  EXPECT_NEAR(l.lambda_kPa, 4.0, 1e-12);
  EXPECT_THROW(lame_from(Material{.youngs_modulus_kPa = 1.0, .poisson_ratio = 0.5}), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::host
