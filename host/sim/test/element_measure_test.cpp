#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/LU>

#include "host/sim/element_measure.hpp"
#include "host/sim/graph_coloring.hpp"

namespace arnav::host {
namespace {

TEST(ElementMeasure, VonMisesOfUniaxialAndShearStress) {
  Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
  s(0, 0) = 7.0;
  EXPECT_NEAR(von_mises(s), 7.0, 1e-12);
  s.setZero();
  s(0, 1) = s(1, 0) = 2.0;
  EXPECT_NEAR(von_mises(s), std::sqrt(3.0) * 2.0, 1e-12);
  EXPECT_NEAR(von_mises(5.0 * Eigen::Matrix3d::Identity()), 0.0, 1e-12);  // hydrostatic
}

TEST(ElementMeasure, GreenStrainAndCorotatedStressAreRotationInvariant) {
  const Lame lame = lame_from(Material{.youngs_modulus_kPa = 10.0, .poisson_ratio = 0.3});
  const Eigen::Matrix3d F = Eigen::Vector3d(1.1, 1.0, 0.95).asDiagonal();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.5, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  EXPECT_NEAR(max_green_strain(F), 0.5 * (1.21 - 1.0), 1e-12);
  EXPECT_NEAR(max_green_strain(R * F), max_green_strain(F), 1e-12);
  const double vm = von_mises(corotated_linear_stress_kPa(F, lame));
  EXPECT_NEAR(von_mises(corotated_linear_stress_kPa(R * F, lame)), vm, 1e-9);
  // Uniaxial small strain with free lateral faces: sigma = E eps.
  const double nu = 0.3, eps = 1e-3;
  const Eigen::Matrix3d Fu = Eigen::Vector3d(1 + eps, 1 - nu * eps, 1 - nu * eps).asDiagonal();
  EXPECT_NEAR(corotated_linear_stress_kPa(Fu, lame)(0, 0), 10.0 * eps, 1e-9);
  EXPECT_NEAR(corotated_linear_stress_kPa(Fu, lame)(1, 1), 0.0, 1e-9);
}

TEST(ElementMeasure, PolarRotationIsProperForInvertedF) {
  const Eigen::Matrix3d F = Eigen::Vector3d(1.0, 1.0, -0.5).asDiagonal();
  const Eigen::Matrix3d R = polar_rotation(F);
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
  EXPECT_NEAR((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-12);
}

TEST(GraphColoring, ElementsOfOneColourShareNoVertex) {
  const std::vector<std::array<int, 4>> tets = {{0, 1, 2, 3}, {1, 2, 3, 4}, {4, 5, 6, 7}, {0, 5, 8, 9}, {10, 11, 12, 13}};
  const Coloring c = greedy_vertex_coloring(tets, 14);
  ASSERT_EQ(c.order.size(), tets.size());
  for (int col = 0; col < c.num_colors(); ++col) {
    std::vector<int> seen(14, 0);
    for (int k = c.color_offsets[col]; k < c.color_offsets[col + 1]; ++k)
      for (int v : tets[c.order[k]]) EXPECT_EQ(seen[v]++, 0) << "colour " << col << " vertex " << v;
  }
  EXPECT_EQ(c.num_colors(), 2);
}

}  // namespace
}  // namespace arnav::host
