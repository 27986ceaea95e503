// Lone-beam verification against the cantilever formulas (reference-figures.md) and the
// embedding map J (rigid motions of the tissue must map to rigid motions of the beam).
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <numbers>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/beams/beam_element.hpp"
#include "host/sim/beams/beam_embedding.hpp"

namespace arnav::host {
namespace {

// Cantilever of n beam elements along `axis` clamped at node 0; returns the displacement
// vector (6 DOF per node) under the given nodal load vector.
Eigen::VectorXd solve_cantilever(int n, double L, const Eigen::Vector3d& axis, const BeamSection& s, double E,
                                 double nu, const Eigen::VectorXd& load) {
  const int dof = 6 * (n + 1);
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(dof, dof);
  for (int e = 0; e < n; ++e) {
    const Eigen::Vector3d a = axis * (L * e / n), b = axis * (L * (e + 1) / n);
    K.block<12, 12>(6 * e, 6 * e) += beam_world_stiffness(a, b, s, E, nu);
  }
  const Eigen::MatrixXd Kf = K.bottomRightCorner(dof - 6, dof - 6);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(dof);
  u.tail(dof - 6) = Kf.ldlt().solve(load.tail(dof - 6));
  return u;
}

TEST(BeamElement, CantileverEndLoadMatchesTimoshenko) {
  const double L = 100, E = 500, nu = 0.45, P = 0.01;
  const BeamSection s = rectangle_section(4.0, 6.0);
  const double G = E / (2 * (1 + nu));
  for (int n : {1, 4}) {
    Eigen::VectorXd load = Eigen::VectorXd::Zero(6 * (n + 1));
    load[6 * n + 1] = P;  // tip force along y: bending about z
    load[6 * n + 2] = P;  // and along z: bending about y
    const Eigen::VectorXd u = solve_cantilever(n, L, Eigen::Vector3d::UnitX(), s, E, nu, load);
    const double shear = P * L / (s.shear_factor * G * s.area_mm2);
    EXPECT_NEAR(u[6 * n + 1], P * L * L * L / (3 * E * s.I_z_mm4) + shear, 1e-9) << n;
    EXPECT_NEAR(u[6 * n + 2], P * L * L * L / (3 * E * s.I_y_mm4) + shear, 1e-9) << n;
    // Tip rotation PL^2/(2EI): +z rotation for a +y deflection, -y rotation for +z.
    EXPECT_NEAR(u[6 * n + 5], P * L * L / (2 * E * s.I_z_mm4), 1e-9);
    EXPECT_NEAR(u[6 * n + 4], -P * L * L / (2 * E * s.I_y_mm4), 1e-9);
  }
}

TEST(BeamElement, AxialAndTorsion) {
  const double L = 50, E = 600, nu = 0.3, P = 0.2, T = 0.05;
  const BeamSection s = tube_section(3.0, 0.5);
  Eigen::VectorXd load = Eigen::VectorXd::Zero(6 * 4);
  load[18] = P;
  load[21] = T;
  const Eigen::VectorXd u = solve_cantilever(3, L, Eigen::Vector3d::UnitX(), s, E, nu, load);
  EXPECT_NEAR(u[18], P * L / (E * s.area_mm2), 1e-12);
  EXPECT_NEAR(u[21], T * L / (E / (2 * (1 + nu)) * s.J_torsion_mm4), 1e-12);
}

TEST(BeamElement, UniformLoadEulerBernoulliLimit) {
  // Consistent nodal loads of a uniform load q: (qh/2, qh^2/12) per element end; with shear
  // made negligible the nodal deflection is exact: q L^4 / (8 E I).
  const double L = 80, E = 500, nu = 0.45, q = 1e-4;
  BeamSection s = rectangle_section(3.0, 3.0);
  s.shear_factor = 1e12;
  const int n = 5;
  const double h = L / n;
  Eigen::VectorXd load = Eigen::VectorXd::Zero(6 * (n + 1));
  for (int e = 0; e < n; ++e) {
    load[6 * e + 2] += q * h / 2;
    load[6 * (e + 1) + 2] += q * h / 2;
    load[6 * e + 4] += -q * h * h / 12;  // theta_y = -dw/dx: moments carry the opposite sign
    load[6 * (e + 1) + 4] += q * h * h / 12;
  }
  const Eigen::VectorXd u = solve_cantilever(n, L, Eigen::Vector3d::UnitX(), s, E, nu, load);
  EXPECT_NEAR(u[6 * n + 2], q * L * L * L * L / (8 * E * s.I_y_mm4), 1e-9 * u[6 * n + 2] + 1e-12);
}

TEST(BeamElement, RigidMotionsCostNoEnergyInAnyOrientation) {
  const Eigen::Vector3d a(1, 2, 3), b(4, -1, 7);
  const Eigen::Matrix<double, 12, 12> K = beam_world_stiffness(a, b, tube_section(2.0, 0.3), 500, 0.45);
  EXPECT_LT((K - K.transpose()).norm(), 1e-9 * K.norm());
  const Eigen::Vector3d t(0.3, -0.2, 0.5), w(0.1, 0.4, -0.2);
  Eigen::Matrix<double, 12, 1> u;
  u << t + w.cross(a), w, t + w.cross(b), w;
  EXPECT_LT((K * u).norm(), 1e-10 * K.norm());
  // A bending mode is not free.
  Eigen::Matrix<double, 12, 1> bend = Eigen::Matrix<double, 12, 1>::Zero();
  bend.segment<3>(9) = Eigen::Vector3d(0, 0, 0.1);
  EXPECT_GT(bend.dot(K * bend), 0.0);
}

TEST(BeamEmbedding, JacobianMapsAffineFieldsExactly) {
  const TetMesh mesh = make_box_tet_mesh(1, 1, 1, Eigen::Vector3d(10, 10, 10));
  const auto& tet = mesh.tets[2];
  const Eigen::Vector4d bary(0.1, 0.2, 0.3, 0.4);
  const Eigen::Matrix<double, 6, 12> J = embedding_jacobian(mesh.rest_positions_World_mm, tet, bary);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) p += bary[k] * mesh.rest_positions_World_mm.col(tet[k]);
  // Infinitesimal rotation w plus translation t: the point moves by t + w x p, rotates by w.
  // A symmetric strain adds displacement but no rotation.
  const Eigen::Vector3d t(1, -2, 0.5), w(0.01, -0.02, 0.03);
  Eigen::Matrix3d strain;
  strain << 0.01, 0.002, 0, 0.002, -0.01, 0.003, 0, 0.003, 0.02;
  Eigen::Matrix<double, 12, 1> u;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d X = mesh.rest_positions_World_mm.col(tet[k]);
    u.segment<3>(3 * k) = t + w.cross(X) + strain * X;
  }
  const Eigen::Matrix<double, 6, 1> q = J * u;
  EXPECT_LT((q.head<3>() - (t + w.cross(p) + strain * p)).norm(), 1e-12);
  EXPECT_LT((q.tail<3>() - w).norm(), 1e-12);
}

TEST(BeamEmbedding, SuperElementsLocateNodesAndKeepRigidModesFree) {
  const TetMesh mesh = make_box_tet_mesh(4, 4, 8, Eigen::Vector3d(20, 20, 40));
  VesselTree tree;
  tree.nodes_World_mm.resize(3, 3);
  tree.nodes_World_mm << 10, 11, 9, 10, 9.5, 10.5, 2, 20, 38;
  tree.radius_mm = {2.0, 1.5, 1.0};
  tree.segments = {{0, 1}, {1, 2}};
  Material vessel{.youngs_modulus_kPa = 500.0, .poisson_ratio = 0.45};
  const VesselEmbedding e = embed_vessels(mesh, tree, vessel, {.max_element_length_mm = 5.0});
  EXPECT_EQ(e.segments.size(), 4u + 4u);  // 18 mm and 18 mm segments in 5 mm pieces
  const Eigen::Matrix3Xd p = beam_node_positions(e, mesh, mesh.rest_positions_World_mm);
  EXPECT_LT((p - e.node_rest_World_mm).norm(), 1e-10);
  for (const auto& b : e.beams) {
    const Eigen::Vector3d t(0.3, -0.2, 0.5), w(0.1, 0.4, -0.2);
    Eigen::VectorXd u(3 * b.vertices.size());
    for (std::size_t k = 0; k < b.vertices.size(); ++k)
      u.segment<3>(3 * k) = t + w.cross(Eigen::Vector3d(mesh.rest_positions_World_mm.col(b.vertices[k])));
    EXPECT_LT((b.K_rest * u).norm(), 1e-9 * b.K_rest.norm());
    EXPECT_GT(b.K_rest.trace(), 0.0);
  }
}

TEST(BeamEmbedding, NodeOutsideTheMeshIsReportedByIndex) {
  const TetMesh mesh = make_box_tet_mesh(2, 2, 2, Eigen::Vector3d(10, 10, 10));
  VesselTree tree;
  tree.nodes_World_mm.resize(3, 2);
  tree.nodes_World_mm << 5, 5, 5, 5, 5, 30;
  tree.radius_mm = {1.0, 1.0};
  tree.segments = {{0, 1}};
  try {
    embed_vessels(mesh, tree, Material{});
    FAIL() << "expected an exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vessel node 1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arnav::host
