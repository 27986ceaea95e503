// Solver options agree, factor reuse and warm start behave, and what the model cannot
// handle is reported (healthy=false + warning, state kept) instead of exploding.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "host/sim/fem/stable_neo_hookean_fem.hpp"
#include "host/sim/fem/test/fem_test_util.hpp"
#include "host/sim/tet_geometry.hpp"
#include "host/sim/fem/symmetric_pattern.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <random>

namespace arnav::host {
namespace {

using fem_test::box_problem;
using fem_test::vertices_where;

using fem_test::hanging_block;

Eigen::Matrix3Xd run(const SimProblem& problem, const ModelConfig& config, int steps, std::vector<StepSummary>* log = nullptr) {
  CorotationalFem model(problem, config);
  for (int k = 0; k < steps; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    EXPECT_TRUE(s.healthy) << config.linear_solver << ": " << s.warning;
    if (log) log->push_back(s);
  }
  return model.positions_World_mm();
}

// Random vertex groups (tets, attachments) on `n` vertices.
std::vector<std::vector<int>> random_groups(int count, int n, std::mt19937& rng) {
  std::uniform_int_distribution<int> pick(0, n - 1);
  std::vector<std::vector<int>> groups;
  for (int g = 0; g < count; ++g) {
    std::vector<int> v;
    while (v.size() < 4) {
      const int w = pick(rng);
      if (std::find(v.begin(), v.end(), w) == v.end()) v.push_back(w);
    }
    groups.push_back(v);
  }
  return groups;
}

// A symmetric positive definite matrix on the pattern: identity plus a graph Laplacian of the groups.
SparseMatrixLower spd_on(const SymmetricPattern& pattern, const std::vector<std::vector<int>>& groups) {
  SparseMatrixLower A = pattern.matrix();
  for (int d = 0; d < A.rows(); ++d) A.valuePtr()[pattern.diagonal()[static_cast<std::size_t>(d)]] += 1.0;
  for (const auto& g : groups)
    for (int a : g)
      for (int b : g)
        for (int k = 0; k < 3; ++k) {
          if (a == b) A.valuePtr()[pattern.index(3 * a + k, 3 * a + k)] += static_cast<double>(g.size() - 1);
          if (a > b) A.valuePtr()[pattern.index(3 * a + k, 3 * b + k)] -= 1.0;
        }
  return A;
}

// After a cut the pattern grows by a merge (SymmetricPattern::extended): the result is the
// pattern built from the remaining and added groups at once, and every old entry is
// remapped to itself (or to -1: a pair no group couples any more).
TEST(SymmetricPatternExtended, EqualsThePatternOfAllGroupsAndRemapsEveryEntry) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 20; ++trial) {
    const int n_old = 12 + trial, n = n_old + trial % 5;
    const auto before = random_groups(2 * n_old, n_old, rng);
    const auto added = random_groups(3 + trial, n, rng);
    const SymmetricPattern old_pattern(n_old, before);
    // Some groups leave (tets a cut replaced): pairs no remaining or added group couples go.
    auto all = before;
    all.erase(all.begin(), all.begin() + trial % 7);
    all.insert(all.end(), added.begin(), added.end());
    std::vector<std::pair<int, int>> drop;
    for (const auto& g : before)
      for (int a : g)
        for (int b : g)
          if (a > b && std::none_of(all.begin(), all.end(), [&](const std::vector<int>& h) {
                return std::find(h.begin(), h.end(), a) != h.end() && std::find(h.begin(), h.end(), b) != h.end();
              }))
            drop.emplace_back(b, a);
    std::sort(drop.begin(), drop.end());
    drop.erase(std::unique(drop.begin(), drop.end()), drop.end());
    std::vector<int> remap;
    const SymmetricPattern grown = old_pattern.extended(n, added, remap, drop);
    const SymmetricPattern direct(n, all);
    ASSERT_EQ(grown.matrix().nonZeros(), direct.matrix().nonZeros());
    ASSERT_EQ(grown.matrix().rows(), direct.matrix().rows());
    for (Eigen::Index c = 0; c <= grown.matrix().cols(); ++c)
      ASSERT_EQ(grown.matrix().outerIndexPtr()[c], direct.matrix().outerIndexPtr()[c]);
    for (Eigen::Index k = 0; k < grown.matrix().nonZeros(); ++k)
      ASSERT_EQ(grown.matrix().innerIndexPtr()[k], direct.matrix().innerIndexPtr()[k]);
    EXPECT_EQ(grown.diagonal(), direct.diagonal());
    ASSERT_EQ(remap.size(), static_cast<std::size_t>(old_pattern.matrix().nonZeros()));
    const SparseMatrixLower& m = old_pattern.matrix();
    for (Eigen::Index c = 0; c < m.cols(); ++c)
      for (int k = m.outerIndexPtr()[c]; k < m.outerIndexPtr()[c + 1]; ++k)
        ASSERT_EQ(remap[static_cast<std::size_t>(k)], grown.index(m.innerIndexPtr()[k], static_cast<int>(c)));  // -1: dropped
  }
  const SymmetricPattern p(3, {{0, 1, 2}});
  std::vector<int> remap;
  EXPECT_THROW(p.extended(2, {}, remap), std::invalid_argument);
  EXPECT_THROW(p.extended(4, {{0, 7}}, remap), std::invalid_argument);
}

// PCG after a cut (FemLinearSolver::pattern_extended): the factor of the matrix before,
// padded for the appended DOFs, preconditions the grown matrix; PCG still converges to it,
// and the factor of the new pattern made on the worker replaces the old one.
TEST(FemSolvers, PaddedOldFactorPreconditionsTheGrownSystem) {
  std::mt19937 rng(3);
  const int n_old = 40, n = 46;
  const auto before = random_groups(60, n_old, rng);
  const SymmetricPattern old_pattern(n_old, before);
  FemLinearSolver solver(FemLinearSolver::Kind::PcgFactor, 0, 500, 1e-12);
  const SparseMatrixLower A_old = spd_on(old_pattern, before);
  Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(3 * n_old, -1.0, 2.0), x = Eigen::VectorXd::Zero(3 * n_old);
  ASSERT_TRUE(solver.solve(A_old, b, x).ok);
  const auto added = random_groups(10, n, rng);
  std::vector<int> remap;
  const SymmetricPattern grown = old_pattern.extended(n, added, remap);
  auto all = before;
  all.insert(all.end(), added.begin(), added.end());
  const SparseMatrixLower A = spd_on(grown, all);
  std::vector<int> alias(n - n_old);
  for (int i = 0; i < n - n_old; ++i) alias[static_cast<std::size_t>(i)] = i % 2 ? i : -1;  // some aggregated, some not
  solver.pattern_extended(n_old, alias);
  EXPECT_TRUE(solver.factor_pending());
  b = Eigen::VectorXd::LinSpaced(3 * n, 1.0, -3.0);
  x.setZero(3 * n);
  const LinearSolveSummary s = solver.solve(A, b, x);
  ASSERT_TRUE(s.ok) << s.message;
  EXPECT_FALSE(s.factorized);
  EXPECT_TRUE(s.background_started);
  EXPECT_EQ(s.termination, "converged");
  const SparseMatrixLower full = SparseMatrixLower(A.selfadjointView<Eigen::Lower>());
  const Eigen::VectorXd exact = Eigen::MatrixXd(full).ldlt().solve(b);
  EXPECT_LT((x - exact).norm(), 1e-9 * exact.norm());
  solver.wait_for_background();
  x.setZero(3 * n);
  const LinearSolveSummary fresh = solver.solve(A, b, x);
  EXPECT_TRUE(fresh.background_swapped);
  EXPECT_FALSE(solver.factor_pending());
  EXPECT_LE(fresh.iterations, 2);  // the factor of this very matrix
  EXPECT_LT((x - exact).norm(), 1e-9 * exact.norm());
}

TEST(FemSolvers, AllLinearSolversGiveTheSameImplicitEulerTrajectory) {
  const SimProblem problem = hanging_block();
  const Eigen::Matrix3Xd ref = run(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"}, 20);
  const double sag = (ref - problem.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff();
  EXPECT_GT(sag, 1.0);  // it does move (large deformation: soft tissue, 40 mm lever)
  for (const std::string solver : {"eigen_ldlt", "pcg", "pcg_jacobi"}) {
    const ModelConfig config{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = solver,
                             .iterations = 5000, .tolerance = 1e-12, .refactor_every = solver == "eigen_ldlt" ? 1 : 10};
    EXPECT_LT((run(problem, config, 20) - ref).cwiseAbs().maxCoeff(), 1e-6 * sag) << solver;
  }
  // Two assembly threads (partitioned scatter) and two substeps of half the step.
  ModelConfig two{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"};
  two.threads = 2;
  EXPECT_LT((run(problem, two, 20) - ref).cwiseAbs().maxCoeff(), 1e-9 * sag);
  two.substeps = 2;
  const double diff = (run(problem, two, 20) - ref).cwiseAbs().maxCoeff();
  EXPECT_GT(diff, 1e-6 * sag);  // a different time discretisation...
  EXPECT_LT(diff, 0.2 * sag);   // ...of the same motion
}

TEST(FemSolvers, LaggedFactorIsApproximateButPcgOnItConverges) {
  const SimProblem problem = hanging_block();
  std::vector<StepSummary> pcg_log, jacobi_log;
  {
    // A lagged factor used as a direct solve is inexact; without the refresh safeguard the
    // swinging soft block (large rotations) makes it diverge.
    FemOptions no_refresh;
    no_refresh.refresh_residual = 1e30;
    CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod",
                                    .refactor_every = 4}, no_refresh);
    std::vector<StepSummary> log;
    for (int k = 0; k < 5; ++k) log.push_back(model.step(1.0 / 60.0));
    EXPECT_EQ(log[0].termination, "direct");
    EXPECT_EQ(log[1].termination, "direct_lagged");
    EXPECT_EQ(log[4].termination, "direct");  // refactorised every 4 steps
    EXPECT_LT(log[0].final_residual, 1e-10);
    EXPECT_GT(log[2].final_residual, 1e-3);  // the lagged factor is not the current matrix
  }
  {
    // With the safeguard (default 0.1) a lagged solve that misses is refactorised at once.
    CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod",
                                    .refactor_every = 4});
    int refreshed = 0;
    for (int k = 0; k < 16; ++k) {
      const StepSummary s = model.step(1.0 / 60.0);
      EXPECT_TRUE(s.healthy) << s.warning;
      EXPECT_LE(s.final_residual, 0.1) << k;
      refreshed += s.termination == "direct_refreshed";
    }
    EXPECT_GT(refreshed, 0);
  }
  run(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "pcg", .iterations = 200,
                .tolerance = 1e-8, .refactor_every = 8}, 16, &pcg_log);
  run(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "pcg_jacobi", .iterations = 2000,
                .tolerance = 1e-8}, 16, &jacobi_log);
  int pcg_total = 0, jacobi_total = 0;
  for (std::size_t k = 0; k < pcg_log.size(); ++k) {
    EXPECT_EQ(pcg_log[k].termination, "converged") << k;
    EXPECT_LE(pcg_log[k].final_residual, 1e-8);
    pcg_total += pcg_log[k].iterations;
    jacobi_total += jacobi_log[k].iterations;
  }
  EXPECT_LT(3 * pcg_total, jacobi_total);  // the lagged factor is a much better preconditioner
}

TEST(FemSolvers, SinglePrecisionPreconditionerGivesTheSameAnswer) {
  // The factor applied in float: one application is accurate to ~1e-6 (float rounding),
  // PCG on top of it converges to the same tolerance as with the double factor, and the
  // implicit-Euler trajectory is the same to the solver tolerance.
  const SimProblem problem = hanging_block();
  ModelConfig config{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "pcg",
                     .iterations = 200, .tolerance = 1e-10, .refactor_every = 5};
  const Eigen::Matrix3Xd ref = run(problem, config, 20);
  config.single_precision_preconditioner = true;
  CorotationalFem model(problem, config);
  int first_iterations = 0;
  for (int k = 0; k < 20; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    ASSERT_TRUE(s.healthy) << s.warning;
    EXPECT_EQ(s.termination, "converged") << k;
    if (k == 0) first_iterations = s.iterations;
  }
  // A fresh factor in float is no longer exact: PCG needs a few iterations, not 1...
  EXPECT_GT(first_iterations, 1);
  EXPECT_LE(first_iterations, 6);  // ...but only a few (float has ~7 digits)
  const double sag = (ref - problem.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff();
  EXPECT_LT((model.positions_World_mm() - ref).cwiseAbs().maxCoeff(), 1e-6 * sag);
}

TEST(FemSolvers, WarmStartMakesPcgNearlyFreeAtRest) {
  SimProblem problem = hanging_block();
  problem.region_materials[0].damping_mass_per_s = 20.0;  // settle quickly
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "pcg_jacobi",
                                  .iterations = 2000, .tolerance = 1e-6});
  StepSummary first = model.step(1.0 / 60.0), last;
  for (int k = 0; k < 400; ++k) last = model.step(1.0 / 60.0);
  EXPECT_LT(last.initial_residual, 1e-4 * first.initial_residual);
  EXPECT_LT(last.iterations, first.iterations / 3) << first.iterations;
}

TEST(FemStability, InvertedElementsAreReportedAndRecover) {
  SimProblem problem = box_problem(2, 2, 2, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  problem.fixed_vertices = vertices_where(problem.mesh, [](const Eigen::Vector3d& q) { return q.z() == 0.0; });
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"});
  // Push the top centre vertex down through the middle layer: its tets invert.
  Eigen::Matrix3Xd x = problem.mesh.rest_positions_World_mm;
  const int top = box_vertex_index(2, 2, 1, 1, 2);
  for (int i = 0; i < x.cols(); ++i)
    if (i == top) x(2, i) = 2.0;  // (a loop: GCC 12 flags a constant-index write as null dereference)
  model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  const StepSummary s0 = model.step(1.0 / 60.0);
  EXPECT_TRUE(s0.healthy);
  EXPECT_NE(s0.warning.find("inverted tets"), std::string::npos) << s0.warning;
  StepSummary s;
  for (int k = 0; k < 120; ++k) s = model.step(1.0 / 60.0);
  EXPECT_TRUE(s.healthy) << s.warning;
  EXPECT_EQ(s.warning.find("inverted"), std::string::npos) << s.warning;
  for (const ElementMeasure& m : model.element_measures()) EXPECT_GT(m.volume_ratio, 0.0);
  EXPECT_NEAR(model.positions_World_mm()(2, top), 10.0, 1.0);  // back up near its rest place
}

// The health rule (docs/sim.md, "Run-time health"), both sides: a few tets held inverted
// are a counted warning for as long as they stay so (the run goes on, healthy); a mesh
// collapse (more than 10 % of the tets inverted for more than 1 s) is unhealthy.
TEST(FemStability, FewTetsHeldInvertedAreACountedWarning) {
  SimProblem problem = box_problem(4, 4, 2, Eigen::Vector3d(40, 40, 20), 5.0, 0.45);
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"});
  // Push the top centre vertex down through the middle layer and hold every vertex where
  // it is: its tets stay inverted whatever the model does.
  Eigen::Matrix3Xd x = problem.mesh.rest_positions_World_mm;
  const int top = box_vertex_index(4, 4, 2, 2, 2);
  for (int i = 0; i < x.cols(); ++i)
    if (i == top) x(2, i) = 2.0;
  model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  std::vector<int> all(x.cols());
  for (int i = 0; i < x.cols(); ++i) all[i] = i;
  model.set_fixed_vertices(all);
  StepSummary s;
  for (int k = 0; k < 150; ++k) {  // 2.5 s
    s = model.step(1.0 / 60.0);
    ASSERT_TRUE(s.healthy) << "step " << k << ": " << s.warning;
  }
  EXPECT_GT(s.inverted_elements, 0);
  EXPECT_LT(s.inverted_elements, problem.mesh.num_tets() / 10);
  EXPECT_NE(s.warning.find("inverted tets: " + std::to_string(s.inverted_elements)), std::string::npos) << s.warning;
  EXPECT_NEAR(model.inversions().episode_s(), 2.5, 0.02);
  EXPECT_EQ(model.inversions().steps_with_inversions(), 150);
}

TEST(FemStability, CollapsedMeshBecomesUnhealthy) {
  SimProblem problem = box_problem(1, 1, 1, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"});
  Eigen::Matrix3Xd x = problem.mesh.rest_positions_World_mm;
  x.row(2) *= -0.2;  // mirror the whole cube through z = 0: every tet inverted
  model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  std::vector<int> all(x.cols());
  for (int i = 0; i < x.cols(); ++i) all[i] = i;
  model.set_fixed_vertices(all);
  StepSummary s;
  int first_unhealthy = -1;
  for (int k = 0; k < 110 && first_unhealthy < 0; ++k) {
    s = model.step(0.01);
    if (!s.healthy) first_unhealthy = k;
  }
  // After 1 s (the 100th step, up to round-off in the summed time), not before.
  EXPECT_GE(first_unhealthy, 98) << s.warning;
  EXPECT_LE(first_unhealthy, 100) << s.warning;
  EXPECT_NE(s.warning.find("mesh collapse"), std::string::npos) << s.warning;
}

// Step control (issue 29, step_control.hpp) in both FEM materials: an unhealthy step is redone
// from the state it started from with 2x, 4x, 8x the sub-steps. A cube in free fall (no
// support, no damping: implicit Euler gives v_k = k g h exactly) with a speed limit of 0.6 g dt:
// 1x fails in its only sub-step, 2x in its second, 4x in its third, 8x in its fifth. Each redo
// must start from the saved state: the model ends where four sub-steps of dt/8 from rest take
// it (x = -10 g h^2, v = -4 g h), not further; counted as 3 redone and 1 not held at 8x. With
// the default limit the same fall is held at 1x with no redo and no step-control warning.
TEST(FemStability, StepControlRedoesAnUnhealthyStepFromItsSavedState) {
  SimProblem problem = box_problem(1, 1, 1, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  problem.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  const double dt = 1.0 / 60.0, g = 9810.0, h = dt / 8;
  FemOptions tight;
  tight.max_speed_mm_s = 0.6 * g * dt;
  const ModelConfig corotational{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"};
  ModelConfig neo_hookean = corotational;
  neo_hookean.material_model = "stable_neo_hookean";
  neo_hookean.iterations = 4;
  neo_hookean.tolerance = 1e-9;
  auto check = [&](TissueModel& model, const SubstepControl& control, const std::string& what) {
    const StepSummary s = model.step(dt);
    EXPECT_FALSE(s.healthy) << what;
    EXPECT_NE(s.warning.find("exceeds"), std::string::npos) << what << ": " << s.warning;
    EXPECT_EQ(control.redone_steps(), 3) << what;
    EXPECT_EQ(control.failed_steps(), 1) << what;
    EXPECT_EQ(control.steps_at_factor()[3], 1) << what;
    const Eigen::Matrix3Xd dx = model.positions_World_mm() - problem.mesh.rest_positions_World_mm;
    EXPECT_LT((dx.row(2).array() + 10.0 * g * h * h).abs().maxCoeff(), 1e-9) << what;
    EXPECT_LT(dx.topRows(2).cwiseAbs().maxCoeff(), 1e-9) << what;
    EXPECT_LT((model.velocities_World_mm_s().row(2).array() + 4.0 * g * h).abs().maxCoeff(), 1e-7) << what;
  };
  CorotationalFem a(problem, corotational, tight);
  check(a, a.step_control(), "corotational");
  StableNeoHookeanFem b(problem, neo_hookean, tight);
  check(b, b.step_control(), "stable_neo_hookean");
  CorotationalFem free_fall(problem, corotational);
  for (int k = 0; k < 10; ++k) {
    const StepSummary s = free_fall.step(dt);
    EXPECT_TRUE(s.healthy) << s.warning;
    EXPECT_EQ(s.warning.find("step control"), std::string::npos) << s.warning;
  }
  EXPECT_EQ(free_fall.step_control().redone_steps(), 0);
  EXPECT_EQ(free_fall.step_control().steps_at_factor()[0], 10);
}

TEST(FemStability, QuasiStaticLineSearchConvergesUnderLargeSag) {
  // A very soft column (0.3 kPa) hung from its top face sags by about its own height
  // scale: full warped-Newton steps overshoot here; the line search keeps the total
  // potential decreasing and the iteration converges.
  SimProblem problem = box_problem(3, 3, 8, Eigen::Vector3d(20, 20, 40), 0.3, 0.45);
  problem.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810.0);
  problem.fixed_vertices = vertices_where(problem.mesh, [](const Eigen::Vector3d& q) { return q.z() == 40.0; });
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  const Eigen::VectorXd mass = lumped_masses_kg(problem.mesh, problem.region_materials);
  auto potential = [&](const StepSummary& s, const Eigen::Matrix3Xd& x_before) {
    double e = s.elastic_energy;
    for (int i = 0; i < x_before.cols(); ++i) e -= mass[i] * problem.gravity_World_mm_s2.dot(x_before.col(i));
    return e;
  };
  double previous = 1e300;
  bool shortened = false, converged = false;
  for (int k = 0; k < 80 && !converged; ++k) {
    const Eigen::Matrix3Xd before = model.positions_World_mm();
    const StepSummary s = model.step(1.0);
    ASSERT_TRUE(s.healthy) << k << ": " << s.warning;
    const double pi = potential(s, before);  // energies are of the state before the update
    EXPECT_LE(pi, previous + 1e-9 * std::abs(previous)) << k;
    previous = pi;
    shortened = shortened || s.warning.find("line search") != std::string::npos;
    converged = (model.positions_World_mm() - before).cwiseAbs().maxCoeff() < 1e-8;
  }
  EXPECT_TRUE(converged);
  EXPECT_TRUE(shortened);
  const double sag = (problem.mesh.rest_positions_World_mm - model.positions_World_mm()).row(2).maxCoeff();
  EXPECT_GT(sag, 10.0);
}

TEST(FemStability, StrainBeyondTheLinearRangeIsReported) {
  SimProblem problem = box_problem(2, 2, 2, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  problem.fixed_vertices = vertices_where(problem.mesh, [](const Eigen::Vector3d& q) { return q.x() == 0.0 || q.x() == 10.0; });
  for (const double stretch : {1.1, 1.5}) {
    CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"});
    Eigen::Matrix3Xd x = problem.mesh.rest_positions_World_mm;
    x.row(0) *= stretch;
    model.set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
    const StepSummary s = model.step(0.01);
    EXPECT_TRUE(s.healthy);
    EXPECT_EQ(s.warning.find("beyond the linear range") != std::string::npos, stretch > 1.3) << s.warning;
  }
}

TEST(FemStability, UnsupportedQuasiStaticAndSingularSystemsAreReported) {
  SimProblem problem = box_problem(2, 2, 2, Eigen::Vector3d(10, 10, 10), 5.0, 0.45);
  problem.gravity_World_mm_s2 = Eigen::Vector3d(0, 0, -9810);
  CorotationalFem model(problem, fem_test::quasi_static_cholmod());
  const StepSummary s = model.step(0.01);
  EXPECT_FALSE(s.healthy);
  EXPECT_NE(s.warning.find("fixed vertices or attachments"), std::string::npos);
  // One point attachment leaves rotations about it free: the factorisation fails, the state is kept.
  model.add_attachment({.point = {{0}, {1.0}}, .target_World_mm = Eigen::Vector3d::Zero(), .stiffness_mN_per_mm = 1.0});
  const StepSummary s2 = model.step(0.01);
  EXPECT_FALSE(s2.healthy);
  EXPECT_EQ(s2.termination, "factorization_failed");
  EXPECT_EQ(model.positions_World_mm(), problem.mesh.rest_positions_World_mm);
}

TEST(FemStability, UnphysicalVelocityIsRejectedAndStateKept) {
  const SimProblem problem = hanging_block();
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"});
  Eigen::Matrix3Xd v = Eigen::Matrix3Xd::Zero(3, problem.mesh.num_vertices());
  v(0, problem.mesh.num_vertices() - 1) = 1e7;  // 10 km/s
  model.set_state(problem.mesh.rest_positions_World_mm, v);
  const StepSummary s = model.step(1.0 / 60.0);
  EXPECT_FALSE(s.healthy);
  EXPECT_NE(s.warning.find("unstable"), std::string::npos) << s.warning;
  EXPECT_EQ(model.positions_World_mm(), problem.mesh.rest_positions_World_mm);
}

TEST(FemInput, BadConfigurationAndInputsAreNamed) {
  const SimProblem problem = hanging_block();
  auto message = [&](auto f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  EXPECT_NE(message([&] { CorotationalFem(problem, {.kind = "corotational_fem", .integrator = "rk4", .linear_solver = ""}); }).find("'rk4'"), std::string::npos);
  EXPECT_NE(message([&] { CorotationalFem(problem, {.kind = "corotational_fem", .integrator = "", .linear_solver = "mumps"}); }).find("'mumps'"), std::string::npos);
  SimProblem bad = problem;
  bad.fixed_vertices.push_back(100000);
  EXPECT_NE(message([&] { CorotationalFem(bad, {}); }).find("100000"), std::string::npos);
  CorotationalFem model(problem, {});
  EXPECT_NE(message([&] { model.step(0.0); }).find("dt"), std::string::npos);
  EXPECT_NE(message([&] { model.add_attachment({.point = {{-1}, {1.0}}}); }).find("vertex -1"), std::string::npos);
  EXPECT_NE(message([&] { model.set_attachment_target(7, Eigen::Vector3d::Zero()); }).find("id 7"), std::string::npos);
}

TEST(FemModel, OnlyDeclaredMachineryIsBuiltAndAttachmentsPull) {
  const SimProblem problem = hanging_block();
  CorotationalFem model(problem, {.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "cholmod"});
  EXPECT_EQ(model.num_beam_elements(), 0);
  EXPECT_FALSE(model.vessel_embedding().has_value());
  // An attachment coupling two vertices that share no tet extends the pattern.
  const int a = box_vertex_index(8, 4, 8, 0, 0), b = box_vertex_index(8, 4, 8, 4, 4);
  const Eigen::Index nnz = model.system_matrix().nonZeros();
  const Eigen::Vector3d mid = 0.5 * (problem.mesh.rest_positions_World_mm.col(a) + problem.mesh.rest_positions_World_mm.col(b));
  const AttachmentId id = model.add_attachment({.point = {{a, b}, {0.5, 0.5}}, .target_World_mm = mid + Eigen::Vector3d(0, 0, 30),
                                                .stiffness_mN_per_mm = 100.0});
  ASSERT_GT(fem_test::solve_to_equilibrium(model, 40, 1e-8), 0);
  EXPECT_GT(model.system_matrix().nonZeros(), nnz);
  const Eigen::Vector3d p = 0.5 * (model.positions_World_mm().col(a) + model.positions_World_mm().col(b));
  EXPECT_GT(p.z() - mid.z(), 5.0);  // lifted against gravity toward the target
  model.remove_attachment(id);
  EXPECT_NE(model.step(1.0).termination, "");
}

}  // namespace
}  // namespace arnav::host
