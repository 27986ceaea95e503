// Verification of the XPBD model: rigid-motion invariance, convergence toward the analytic
// static solution of a hanging bar as iterations grow, dissipation, recovery from
// inverted elements, attachments, and identical results for 1 and 2 threads.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "host/scene/box_mesh.hpp"
#include "host/sim/xpbd/xpbd_model.hpp"

namespace arnav::host {
namespace {

SimProblem box_problem(int nx, int ny, int nz, const Eigen::Vector3d& size_mm, const Material& m, bool gravity) {
  SimProblem p;
  p.mesh = make_box_tet_mesh(nx, ny, nz, size_mm);
  p.region_materials = {m};
  if (!gravity) p.gravity_World_mm_s2.setZero();
  return p;
}

ModelConfig config(int iterations, int substeps = 1, int threads = 1) {
  ModelConfig c;
  c.kind = "xpbd";
  c.iterations = iterations;
  c.substeps = substeps;
  c.tolerance = 0.0;
  c.threads = threads;
  return c;
}

TEST(Xpbd, RotatedRestStateStaysAtRest) {
  const SimProblem p = box_problem(4, 3, 2, {40, 30, 20}, Material{}, false);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.1, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const Eigen::Matrix3Xd x_rot = (R * p.mesh.rest_positions_World_mm).colwise() + Eigen::Vector3d(5, -7, 11);
  XpbdModel model(p, config(10, 2));
  model.set_state(x_rot, Eigen::Matrix3Xd::Zero(3, x_rot.cols()));
  for (int k = 0; k < 10; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    ASSERT_TRUE(s.healthy) << s.warning;
    EXPECT_LT(s.final_residual, 1e-9);
  }
  EXPECT_LT((model.positions_World_mm() - x_rot).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(model.elastic_energy(), 0.0, 1e-12);
  for (const ElementMeasure& m : model.element_measures()) {
    EXPECT_NEAR(m.von_mises_stress_kPa, 0.0, 1e-9);
    EXPECT_NEAR(m.volume_ratio, 1.0, 1e-12);
  }
}

// Bar hanging from its top face, nu = 0: exact uniaxial stress rho g (L - z) and end
// displacement rho g L^2 / (2E) (0.6 % strain, so the linear reference holds).
struct HangingBar {
  SimProblem problem;
  double analytic_sag_mm;
  int n = 2, nz = 8;
  HangingBar() {
    Material m;
    m.youngs_modulus_kPa = 100.0;
    m.poisson_ratio = 0.0;
    m.damping_mass_per_s = 30.0;
    const double L = 120.0;
    problem = box_problem(n, n, nz, {30, 30, L}, m, true);
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) problem.fixed_vertices.push_back(box_vertex_index(n, n, i, j, nz));
    analytic_sag_mm = 1.06e-6 * 9810.0 * L * L / (2.0 * m.youngs_modulus_kPa);
  }
  // Settled positions after 1.7 s of simulated time at 60 Hz (slowest mode ~20 Hz, damped).
  // `healthy` tells whether every step reported healthy.
  Eigen::Matrix3Xd settle(int iterations, int substeps, bool* healthy) const {
    XpbdModel model(problem, config(iterations, substeps));
    *healthy = true;
    for (int k = 0; k < 100; ++k) *healthy = model.step(1.0 / 60.0).healthy && *healthy;
    return model.positions_World_mm();
  }
  double sag(const Eigen::Matrix3Xd& x) const {
    double s = 0.0;
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) s += -x(2, box_vertex_index(n, n, i, j, 0));
    return s / ((n + 1) * (n + 1));
  }
};

// The converged static solution matches the analytic sag (discretisation error of the
// 2x2x8 Kuhn mesh with nu = 0: stated bound 1 %), and the steady state of real-time settings
// approaches it as the iterations per substep grow (RMS nodal distance, monotone).
TEST(Xpbd, ConvergesTowardStaticSolutionAsIterationsGrow) {
  const HangingBar bar;
  bool healthy = false;
  const Eigen::Matrix3Xd reference = bar.settle(128, 4, &healthy);
  EXPECT_TRUE(healthy);
  const double sag = bar.sag(reference);
  RecordProperty("converged_sag_mm", std::to_string(sag));
  RecordProperty("analytic_sag_mm", std::to_string(bar.analytic_sag_mm));
  EXPECT_NEAR(sag, bar.analytic_sag_mm, 0.01 * bar.analytic_sag_mm);
  double previous = 1e9;
  for (int iterations : {2, 8, 32}) {
    const Eigen::Matrix3Xd x = bar.settle(iterations, 4, &healthy);
    // Too little work settles in a wrong state that stores more energy than gravity put
    // in: the energy ledger must report it.
    if (iterations == 2) EXPECT_FALSE(healthy);
    if (iterations == 32) EXPECT_TRUE(healthy);
    const double rms_mm = std::sqrt((x - reference).colwise().squaredNorm().mean());
    RecordProperty("rms_distance_mm_at_" + std::to_string(iterations), std::to_string(rms_mm));
    EXPECT_LT(rms_mm, previous) << iterations << " iterations";
    previous = rms_mm;
  }
  EXPECT_LT(previous, 0.2 * bar.analytic_sag_mm);
}

TEST(Xpbd, EnergyIsBoundedUndampedAndDissipatedWithDamping) {
  for (double beta : {0.0, 0.01}) {
    Material m;
    m.damping_stiffness_s = beta;
    const SimProblem p = box_problem(4, 2, 2, {40, 20, 20}, m, false);
    XpbdModel model(p, config(20, 4));
    Eigen::Matrix3Xd x = p.mesh.rest_positions_World_mm;
    x.row(0) *= 1.05;
    model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
    const double e0 = model.elastic_energy();
    double last = e0, max_e = 0.0;
    for (int k = 0; k < 300; ++k) {
      const StepSummary s = model.step(1.0 / 60.0);
      ASSERT_TRUE(s.healthy) << s.warning;
      last = s.kinetic_energy + s.elastic_energy;
      max_e = std::max(max_e, last);
    }
    EXPECT_LE(max_e, 1.001 * e0) << "beta " << beta;  // implicit: never gains energy
    if (beta > 0.0) EXPECT_LT(last, 0.01 * e0);
  }
}

TEST(Xpbd, InvertedElementsRecover) {
  Material m;
  m.damping_mass_per_s = 10.0;
  const SimProblem p = box_problem(2, 2, 2, {20, 20, 20}, m, false);
  XpbdModel model(p, config(20, 2));
  Eigen::Matrix3Xd x = p.mesh.rest_positions_World_mm;
  x(2, box_vertex_index(2, 2, 1, 1, 1)) = 25.0;  // centre vertex pushed through the top
  model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  const StepSummary first = model.step(1.0 / 60.0);
  EXPECT_NE(first.warning.find("inverted tets"), std::string::npos) << first.warning;
  StepSummary s;
  for (int k = 0; k < 300; ++k) s = model.step(1.0 / 60.0);
  EXPECT_TRUE(s.healthy) << s.warning;
  EXPECT_TRUE(s.warning.empty()) << s.warning;
  for (const ElementMeasure& e : model.element_measures()) EXPECT_GT(e.volume_ratio, 0.9);
}

TEST(Xpbd, AttachmentPullsAndReleaseReturnsToRest) {
  Material m;
  m.damping_mass_per_s = 10.0;
  SimProblem p = box_problem(4, 2, 2, {40, 20, 20}, m, false);
  for (int k = 0; k <= 2; ++k)
    for (int j = 0; j <= 2; ++j) p.fixed_vertices.push_back(box_vertex_index(4, 2, 0, j, k));
  XpbdModel model(p, config(20, 2));
  const int tip = box_vertex_index(4, 2, 4, 1, 1);
  const Eigen::Vector3d rest_tip = p.mesh.rest_positions_World_mm.col(tip);
  const AttachmentId id = model.add_attachment(
      {.point = {{tip}, {1.0}}, .target_World_mm = rest_tip + Eigen::Vector3d(10, 0, 0), .stiffness_mN_per_mm = 50});
  for (int k = 0; k < 300; ++k) ASSERT_TRUE(model.step(1.0 / 60.0).healthy);
  const double pulled = model.positions_World_mm()(0, tip) - rest_tip.x();
  EXPECT_GT(pulled, 1.0);
  EXPECT_LT(pulled, 10.0);
  model.remove_attachment(id);
  for (int k = 0; k < 300; ++k) ASSERT_TRUE(model.step(1.0 / 60.0).healthy);
  EXPECT_LT((model.positions_World_mm() - p.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff(), 1e-2);
}

// Colours touch disjoint vertices, so the parallel sweep computes exactly what the serial
// sweep computes.
TEST(Xpbd, TwoThreadsGiveTheSameResultAsOne) {
  const SimProblem p = box_problem(3, 3, 3, {30, 30, 30}, Material{}, true);
  SimProblem fixed = p;
  for (int j = 0; j <= 3; ++j)
    for (int i = 0; i <= 3; ++i) fixed.fixed_vertices.push_back(box_vertex_index(3, 3, i, j, 3));
  XpbdModel serial(fixed, config(5, 2, 1));
  XpbdModel parallel(fixed, config(5, 2, 2));
  EXPECT_GT(serial.num_colors(), 1);
  for (int k = 0; k < 2; ++k) {
    serial.step(1.0 / 60.0);
    parallel.step(1.0 / 60.0);
  }
  EXPECT_EQ((serial.positions_World_mm() - parallel.positions_World_mm()).cwiseAbs().maxCoeff(), 0.0);
}

TEST(Xpbd, BadInputIsRejectedWithAReason) {
  const SimProblem p = box_problem(2, 1, 1, {20, 10, 10}, Material{}, true);
  XpbdModel model(p, config(5));
  EXPECT_THROW(model.set_fixed_vertices({100}), std::invalid_argument);
  EXPECT_THROW(model.step(-1.0), std::invalid_argument);
  EXPECT_THROW(model.add_attachment({.point = {{0, 1, 2, 3, 4}, {0.2, 0.2, 0.2, 0.2, 0.2}}}), std::invalid_argument);
  EXPECT_THROW(XpbdModel(p, config(0)), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::host
