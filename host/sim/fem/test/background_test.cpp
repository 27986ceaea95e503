// Background refactorisation (refactor_in_background) gives the trajectory of the inline
// mode to the solver tolerance, swaps factors in, reports failures instead of hiding them;
// the BLAS thread setting is applied or reported.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "host/sim/fem/blas_threads.hpp"
#include "host/sim/fem/test/fem_test_util.hpp"

namespace arnav::host {
namespace {


using fem_test::hanging_block;

ModelConfig pcg(int refactor_every, int iterations, double tolerance, bool background) {
  ModelConfig c{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "pcg",
                .iterations = iterations, .tolerance = tolerance, .refactor_every = refactor_every};
  c.refactor_in_background = background;
  return c;
}

struct RunLog {
  Eigen::Matrix3Xd x;
  int started = 0, swapped = 0, inline_factorizations = 0, max_age = 0;
};

// wait: block on the worker after every step, so that each factor is swapped in at the
// next step (deterministic); otherwise the worker runs freely.
RunLog run(const SimProblem& problem, const ModelConfig& config, int steps, bool wait) {
  CorotationalFem model(problem, config);
  RunLog r;
  for (int k = 0; k < steps; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    EXPECT_TRUE(s.healthy) << k << ": " << s.warning;
    const LinearSolveSummary& ls = model.last_linear_solve();
    r.started += ls.background_started;
    r.swapped += ls.background_swapped;
    r.inline_factorizations += ls.factorized;
    r.max_age = std::max(r.max_age, ls.factor_age);
    if (wait) model.wait_for_background();
  }
  r.x = model.positions_World_mm();
  return r;
}

TEST(FemBackgroundRefactor, SameTrajectoryAsInlineWithinTheSolverTolerance) {
  const SimProblem problem = hanging_block();
  const RunLog inline_run = run(problem, pcg(4, 500, 1e-10, false), 30, false);
  const double sag = (inline_run.x - problem.mesh.rest_positions_World_mm).cwiseAbs().maxCoeff();
  ASSERT_GT(sag, 1.0);
  for (const bool wait : {true, false}) {
    const RunLog bg = run(problem, pcg(4, 500, 1e-10, true), 30, wait);
    EXPECT_LT((bg.x - inline_run.x).cwiseAbs().maxCoeff(), 1e-6 * sag) << "wait " << wait;
    EXPECT_GT(bg.started, 0);
    if (wait) {
      // Deterministic: a job every 4 solves, each swapped in at the next solve; only the
      // first factor is inline.
      EXPECT_EQ(bg.inline_factorizations, 1);
      EXPECT_EQ(bg.started, 7);  // solves 5, 9, ..., 29
      EXPECT_EQ(bg.swapped, 7);
      EXPECT_LE(bg.max_age, 4);
    }
  }
}

TEST(FemBackgroundRefactor, StaleFactorIsExtendedThenRefreshedInline) {
  // The factor of the rest state only (refactor_every 0) and one PCG iteration: on the
  // swinging block one iteration is not enough. Background mode first extends PCG by
  // another `iterations` with the lagged factor, then refactorises inline: every step
  // ends below the safeguard threshold, as in the inline mode.
  const SimProblem problem = hanging_block();
  CorotationalFem model(problem, pcg(0, 1, 1e-6, true));
  int extended = 0, refreshed = 0;
  for (int k = 0; k < 20; ++k) {
    const StepSummary s = model.step(1.0 / 60.0);
    ASSERT_TRUE(s.healthy) << s.warning;
    const LinearSolveSummary& ls = model.last_linear_solve();
    EXPECT_LE(ls.final_residual, 0.1) << k;
    extended += ls.message.find("PCG extended") != std::string::npos;
    refreshed += k > 0 && ls.factorized;
    model.wait_for_background();
  }
  EXPECT_GT(extended, 0);
  EXPECT_GT(refreshed + extended, 0);
}

TEST(FemBackgroundRefactor, SolverLevelSwapAndFailure) {
  // A 1D Laplacian-like SPD matrix (lower triangle), then an indefinite one.
  const int n = 50;
  auto matrix = [&](double shift) {
    std::vector<Eigen::Triplet<double>> t;
    for (int i = 0; i < n; ++i) {
      t.emplace_back(i, i, 2.0 + shift);
      if (i + 1 < n) t.emplace_back(i + 1, i, -1.0);
    }
    SparseMatrixLower A(n, n);
    A.setFromTriplets(t.begin(), t.end());
    A.makeCompressed();
    return A;
  };
  FemLinearSolver solver(FemLinearSolver::Kind::PcgFactor, 0, 100, 1e-12);
  solver.set_background_refactor(true);
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, 1.0, 2.0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  const SparseMatrixLower A0 = matrix(0.0), A1 = matrix(0.5);
  LinearSolveSummary s = solver.solve(A0, b, x);
  EXPECT_TRUE(s.factorized);  // the first factor is inline
  EXPECT_FALSE(s.background_started);
  solver.wait_for_background();  // the spare factor's symbolic analysis, started now
  solver.force_refactor();  // background mode: keep this factor, start a new one at the next solve
  x.setZero();
  s = solver.solve(A1, b, x);
  EXPECT_FALSE(s.factorized);
  EXPECT_TRUE(s.background_started);
  EXPECT_EQ(s.termination, "converged");  // PCG on the new matrix with the old factor
  EXPECT_GT(s.iterations, 1);
  solver.wait_for_background();
  x.setZero();
  s = solver.solve(A1, b, x);
  EXPECT_TRUE(s.background_swapped);
  EXPECT_EQ(s.factor_age, 1);  // the factor of the previous solve's matrix (the same A1)
  EXPECT_LE(s.iterations, 1);  // exact preconditioner
  EXPECT_LT((b - A1.selfadjointView<Eigen::Lower>() * x).norm(), 1e-10 * b.norm());
  // An indefinite matrix: PCG meets non-positive curvature with the lagged factor, the
  // inline refactorisation fails: reported (factorization_failed), not hidden.
  const SparseMatrixLower bad = matrix(-3.0);
  x.setZero();
  s = solver.solve(bad, b, x);
  EXPECT_FALSE(s.ok);
  EXPECT_EQ(s.termination, "factorization_failed");
  EXPECT_NE(s.message.find("not positive definite"), std::string::npos) << s.message;
  // A background factorisation of it fails as well, and says so when it is collected.
  FemLinearSolver second(FemLinearSolver::Kind::PcgFactor, 0, 100, 1e-12);
  second.set_background_refactor(true);
  x.setZero();
  second.solve(A0, b, x);
  second.wait_for_background();
  second.force_refactor();
  second.solve(bad, b, x);  // starts the job on `bad`
  second.wait_for_background();
  x.setZero();
  s = second.solve(A0, b, x);
  EXPECT_NE(s.message.find("background factorisation failed"), std::string::npos) << s.message;
  EXPECT_TRUE(s.ok);  // the old factor (of A0) still solves A0
  EXPECT_LT((b - A0.selfadjointView<Eigen::Lower>() * x).norm(), 1e-10 * b.norm());
}

TEST(FemBackgroundRefactor, OnlyForPcgAndBadBlasThreadsAreRejected) {
  const SimProblem problem = hanging_block();
  for (const std::string solver : {"cholmod", "eigen_ldlt", "pcg_jacobi"}) {
    ModelConfig c = pcg(4, 10, 1e-6, true);
    c.linear_solver = solver;
    try {
      CorotationalFem model(problem, c);
      ADD_FAILURE() << solver << ": no exception";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("refactor_in_background needs linear_solver pcg"), std::string::npos) << e.what();
    }
  }
  ModelConfig c = pcg(4, 10, 1e-6, false);
  c.blas_threads = -1;
  EXPECT_THROW(CorotationalFem(problem, c), std::invalid_argument);
  ModelConfig f = pcg(4, 10, 1e-6, false);
  f.linear_solver = "cholmod";
  f.single_precision_preconditioner = true;
  EXPECT_THROW(CorotationalFem(problem, f), std::invalid_argument);
  // The worker's nice level: 0-19 (a background run at 19 still steps and swaps factors).
  const auto nice_level = [](int level) {
    FemOptions o;
    o.background_nice = level;
    return o;
  };
  EXPECT_THROW(CorotationalFem(problem, pcg(4, 10, 1e-6, true), nice_level(20)), std::invalid_argument);
  EXPECT_THROW(CorotationalFem(problem, pcg(4, 10, 1e-6, true), nice_level(-1)), std::invalid_argument);
  CorotationalFem low(problem, pcg(2, 10, 1e-6, true), nice_level(19));
  bool swapped = false;
  for (int k = 0; k < 8; ++k) {
    ASSERT_TRUE(low.step(1.0 / 60).healthy);
    low.wait_for_background();
    swapped = swapped || low.last_linear_solve().background_swapped;
  }
  EXPECT_TRUE(swapped);
}

TEST(FemBlas, ThreadSettingIsAppliedOrReported) {
  const BlasInfo before = blas_info();
  const SimProblem problem = hanging_block();
  ModelConfig c = pcg(4, 10, 1e-6, false);
  c.blas_threads = 2;
  CorotationalFem model(problem, c);
  const StepSummary first = model.step(1.0 / 60.0), second = model.step(1.0 / 60.0);
  if (before.openblas) {
    EXPECT_FALSE(before.config.empty());
    EXPECT_EQ(blas_info().threads, 2);
    EXPECT_EQ(first.warning.find("blas_threads"), std::string::npos) << first.warning;
    EXPECT_TRUE(set_blas_threads(before.threads));
    EXPECT_EQ(blas_info().threads, before.threads);
  } else {
    // Reference BLAS: the request cannot be honoured; said once.
    EXPECT_NE(first.warning.find("blas_threads 2 asked for"), std::string::npos) << first.warning;
    EXPECT_EQ(second.warning.find("blas_threads"), std::string::npos) << second.warning;
    EXPECT_FALSE(set_blas_threads(2));
  }
}

}  // namespace
}  // namespace arnav::host
