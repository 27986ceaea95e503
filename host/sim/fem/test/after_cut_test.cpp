// The FEM models after a cut (issue 11 item 4, docs/sim-fem.md "After a cut"): the stable
// Neo-Hookean FEM updated in place (fem_mesh_change.hpp, shared with the co-rotational FEM)
// assembles the system of a model built from scratch on the cut mesh and moves like it;
// random blade sweeps with the quality bound on never rebuild it.
#include <gtest/gtest.h>

#include <iostream>
#include <map>
#include <random>

#include "host/cut/cut_session.hpp"
#include "host/cut/mesh_checks.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/mesh/box_mesh.hpp"
#include "host/sim/test/box_problem.hpp"
#include "host/sim/fem/corotational_fem.hpp"
#include "host/sim/fem/stable_neo_hookean_fem.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {

// A bar of size_mm along x, held at its x = 0 face.
SimProblem clamped_bar(const Eigen::Vector3d& size_mm, int nx, int ny, int nz, double youngs_kPa) {
  Material m = test::soft_tissue(youngs_kPa);
  m.damping_stiffness_s = 0.01;
  SimProblem p = test::box_problem(nx, ny, nz, size_mm, m);
  test::clamp_x0_face(p);
  return p;
}

// Stable Neo-Hookean, Newton to a tight gradient with exact (direct) solves: two models in
// the same state then take the same steps to the Newton tolerance (a stale element map,
// mass or fixed row would differ by O(1)).
ModelConfig neo_hookean_config() {
  ModelConfig c;
  c.kind = "corotational_fem";
  c.material_model = "stable_neo_hookean";
  c.integrator = "implicit_euler";
  c.linear_solver = "cholmod";
  c.refactor_every = 1;
  c.iterations = 30;
  c.tolerance = 1e-7;  // the line search's floor (round-off of the incremental potential) is ~1e-8
  return c;
}

// max |a - b| / max |b| of two lower-triangle matrices (dense: small systems only).
double relative_difference(const SparseMatrixLower& a, const SparseMatrixLower& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) return 1e300;
  const Eigen::MatrixXd da(a), db(b);
  return (da - db).cwiseAbs().maxCoeff() / std::max(db.cwiseAbs().maxCoeff(), 1e-300);
}

// The cutter's appended vertices that CutSession fixes: copies of a fixed vertex, points
// on an edge between two fixed ones.
void fix_appended(SimProblem& problem, int old_vertices, const CutStepReport& r) {
  std::vector<char> fixed(static_cast<std::size_t>(problem.mesh.num_vertices()), 0);
  for (int v : problem.fixed_vertices) fixed[static_cast<std::size_t>(v)] = 1;
  for (std::size_t i = 0; i < r.new_vertices.size(); ++i) {
    const VertexOrigin& o = r.new_vertices[i];
    const bool on_fixed = fixed[static_cast<std::size_t>(o.a)] && (o.b < 0 || fixed[static_cast<std::size_t>(o.b)]);
    if (!on_fixed) continue;
    fixed[static_cast<std::size_t>(old_vertices) + i] = 1;
    problem.fixed_vertices.push_back(old_vertices + static_cast<int>(i));
  }
}

// Steps `model` and one built from scratch on `problem` in the same state side by side:
// largest relative system difference and position difference (mm), and the motion.
struct Comparison {
  double matrix = 0, positions = 0, motion = 0;
  bool same_pattern = true;
};
Comparison step_against_rebuilt(StableNeoHookeanFem& model, const SimProblem& problem, const ModelConfig& config, int steps) {
  StableNeoHookeanFem rebuilt(problem, config);
  rebuilt.set_state(model.positions_World_mm(), model.velocities_World_mm_s());
  const Eigen::Matrix3Xd x0 = model.positions_World_mm();
  Comparison c;
  const double dt = 1.0 / 60.0;
  for (int k = 0; k < steps; ++k) {
    const StepSummary a = model.step(dt), b = rebuilt.step(dt);
    EXPECT_TRUE(a.healthy) << a.warning;
    EXPECT_TRUE(b.healthy) << b.warning;
    // Newton ends at the tolerance or where the energy's round-off stops the line search.
    EXPECT_TRUE(a.termination == "converged" || a.termination == "at_equilibrium") << a.termination << " at " << a.final_residual;
    c.matrix = std::max(c.matrix, relative_difference(model.system_matrix(), rebuilt.system_matrix()));
    c.same_pattern = c.same_pattern && model.system_matrix().nonZeros() == rebuilt.system_matrix().nonZeros();
  }
  c.motion = (model.positions_World_mm() - x0).cwiseAbs().maxCoeff();
  c.positions = (model.positions_World_mm() - rebuilt.positions_World_mm()).cwiseAbs().maxCoeff();
  return c;
}

}  // namespace

// A slit from the top of a sagging bar, then a cut along it through its fixed face: after
// each, the model updated in place assembles the rebuilt model's system (same pattern,
// values to round-off) and takes the same steps; appended fixed vertices stay put.
TEST(StableNeoHookeanAfterCut, StepsLikeAModelRebuiltOnTheCutMesh) {
  SimProblem problem = clamped_bar(Eigen::Vector3d(100, 20, 20), 10, 2, 2, 50.0);
  const ModelConfig config = neo_hookean_config();
  StableNeoHookeanFem local(problem, config);
  const double dt = 1.0 / 60.0;
  for (int f = 0; f < 10; ++f) ASSERT_TRUE(local.step(dt).healthy);
  TetCutter cutter(problem.mesh, CutSettings{});
  SimProblem cut_problem = problem;
  const auto cut = [&](const SweptSurface& sweep) {
    Eigen::Matrix3Xd x = local.positions_World_mm(), v = local.velocities_World_mm_s();
    const int old_vertices = cutter.mesh().num_vertices();
    const CutStepReport r = cutter.step(sweep, x, v);
    ASSERT_TRUE(r.topology_changed);
    cut_problem.mesh = cutter.mesh();
    fix_appended(cut_problem, old_vertices, r);
    const auto stats = local.apply_mesh_change(cut_problem, r.changed_tets, x, v);
    ASSERT_TRUE(stats.has_value()) << "the stable Neo-Hookean FEM must update in place";
    EXPECT_EQ(stats->elements_updated, static_cast<int>(r.changed_tets.size()));  // no passive flag flips here
    EXPECT_LE(stats->vertices_updated, 4 * static_cast<int>(r.changed_tets.size()));
    EXPECT_EQ((local.positions_World_mm() - x).cwiseAbs().maxCoeff(), 0.0);
  };
  const auto check = [&](const char* stage, int steps) {
    const Comparison c = step_against_rebuilt(local, cut_problem, config, steps);
    std::cout << "[neo-hookean after cut] " << stage << ": system difference " << c.matrix << " (relative), positions "
              << c.positions << " mm after " << steps << " steps (moved " << c.motion << " mm)\n";
    EXPECT_TRUE(c.same_pattern) << stage;
    EXPECT_LT(c.matrix, 1e-6) << stage;
    EXPECT_LT(c.positions, 1e-6 * std::max(c.motion, 1.0)) << stage;
  };
  double top = -1e300;
  for (int i = 0; i < local.positions_World_mm().cols(); ++i)
    if (std::abs(local.positions_World_mm()(0, i) - 45.3) < 10) top = std::max(top, local.positions_World_mm()(2, i));
  cut(SweptSurface{{Eigen::Vector3d(45.3, -5, top - 12), Eigen::Vector3d(45.3, -5, top + 10)},
                   {Eigen::Vector3d(45.3, 25, top - 12), Eigen::Vector3d(45.3, 25, top + 10)}, 1, {}});
  check("slit, first step", 1);
  check("slit, 20 steps", 20);
  const int fixed_before = static_cast<int>(cut_problem.fixed_vertices.size());
  cut(SweptSurface{{Eigen::Vector3d(-5, 10.3, -5), Eigen::Vector3d(-5, 10.3, 30)},
                   {Eigen::Vector3d(20, 10.3, -5), Eigen::Vector3d(20, 10.3, 30)}, 1, {}});
  ASSERT_GT(static_cast<int>(cut_problem.fixed_vertices.size()), fixed_before) << "no fixed vertex appended";
  const Eigen::Matrix3Xd x_cut = local.positions_World_mm();
  check("after a cut through the fixed face", 15);
  for (std::size_t i = static_cast<std::size_t>(fixed_before); i < cut_problem.fixed_vertices.size(); ++i) {
    const int w = cut_problem.fixed_vertices[i];
    EXPECT_EQ((local.positions_World_mm().col(w) - x_cut.col(w)).norm(), 0.0) << "appended fixed vertex " << w << " moved";
  }
}

// Random blade sweeps through a clamped bar (quality bound on: slivers become passive,
// their vertices driven) with the model updated in place every time: every step healthy,
// never rebuilt, and after 4 and 8 sweeps the system and the next steps equal those of a
// model built from scratch with the session's mesh, fixed set and embedding.
TEST(StableNeoHookeanAfterCut, RandomSweepsKeepTheModelConsistent) {
  const SimProblem problem = clamped_bar(Eigen::Vector3d(60, 20, 20), 6, 2, 2, 20.0);
  const ModelConfig config = neo_hookean_config();
  CutSessionSettings settings;
  ASSERT_GT(settings.min_dihedral_deg, 0.0);  // the quality bound is on
  CutSession session(problem, config, settings);
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  const double dt = 1.0 / 60.0;
  int passive_seen = 0;
  const auto check = [&](const char* when) {
    auto* model = dynamic_cast<StableNeoHookeanFem*>(&session.model());
    ASSERT_NE(model, nullptr);
    SimProblem p = problem;
    p.mesh = session.mesh();
    p.fixed_vertices = session.fixed_vertices();
    p.embedded = session.embedded();
    for (int t = 0; t < p.mesh.num_tets(); ++t) passive_seen += p.embedded.is_passive(t) ? 1 : 0;
    const Comparison c = step_against_rebuilt(*model, p, config, 3);
    std::cout << "[neo-hookean after cut] random sweeps, " << when << ": " << session.local_updates() << " local updates, "
              << session.mesh().num_tets() << " tets, system difference " << c.matrix << ", positions " << c.positions
              << " mm (moved " << c.motion << " mm)\n";
    EXPECT_TRUE(c.same_pattern) << when;
    EXPECT_LT(c.matrix, 1e-6) << when;
    EXPECT_LT(c.positions, 1e-6 * std::max(c.motion, 1.0)) << when;
  };
  int frame = 0;
  for (int sweep = 0; sweep < 8; ++sweep) {
    const Eigen::Vector3d centre(5 + 50 * uni(rng), 20 * uni(rng), 20 * uni(rng));
    Eigen::Vector3d normal(uni(rng) - 0.5, uni(rng) - 0.5, uni(rng) - 0.5);
    if (sweep % 3 == 0) normal = Eigen::Vector3d(1, 0.1 * (uni(rng) - 0.5), 0.1 * (uni(rng) - 0.5));
    normal.normalize();
    const Eigen::Vector3d u = normal.unitOrthogonal(), w = normal.cross(u);
    const double stop = 10 + 30 * uni(rng);
    for (int f = 0; f <= 12; ++f, ++frame) {
      const Eigen::Vector3d mid = centre + (-30 + (30 + stop) * f / 12.0) * w;
      const CutFrameReport r = session.apply_blade({mid - 40 * u, mid + 40 * u}, true);
      if (r.cut.topology_changed) {
        EXPECT_TRUE(r.local_update) << "frame " << frame;
      }
      const StepSummary s = session.step(dt);
      ASSERT_TRUE(s.healthy) << "sweep " << sweep << " frame " << frame << ": " << s.warning;
    }
    for (int f = 0; f < 3; ++f, ++frame) {
      session.apply_blade({Eigen::Vector3d(0, 100, 100), Eigen::Vector3d(0, 100, 140)}, false);
      ASSERT_TRUE(session.step(dt).healthy);
    }
    if (sweep == 3) check("after 4 sweeps");
  }
  EXPECT_EQ(session.rebuilds(), 0);
  EXPECT_GT(session.local_updates(), 8);
  EXPECT_TRUE(check_cut_mesh(session.mesh()).valid());
  check("after 8 sweeps");
  std::cout << "[neo-hookean after cut] passive tets at the checks: " << passive_seen << "\n";
}

// Co-rotational FEM with refactor_in_background: after a cut PCG runs on the factor from
// before it (padded for the appended vertices), which still couples the two sides of the
// cut. The cut-region correction (FemOptions::cut_region_rings) solves the changed
// vertices and their neighbours exactly on the current matrix inside the preconditioner:
// far fewer PCG iterations to the same tolerance, the same step as a rebuilt model.
TEST(CorotationalAfterCut, CutRegionCorrectionCutsPcgIterationsOnTheOldFactor) {
  std::map<int, int> iterations;
  for (const int rings : {-1, 0, 1, 2}) {
    SimProblem problem = clamped_bar(Eigen::Vector3d(100, 20, 20), 10, 2, 2, 50.0);
    ModelConfig config;
    config.kind = "corotational_fem";
    config.integrator = "implicit_euler";
    config.linear_solver = "pcg";
    config.iterations = 2000;
    config.tolerance = 1e-12;
    config.refactor_every = 1;  // a factor one step old at the cut: the cut, not the lag, is measured
    config.refactor_in_background = true;
    FemOptions options;
    options.cut_region_rings = rings;
    CorotationalFem model(problem, config, options);
    const double dt = 1.0 / 60.0;
    for (int f = 0; f < 10; ++f) ASSERT_TRUE(model.step(dt).healthy);
    model.wait_for_background();
    ASSERT_TRUE(model.step(dt).healthy);  // swaps in the last factor, starts the next job
    const int uncut_iterations = model.last_linear_solve().iterations;
    model.wait_for_background();
    TetCutter cutter(problem.mesh, CutSettings{});
    Eigen::Matrix3Xd x = model.positions_World_mm(), v = model.velocities_World_mm_s();
    double top = -1e300;
    for (int i = 0; i < x.cols(); ++i)
      if (std::abs(x(0, i) - 45.3) < 10) top = std::max(top, x(2, i));
    const CutStepReport r = cutter.step(SweptSurface{{Eigen::Vector3d(45.3, -5, top - 12), Eigen::Vector3d(45.3, -5, top + 10)},
                                                     {Eigen::Vector3d(45.3, 25, top - 12), Eigen::Vector3d(45.3, 25, top + 10)}, 1, {}},
                                        x, v);
    ASSERT_TRUE(r.topology_changed);
    SimProblem cut_problem = problem;
    cut_problem.mesh = cutter.mesh();
    ASSERT_TRUE(model.apply_mesh_change(cut_problem, r.changed_tets, x, v).has_value());
    ASSERT_TRUE(model.factor_pending());
    CorotationalFem rebuilt(cut_problem, config);
    rebuilt.set_state(x, v);
    const StepSummary a = model.step(dt), b = rebuilt.step(dt);
    ASSERT_TRUE(a.healthy) << a.warning;
    ASSERT_TRUE(b.healthy) << b.warning;
    EXPECT_FALSE(model.last_linear_solve().factorized) << "the first step after the cut runs on the old factor";
    EXPECT_EQ(a.termination, "converged");
    const double diff = (model.positions_World_mm() - rebuilt.positions_World_mm()).cwiseAbs().maxCoeff();
    const double motion = (model.positions_World_mm() - x).cwiseAbs().maxCoeff();
    iterations[rings] = model.last_linear_solve().iterations;
    std::cout << "[corotational after cut] cut_region_rings " << rings << ": PCG iterations to 1e-12 on the old factor "
              << iterations[rings] << " (rebuilt model, fresh factor: " << rebuilt.last_linear_solve().iterations
              << "; a step before the cut with a factor as old: " << uncut_iterations << "), positions " << diff
              << " mm from the rebuilt model (moved " << motion << " mm)\n";
    EXPECT_LT(diff, 1e-9 * std::max(motion, 1.0)) << "rings " << rings;
  }
  // The padded old factor alone needs over a hundred iterations here (docs/sim-fem.md).
  EXPECT_GT(iterations[-1], 60);
  EXPECT_LT(iterations[1], iterations[-1] / 3);
  EXPECT_LE(iterations[1], 20);  // about what the same factor age costs without a cut
  EXPECT_LE(iterations[2], iterations[1]);
}

// The work of an in-place update scales with the cut, not with the mesh: the same slit in a
// bar and in one four times longer updates exactly as many element and vertex records
// (both FEM materials), one per changed tet and at most four per changed tet.
TEST(FemUpdateInPlace, WorkScalesWithTheCutNotTheMesh) {
  for (const bool neo_hookean : {false, true}) {
    std::vector<MeshChangeStats> stats;
    std::vector<int> changed;
    for (const double length : {100.0, 400.0}) {
      const int cells = static_cast<int>(length / 10);
      const SimProblem problem = clamped_bar(Eigen::Vector3d(length, 20, 20), cells, 2, 2, 50.0);
      ModelConfig config = neo_hookean_config();
      if (!neo_hookean) {
        config.material_model.clear();
        config.linear_solver = "pcg";
        config.iterations = 200;
        config.tolerance = 1e-10;
      }
      const std::unique_ptr<TissueModel> model =
          neo_hookean ? std::unique_ptr<TissueModel>(std::make_unique<StableNeoHookeanFem>(problem, config))
                      : std::unique_ptr<TissueModel>(std::make_unique<CorotationalFem>(problem, config));
      ASSERT_TRUE(model->step(1.0 / 60.0).healthy);
      TetCutter cutter(problem.mesh, CutSettings{});
      Eigen::Matrix3Xd x = model->positions_World_mm(), v = model->velocities_World_mm_s();
      const CutStepReport r = cutter.step(SweptSurface{{Eigen::Vector3d(45.3, -5, 8), Eigen::Vector3d(45.3, -5, 30)},
                                                       {Eigen::Vector3d(45.3, 25, 8), Eigen::Vector3d(45.3, 25, 30)}, 1, {}},
                                          x, v);
      ASSERT_TRUE(r.topology_changed);
      SimProblem cut_problem = problem;
      cut_problem.mesh = cutter.mesh();
      const auto s = model->apply_mesh_change(cut_problem, r.changed_tets, x, v);
      ASSERT_TRUE(s.has_value());
      stats.push_back(*s);
      changed.push_back(static_cast<int>(r.changed_tets.size()));
      ASSERT_TRUE(model->step(1.0 / 60.0).healthy);
    }
    std::cout << "[fem after cut] " << (neo_hookean ? "stable Neo-Hookean" : "co-rotational") << ": " << changed[0]
              << " changed tets, " << stats[0].elements_updated << " element and " << stats[0].vertices_updated
              << " vertex records on the short and the long bar\n";
    EXPECT_EQ(changed[0], changed[1]);
    EXPECT_EQ(stats[0].elements_updated, changed[0]);
    EXPECT_EQ(stats[1].elements_updated, stats[0].elements_updated);
    EXPECT_EQ(stats[1].vertices_updated, stats[0].vertices_updated);
    EXPECT_LE(stats[0].vertices_updated, 4 * changed[0]);
  }
}
