// Verification of the XPBD model, for both energies (corotated, stable Neo-Hookean):
// rigid-motion invariance, convergence toward the analytic static solution of a hanging
// bar as the sweeps grow, dissipation, recovery from inverted elements, attachments, and
// identical results for 1 and 2 threads; for the Neo-Hookean energy also its small-strain
// moduli against E and nu, zero correction of a rotated rest state and a flipped tet.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <iostream>
#include <random>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/test/box_problem.hpp"
#include "host/sim/embedded_elements.hpp"
#include "host/sim/tet_geometry.hpp"
#include "host/sim/xpbd/xpbd_model.hpp"

namespace arnav::host {
namespace {

using test::box_problem;

// The Neo-Hookean energy runs one sweep per substep (small steps), so for it the same
// work, substeps x iterations sweeps, is given as substeps.
ModelConfig config(int iterations, int substeps = 1, int threads = 1, const std::string& energy = "") {
  ModelConfig c;
  c.kind = "xpbd";
  c.energy = energy;
  if (energy == "neo_hookean") {
    substeps *= iterations;
    iterations = 1;
  }
  c.iterations = iterations;
  c.substeps = substeps;
  c.tolerance = 0.0;
  c.threads = threads;
  return c;
}

// Every test below runs with both energies (ModelConfig::energy).
class XpbdEnergy : public ::testing::TestWithParam<std::string> {};
INSTANTIATE_TEST_SUITE_P(Energies, XpbdEnergy, ::testing::Values("neo_hookean", "corotated"));

TEST_P(XpbdEnergy, RotatedRestStateStaysAtRest) {
  const SimProblem p = box_problem(4, 3, 2, {40, 30, 20}, Material{}, false);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(2.1, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  const Eigen::Matrix3Xd x_rot = (R * p.mesh.rest_positions_World_mm).colwise() + Eigen::Vector3d(5, -7, 11);
  XpbdModel model(p, config(10, 2, 1, GetParam()));
  EXPECT_EQ(model.energy(), GetParam());
  model.set_state(x_rot, Eigen::Matrix3Xd::Zero(3, x_rot.cols()));
  for (int k = 0; k < 10; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    ASSERT_TRUE(s.healthy) << s.warning;
    EXPECT_LT(s.final_residual, 1e-9);
  }
  EXPECT_LT((model.positions_World_mm() - x_rot).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_NEAR(model.elastic_energy(), 0.0, 1e-10);  // round-off of |F|^2 - 3 times mu V
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
  // `redone`: steps the step control redid with more substeps (step_control.hpp).
  Eigen::Matrix3Xd settle(int iterations, int substeps, bool* healthy, const std::string& energy, int* redone = nullptr) const {
    XpbdModel model(problem, config(iterations, substeps, 1, energy));
    *healthy = true;
    for (int k = 0; k < 100; ++k) *healthy = model.step(1.0 / 60.0).healthy && *healthy;
    if (redone) *redone = model.step_control().redone_steps();
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
TEST_P(XpbdEnergy, ConvergesTowardStaticSolutionAsIterationsGrow) {
  const HangingBar bar;
  bool healthy = false;
  const Eigen::Matrix3Xd reference = bar.settle(128, 4, &healthy, GetParam());
  EXPECT_TRUE(healthy);
  const double sag = bar.sag(reference);
  RecordProperty("converged_sag_mm", std::to_string(sag));
  RecordProperty("analytic_sag_mm", std::to_string(bar.analytic_sag_mm));
  EXPECT_NEAR(sag, bar.analytic_sag_mm, 0.01 * bar.analytic_sag_mm);
  double previous = 1e9;
  for (int iterations : {2, 8, 32}) {
    int redone = 0;
    const Eigen::Matrix3Xd x = bar.settle(iterations, 4, &healthy, GetParam(), &redone);
    // Too little work settles in a wrong state that stores more energy than gravity put
    // in: the energy ledger reports it and the step control redoes those steps with more
    // substeps, so the run stays healthy (issue 29).
    if (iterations == 2) {
      EXPECT_GT(redone, 0);
      EXPECT_TRUE(healthy);
    }
    if (iterations == 32) {
      EXPECT_TRUE(healthy);
    }
    const double rms_mm = std::sqrt((x - reference).colwise().squaredNorm().mean());
    RecordProperty("rms_distance_mm_at_" + std::to_string(iterations), std::to_string(rms_mm));
    EXPECT_LT(rms_mm, previous) << iterations << " iterations";
    previous = rms_mm;
  }
  EXPECT_LT(previous, 0.2 * bar.analytic_sag_mm);
}

TEST_P(XpbdEnergy, EnergyIsBoundedUndampedAndDissipatedWithDamping) {
  for (double beta : {0.0, 0.01}) {
    Material m;
    m.damping_stiffness_s = beta;
    const SimProblem p = box_problem(4, 2, 2, {40, 20, 20}, m, false);
    XpbdModel model(p, config(20, 4, 1, GetParam()));
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
    if (beta > 0.0) {
      EXPECT_LT(last, 0.01 * e0);
    }
  }
}

TEST_P(XpbdEnergy, InvertedElementsRecover) {
  Material m;
  m.damping_mass_per_s = 10.0;
  const SimProblem p = box_problem(2, 2, 2, {20, 20, 20}, m, false);
  XpbdModel model(p, config(20, 2, 1, GetParam()));
  Eigen::Matrix3Xd x = p.mesh.rest_positions_World_mm;
  ASSERT_EQ(x.cols(), 27);
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

TEST_P(XpbdEnergy, AttachmentPullsAndReleaseReturnsToRest) {
  Material m;
  m.damping_mass_per_s = 10.0;
  SimProblem p = box_problem(4, 2, 2, {40, 20, 20}, m, false);
  test::clamp_x0_face(p);
  XpbdModel model(p, config(20, 2, 1, GetParam()));
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
TEST_P(XpbdEnergy, TwoThreadsGiveTheSameResultAsOne) {
  const SimProblem p = box_problem(3, 3, 3, {30, 30, 30}, Material{}, true);
  SimProblem fixed = p;
  for (int j = 0; j <= 3; ++j)
    for (int i = 0; i <= 3; ++i) fixed.fixed_vertices.push_back(box_vertex_index(3, 3, i, j, 3));
  XpbdModel serial(fixed, config(5, 2, 1, GetParam()));
  XpbdModel parallel(fixed, config(5, 2, 2, GetParam()));
  // Both halves hold tets, so the two threads really sweep at the same time.
  const std::array<int, 5> groups = serial.group_tets();
  EXPECT_GT(groups[0], 0);
  EXPECT_GT(groups[1], 0);
  EXPECT_EQ(groups[0] + groups[1] + groups[2] + groups[3] + groups[4], fixed.mesh.num_tets());
  for (int k = 0; k < 2; ++k) {
    serial.step(1.0 / 60.0);
    parallel.step(1.0 / 60.0);
  }
  EXPECT_EQ((serial.positions_World_mm() - parallel.positions_World_mm()).cwiseAbs().maxCoeff(), 0.0);
}

// Local updates (apply_mesh_change) re-batch only the changed tets: after many changes
// the batches must still be a valid parallel schedule (lanes of a batch on distinct
// vertices, groups that run at the same time on disjoint vertices, every elastic tet in
// exactly one lane with its rest shape, none below the quality bound), stay about as
// full as a fresh build's (SIMD occupancy) and keep the changed tets out of the one-thread
// seam where they can; and the model must step like one built afresh on the changed mesh.
// The changes: random tets split at their centroid into four (a vertex appended, one tet
// changed, three appended), with the quality bound on so that thin pieces turn passive.
TEST_P(XpbdEnergy, LocalUpdatesKeepAValidParallelScheduleAfterManyChanges) {
  SimProblem p = box_problem(6, 3, 3, {60, 30, 30}, Material{}, true);
  test::clamp_x0_face(p);
  EmbeddedElementTracker tracker(8.0);
  tracker.build(p.mesh, p.fixed_vertices, p.embedded);
  // Small steps (so that the sweep order matters little when compared with a fresh build
  // below): 40 substeps of one sweep.
  const ModelConfig c = config(1, 40, 2, GetParam());
  ModelConfig c1 = c;
  c1.threads = 1;
  XpbdModel local(p, c), serial(p, c1);
  ASSERT_EQ(local.check_batches(p), "");
  const double fresh_lanes = local.mean_lanes();
  const int seam_before = local.group_tets()[4];
  std::mt19937 rng(7);
  const double dt = 1.0 / 60.0;
  int changed_total = 0;
  for (int change = 0; change < 40; ++change) {
    // Split 1-6 random tets, each at its centroid.
    const int splits = 1 + static_cast<int>(rng() % 6);
    Eigen::Matrix3Xd x = local.positions_World_mm(), v = local.velocities_World_mm_s();
    std::vector<int> changed;
    for (int s = 0; s < splits; ++s) {
      const int t = static_cast<int>(rng() % static_cast<unsigned>(p.mesh.num_tets()));
      if (std::find(changed.begin(), changed.end(), t) != changed.end()) continue;
      const std::array<int, 4> tet = p.mesh.tets[static_cast<std::size_t>(t)];
      const int e = p.mesh.num_vertices();
      Eigen::Vector3d rest = Eigen::Vector3d::Zero(), xc = Eigen::Vector3d::Zero(), vc = Eigen::Vector3d::Zero();
      for (int w : tet) {
        rest += 0.25 * p.mesh.rest_positions_World_mm.col(w);
        xc += 0.25 * x.col(w);
        vc += 0.25 * v.col(w);
      }
      p.mesh.rest_positions_World_mm.conservativeResize(Eigen::NoChange, e + 1);
      p.mesh.rest_positions_World_mm.col(e) = rest;
      x.conservativeResize(Eigen::NoChange, e + 1);
      v.conservativeResize(Eigen::NoChange, e + 1);
      x.col(e) = xc;
      v.col(e) = vc;
      for (int a = 0; a < 4; ++a) {  // piece a: corner a replaced by the centroid (same orientation)
        std::array<int, 4> piece = tet;
        piece[static_cast<std::size_t>(a)] = e;
        if (a == 0) {
          p.mesh.tets[static_cast<std::size_t>(t)] = piece;
          changed.push_back(t);
        } else {
          changed.push_back(p.mesh.num_tets());
          p.mesh.tets.push_back(piece);
          p.mesh.tet_region.push_back(p.mesh.tet_region.empty() ? 0 : p.mesh.tet_region[static_cast<std::size_t>(t)]);
        }
      }
    }
    if (p.mesh.tet_region.size() != p.mesh.tets.size()) p.mesh.tet_region.resize(p.mesh.tets.size(), 0);
    // Tets whose flag the update changed without being changed themselves (islands cut off
    // by passive tets) are re-made too (as CutSession does).
    const std::vector<std::uint8_t> passive_before = p.embedded.passive;
    tracker.update(p.mesh, changed, p.fixed_vertices, p.embedded);
    for (std::size_t t = 0; t < passive_before.size(); ++t)
      if (p.embedded.is_passive(static_cast<int>(t)) != (passive_before[t] != 0) &&
          std::find(changed.begin(), changed.end(), static_cast<int>(t)) == changed.end())
        changed.push_back(static_cast<int>(t));
    std::sort(changed.begin(), changed.end());
    changed_total += static_cast<int>(changed.size());
    ASSERT_TRUE(local.apply_mesh_change(p, changed, x, v).has_value());
    ASSERT_TRUE(serial.apply_mesh_change(p, changed, x, v).has_value());
    const std::string why = local.check_batches(p);
    ASSERT_EQ(why, "") << "after change " << change;
    const StepSummary a = local.step(dt), b = serial.step(dt);
    ASSERT_TRUE(a.healthy) << a.warning;
    ASSERT_TRUE(b.healthy) << b.warning;
  }
  EXPECT_GT(p.embedded.passive_count(), 0);  // the passive paths ran too
  // Two threads and one compute the same after the changes (the groups that run at once
  // share no vertex).
  EXPECT_EQ((local.positions_World_mm() - serial.positions_World_mm()).cwiseAbs().maxCoeff(), 0.0);
  // Occupancy and seam against a fresh build on the changed mesh.
  XpbdModel fresh(p, c);
  ASSERT_EQ(fresh.check_batches(p), "");
  const std::array<int, 5> groups = local.group_tets(), fresh_groups = fresh.group_tets();
  int total = 0, fresh_total = 0;
  for (int g = 0; g < 5; ++g) {
    total += groups[static_cast<std::size_t>(g)];
    fresh_total += fresh_groups[static_cast<std::size_t>(g)];
  }
  EXPECT_EQ(total, fresh_total);
  // Tets on the step's critical path: phases 1 and 2 run two groups at once, the seam alone.
  auto path = [](const std::array<int, 5>& n) { return std::max(n[0], n[1]) + std::max(n[2], n[3]) + n[4]; };
  std::cout << "[xpbd local updates] critical path " << path(groups) << " tets of " << total << " (fresh build " << path(fresh_groups) << ")\n";
  EXPECT_LT(path(groups), 0.8 * total);  // the two threads share the work
  std::cout << "[xpbd local updates] " << changed_total << " changed tets: mean lanes per batch " << local.mean_lanes() << " (fresh build "
            << fresh.mean_lanes() << ", first build " << fresh_lanes << "), seam " << groups[4] << " tets (fresh " << fresh_groups[4]
            << ", first build " << seam_before << ")\n";
  EXPECT_GT(local.mean_lanes(), 0.75 * fresh.mean_lanes());
  EXPECT_LE(groups[4], seam_before + changed_total / 4);
  // Stepping like the fresh model from the same state: the same stored energy (element
  // data), and close after steps (the sweep order differs: Gauss-Seidel; the physics not).
  const Eigen::Matrix3Xd x_now = local.positions_World_mm(), v_now = local.velocities_World_mm_s();
  local.set_state(x_now, v_now);  // both rotation warm starts (corotated) from the same state
  fresh.set_state(x_now, v_now);
  ASSERT_EQ(local.masses_kg().size(), fresh.masses_kg().size());
  EXPECT_LT((local.masses_kg() - fresh.masses_kg()).cwiseAbs().maxCoeff(), 1e-12 * fresh.masses_kg().maxCoeff());
  EXPECT_NEAR(local.elastic_energy(), fresh.elastic_energy(), 1e-9 * std::abs(fresh.elastic_energy()) + 1e-12);
  double motion = 0.0, diff = 0.0;
  const Eigen::Matrix3Xd start = local.positions_World_mm();
  for (int k = 0; k < 10; ++k) {
    local.step(dt);
    fresh.step(dt);
  }
  motion = (local.positions_World_mm() - start).colwise().norm().maxCoeff();
  diff = (local.positions_World_mm() - fresh.positions_World_mm()).colwise().norm().maxCoeff();
  std::cout << "[xpbd local updates] after 10 steps: largest motion " << motion << " mm, largest difference from the fresh model " << diff << " mm\n";
  EXPECT_LT(diff, 0.05 * motion + 1e-6);
}

// Stable Neo-Hookean against linear elasticity: under a small uniaxial strain eps along x
// (F = diag(1 + eps, 1, 1)) the energy density is (lambda + 2 mu) eps^2 / 2 and the
// stress is sigma_xx = (lambda + 2 mu) eps, sigma_yy = sigma_zz = lambda eps, so von Mises
// = 2 mu eps, with the Lame parameters of the region's E and nu (to first order in eps).
TEST(XpbdNeoHookean, UniaxialStrainMatchesYoungsModulusAndPoissonRatio) {
  for (double nu : {0.0, 0.3, 0.45}) {
    Material m;
    m.youngs_modulus_kPa = 12.0;
    m.poisson_ratio = nu;
    const SimProblem p = box_problem(3, 2, 2, {30, 20, 20}, m, false);
    XpbdModel model(p, config(1, 1, 1, "neo_hookean"));
    const double mu = m.youngs_modulus_kPa / (2 * (1 + nu)), lambda = m.youngs_modulus_kPa * nu / ((1 + nu) * (1 - 2 * nu));
    const double eps = 1e-4, volume = 30.0 * 20.0 * 20.0;
    Eigen::Matrix3Xd x = p.mesh.rest_positions_World_mm;
    x.row(0) *= 1.0 + eps;
    model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
    const double expected = 0.5 * (lambda + 2 * mu) * eps * eps * volume;
    EXPECT_NEAR(model.elastic_energy(), expected, 1e-3 * expected) << "nu " << nu;
    for (const ElementMeasure& e : model.element_measures()) {
      EXPECT_NEAR(e.von_mises_stress_kPa, 2 * mu * eps, 1e-3 * 2 * mu * eps) << "nu " << nu;
      EXPECT_NEAR(e.volume_ratio, 1.0 + eps, 1e-12);
    }
  }
}

// The coupled 2x2 block leaves any rigid state exactly in place, also with one sweep per
// substep (no multipliers kept) and with damping, and its correction is zero.
TEST(XpbdNeoHookean, RotatedRestStateGetsZeroCorrection) {
  for (double beta : {0.0, 0.02}) {
    Material m;
    m.damping_stiffness_s = beta;
    const SimProblem p = box_problem(3, 3, 2, {30, 30, 20}, m, false);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(-2.7, Eigen::Vector3d(0.3, 1, -0.4).normalized()).toRotationMatrix();
    const Eigen::Matrix3Xd x_rot = (R * p.mesh.rest_positions_World_mm).colwise() + Eigen::Vector3d(-3, 2, 40);
    XpbdModel model(p, config(1, 10, 2, "neo_hookean"));
    model.set_state(x_rot, Eigen::Matrix3Xd::Zero(3, x_rot.cols()));
    for (int k = 0; k < 20; ++k) {
      const StepSummary s = model.step(1.0 / 60.0);
      ASSERT_TRUE(s.healthy) << s.warning;
      EXPECT_LT(s.final_residual, 1e-12);
      EXPECT_TRUE(s.warning.empty()) << s.warning;
    }
    EXPECT_LT((model.positions_World_mm() - x_rot).cwiseAbs().maxCoeff(), 1e-10) << "beta " << beta;
    EXPECT_NEAR(model.elastic_energy(), 0.0, 1e-10);
  }
}

// A single tet turned inside out (one vertex mirrored through the opposite face) is
// pushed back by the hydrostatic constraint and settles at rest.
TEST(XpbdNeoHookean, InvertedTetRecovers) {
  SimProblem p;
  Eigen::Matrix<double, 3, 4> rest;
  rest << 0, 10, 0, 0, 0, 0, 10, 0, 0, 0, 0, 10;
  p.mesh.rest_positions_World_mm = rest;
  p.mesh.tets = {{0, 1, 2, 3}};
  Material m;
  m.damping_mass_per_s = 10.0;
  p.region_materials = {m};
  p.gravity_World_mm_s2.setZero();
  p.fixed_vertices = {0, 1, 2};
  XpbdModel model(p, config(1, 10, 1, "neo_hookean"));
  Eigen::Matrix<double, 3, 4> inverted = rest;
  inverted(2, 3) = -6.0;  // apex below the base: det F = -0.6
  model.set_state(inverted, Eigen::Matrix3Xd::Zero(3, 4));
  EXPECT_NE(model.step(1.0 / 60.0).warning.find("inverted tets"), std::string::npos);
  StepSummary s;
  for (int k = 0; k < 120; ++k) s = model.step(1.0 / 60.0);
  EXPECT_TRUE(s.healthy) << s.warning;
  EXPECT_LT((model.positions_World_mm() - rest).cwiseAbs().maxCoeff(), 1e-3);
}

TEST(Xpbd, UnknownEnergyOrNeoHookeanWithSeveralSweepsIsRejected) {
  const SimProblem p = box_problem(2, 1, 1, {20, 10, 10}, Material{}, true);
  EXPECT_THROW(XpbdModel(p, config(1, 1, 1, "neohookean")), std::invalid_argument);
  ModelConfig c = config(1, 4, 1, "neo_hookean");
  c.iterations = 2;
  EXPECT_THROW(XpbdModel(p, c), std::invalid_argument);
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
