// arnav-fem-bench: error against run time of the co-rotational FEM solver strategies on a
// liver-sized box (~24k tets until the liver scene lands), vessel-contrast conditioning,
// and cantilever refinement beyond what the unit tests run. Prints JSON (or CSV).
//
//   arnav-fem-bench realtime      [--nx 20 --ny 15 --nz 13 --frames 90 --threads 2]
//   arnav-fem-bench realtime      --scene data/liver/liver.scene.yaml [--settle] [--blas-threads 1]
//                                 [--only LABEL ...] [--trace LABEL] [--csv]
//   arnav-fem-bench conditioning  [--contrasts 1,10,100,1000,10000]
//   arnav-fem-bench cantilever    [--max-n 8]
//   arnav-fem-bench factor        --scene data/liver/liver.scene.yaml [--repeats 5] [--cholmod-openmp]
#include <CLI/CLI.hpp>
#include <cholmod.h>
#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <iostream>
#include <nlohmann/json.hpp>
#include <omp.h>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include "host/mesh/box_mesh.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/fem/blas_threads.hpp"
#include "host/sim/fem/corotational_fem.hpp"
#include "host/sim/fem/single_precision_factor.hpp"
#include "protocol/guarded_main.hpp"

namespace {

using namespace arnav::host;
using nlohmann::json;

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

std::vector<int> where(const TetMesh& mesh, auto pred) {
  std::vector<int> out;
  for (int i = 0; i < mesh.num_vertices(); ++i)
    if (pred(Eigen::Vector3d(mesh.rest_positions_World_mm.col(i)))) out.push_back(i);
  return out;
}

// ---------------------------------------------------------------- realtime
// A liver-sized block (160 x 120 x 80 mm, 5 kPa, nu 0.45) resting on its bottom face
// (held), settled under gravity; a grasper holding the top surface near the far end
// (vertices within 12 mm of the grasp point, 50 mN/mm each) lifts and pulls it 30 mm over
// 1 s, then holds. "Tumour": vertices in a 12 mm sphere 25 mm below the grasp.
struct Scenario {
  SimProblem problem;
  Eigen::Matrix3Xd x0;  // start: gravity equilibrium (box) or rest (scene)
  std::vector<int> grasp;
  std::vector<int> tumour;               // box: tumour = these vertices
  const Scene* scene = nullptr;          // scene: tumour 0 of the scene
  Eigen::Vector3d pull_mm{10, 0, 28.3};  // |pull| = 30 mm
  std::string description;
};

// Gravity equilibrium: exact quasi-static steps until the update is below 1e-9 mm.
// Warnings (strain range) are allowed; an unhealthy step or no convergence is an error.
Eigen::Matrix3Xd settle(const SimProblem& problem, int threads) {
  ModelConfig qs{.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "cholmod"};
  qs.threads = threads;
  CorotationalFem eq(problem, qs);
  for (int k = 0; k < 200; ++k) {
    const Eigen::Matrix3Xd before = eq.positions_World_mm();
    const StepSummary s = eq.step(1.0);
    if (!s.healthy) throw std::runtime_error("gravity equilibrium failed: " + s.warning);
    if ((eq.positions_World_mm() - before).cwiseAbs().maxCoeff() < 1e-9) return eq.positions_World_mm();
  }
  throw std::runtime_error("gravity equilibrium not reached in 200 quasi-static steps");
}

Eigen::Vector3d tumour_centroid(const Scenario& sc, const Eigen::Matrix3Xd& x) {
  if (sc.scene) return tumour_centroid_World_mm(*sc.scene, 0, x);
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int v : sc.tumour) c += x.col(v);
  return c / static_cast<double>(sc.tumour.size());
}

// A loaded scene (the liver): starts from its rest shape in gravity (the transient sag is
// part of the run) or, with --settle, from its gravity equilibrium; the grasper holds the surface vertices within 12 mm of the surface
// point nearest to tumour 0 and pulls them 20 mm away from the tumour over 1 s.
Scenario scene_scenario(const Scene& scene, bool settled, int threads) {
  Scenario sc;
  sc.scene = &scene;
  sc.problem = scene.problem;
  sc.x0 = settled ? settle(scene.problem, threads) : scene.problem.mesh.rest_positions_World_mm;
  if (scene.tumours.empty()) throw std::runtime_error(scene.source + ": the scene has no tumour to track");
  const Eigen::Vector3d c = scene.tumours[0].rest_centroid_World_mm;
  std::vector<char> on_surface(sc.x0.cols(), 0);
  for (const auto& tri : scene.problem.mesh.surface_tris)
    for (int v : tri) on_surface[v] = 1;
  int nearest = -1;
  for (int i = 0; i < sc.x0.cols(); ++i)
    if (on_surface[i] && (nearest < 0 || (sc.x0.col(i) - c).norm() < (sc.x0.col(nearest) - c).norm())) nearest = i;
  const Eigen::Vector3d at = sc.x0.col(nearest);
  for (int i = 0; i < sc.x0.cols(); ++i)
    if (on_surface[i] && (sc.x0.col(i) - at).norm() < 12.0) sc.grasp.push_back(i);
  sc.pull_mm = 20.0 * (at - c).normalized();
  sc.description = scene.source + (settled ? " (settled under gravity first)" : " (from rest, gravity on)") + ": grasp " +
                   std::to_string(sc.grasp.size()) + " surface vertices nearest tumour 0, pull 20 mm";
  return sc;
}

Scenario make_scenario(int nx, int ny, int nz, int threads) {
  Scenario sc;
  const Eigen::Vector3d size(160, 120, 80);
  sc.problem.mesh = make_box_tet_mesh(nx, ny, nz, size);
  Material liver;
  liver.damping_mass_per_s = 2.0;
  sc.problem.region_materials = {liver};
  sc.problem.fixed_vertices = where(sc.problem.mesh, [](const Eigen::Vector3d& p) { return p.z() == 0.0; });
  const TetMesh& mesh = sc.problem.mesh;
  const Eigen::Vector3d grasp_at(135, 60, 80);
  sc.grasp = where(mesh, [&](const Eigen::Vector3d& p) { return (p - grasp_at).norm() < 12.0; });
  sc.tumour = where(mesh, [&](const Eigen::Vector3d& p) { return (p - (grasp_at - Eigen::Vector3d(0, 0, 25))).norm() < 12.0; });
  sc.description = "box 160x120x80 mm on its bottom face, settled; grasp near the top far end, pull 30 mm";
  if (sc.grasp.empty() || sc.tumour.empty()) throw std::runtime_error("mesh too coarse for the grasp/tumour regions");
  sc.x0 = settle(sc.problem, threads);
  return sc;
}

struct RunResult {
  std::vector<Eigen::Vector3d> centroid;
  Eigen::Matrix3Xd final_x;
  std::vector<double> step_ms, step_cpu_ms, step_thread_cpu_ms, assemble_ms, solve_ms, assemble_cpu_ms, solve_cpu_ms;
  std::vector<double> iterations, residual, initial_residual, factor_age;
  double cpu_ms_per_frame_all_threads = 0;  // process CPU of the whole run / frames (background work included)
  int inline_factorizations = 0, background_factorizations = 0;
  int unhealthy = 0;
  std::string last_warning;
};

double thread_cpu_ms_now() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

RunResult run(const Scenario& sc, const ModelConfig& config, int frames, const FemOptions& options = {}, bool trace = false) {
  const double dt = 1.0 / 60.0;
  CorotationalFem model(sc.problem, config, options);
  model.set_state(sc.x0, Eigen::Matrix3Xd::Zero(3, sc.x0.cols()));
  std::vector<AttachmentId> tool;
  for (int v : sc.grasp)
    tool.push_back(model.add_attachment({.point = {{v}, {1.0}}, .target_World_mm = sc.x0.col(v), .stiffness_mN_per_mm = 50.0}));
  RunResult r;
  const std::clock_t run_c0 = std::clock();
  for (int f = 0; f < frames; ++f) {
    const double t = std::min(1.0, (f + 1) * dt);
    const double s = 0.5 - 0.5 * std::cos(std::numbers::pi * t);  // smooth 0 -> 1 over 1 s
    for (std::size_t k = 0; k < tool.size(); ++k) model.set_attachment_target(tool[k], sc.x0.col(sc.grasp[k]) + s * sc.pull_mm);
    // CPU time next to wall time: on a shared machine the wall time includes waiting for a
    // core; with one thread the CPU time is what the step costs on an idle core.
    const std::clock_t c0 = std::clock();
    const double t0 = thread_cpu_ms_now();
    const StepSummary sum = model.step(dt);
    r.step_thread_cpu_ms.push_back(thread_cpu_ms_now() - t0);
    r.step_cpu_ms.push_back(1000.0 * static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC);
    r.factor_age.push_back(model.last_linear_solve().factor_age);
    r.inline_factorizations += model.last_linear_solve().factorized;
    r.background_factorizations += model.last_linear_solve().background_started;
    if (trace) {
      const LinearSolveSummary& ls = model.last_linear_solve();
      std::cerr << "frame " << f << ": wall " << sum.wall_time_ms << " ms, thread CPU " << r.step_thread_cpu_ms.back()
                << " ms, assemble " << model.last_timing().assemble_ms << " ms, iterations " << ls.iterations
                << ", residual " << ls.final_residual << ", factor age " << ls.factor_age
                << (ls.factorized ? ", INLINE FACTORISATION" : "") << (ls.background_started ? ", bg started" : "")
                << (ls.background_swapped ? ", bg swapped" : "") << (ls.message.empty() ? "" : ", " + ls.message) << '\n';
    }
    if (!sum.healthy) ++r.unhealthy, r.last_warning = sum.warning;
    r.step_ms.push_back(sum.wall_time_ms);
    r.assemble_ms.push_back(model.last_timing().assemble_ms);
    r.solve_ms.push_back(model.last_timing().solve_ms);
    r.assemble_cpu_ms.push_back(model.last_timing().assemble_cpu_ms);
    r.solve_cpu_ms.push_back(model.last_timing().solve_cpu_ms);
    r.iterations.push_back(sum.iterations);
    r.residual.push_back(sum.final_residual);
    r.initial_residual.push_back(sum.initial_residual);
    r.centroid.push_back(tumour_centroid(sc, model.positions_World_mm()));
  }
  r.final_x = model.positions_World_mm();
  r.cpu_ms_per_frame_all_threads = 1000.0 * static_cast<double>(std::clock() - run_c0) / CLOCKS_PER_SEC / frames;
  return r;
}

int realtime(int nx, int ny, int nz, int frames, int threads, bool csv, bool with_ldlt, const std::string& scene_file,
             bool settle_scene, const std::vector<std::string>& only, int blas_threads, const std::string& trace) {
  std::optional<Scene> scene;
  Scenario sc;
  if (scene_file.empty()) {
    sc = make_scenario(nx, ny, nz, threads);
  } else {
    scene = load_scene(scene_file);
    sc = scene_scenario(*scene, settle_scene, threads);
  }
  struct Variant {
    std::string label;
    ModelConfig c;
    FemOptions options{};
  };


  auto cfg = [&](const std::string& solver, int refactor, int iters, double tol, bool background = false,
                 bool single = false) {
    ModelConfig c{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = solver};
    c.refactor_every = refactor;
    c.iterations = iters;
    c.tolerance = tol;
    c.threads = threads;
    c.refactor_in_background = background;
    c.single_precision_preconditioner = single;
    c.blas_threads = blas_threads;
    return c;
  };
  std::vector<Variant> variants = {
      {"direct_every_step", cfg("cholmod", 1, 1, 1e-6)},
      {"direct_refactor_5", cfg("cholmod", 5, 1, 1e-6)},
      {"direct_refactor_20", cfg("cholmod", 20, 1, 1e-6)},
      {"pcg_factor_r30_i1", cfg("pcg", 30, 1, 1e-4)},
      {"pcg_factor_r30_i3", cfg("pcg", 30, 3, 1e-4)},
      {"pcg_factor_r30_i10_tol1e-6", cfg("pcg", 30, 10, 1e-6)},
      {"pcg_factor_r0_i3", cfg("pcg", 0, 3, 1e-4)},
      {"pcg_jacobi_i10", cfg("pcg_jacobi", 1, 10, 1e-4)},
      {"pcg_jacobi_i25", cfg("pcg_jacobi", 1, 25, 1e-4)},
      {"pcg_jacobi_i100", cfg("pcg_jacobi", 1, 100, 1e-4)},
      {"pcg_jacobi_i400_tol1e-6", cfg("pcg_jacobi", 1, 400, 1e-6)},
      // Refactorised on a worker thread; refactor 1 = a new factorisation starts as soon
      // as the last one is done.
      {"pcg_bg_r1_i1", cfg("pcg", 1, 1, 1e-4, true)},
      {"pcg_bg_r1_i2", cfg("pcg", 1, 2, 1e-4, true)},
      {"pcg_bg_r1_i3", cfg("pcg", 1, 3, 1e-4, true)},
      {"pcg_bg_r10_i2", cfg("pcg", 10, 2, 1e-4, true)},
      // The factor applied in single precision.
      {"pcg_bg_r1_i1_float", cfg("pcg", 1, 1, 1e-4, true, true)},
      {"pcg_bg_r1_i2_float", cfg("pcg", 1, 2, 1e-4, true, true)},
      {"pcg_bg_r1_i3_float", cfg("pcg", 1, 3, 1e-4, true, true)},
      {"pcg_factor_r30_i3_float", cfg("pcg", 30, 3, 1e-4, false, true)},
      {"pcg_bg_r10_i2_float", cfg("pcg", 10, 2, 1e-4, true, true)},
      {"pcg_bg_r10_i3_float", cfg("pcg", 10, 3, 1e-4, true, true)},
      {"pcg_bg_r30_i3_float", cfg("pcg", 30, 3, 1e-4, true, true)},
  };
  if (with_ldlt) variants.push_back({"eigen_ldlt_every_step", cfg("eigen_ldlt", 1, 1, 1e-6)});
  if (!only.empty()) {
    std::string names;
    for (const Variant& v : variants) names += " " + v.label;
    for (const std::string& name : only)
      if (std::none_of(variants.begin(), variants.end(), [&](const Variant& v) { return v.label == name; }))
        throw std::invalid_argument("--only: unknown variant '" + name + "'; known:" + names);
    std::vector<Variant> kept{variants[0]};  // the reference always runs
    for (std::size_t k = 1; k < variants.size(); ++k)
      if (std::find(only.begin(), only.end(), variants[k].label) != only.end()) kept.push_back(variants[k]);
    variants = kept;
  }
  const RunResult ref = run(sc, variants[0].c, frames);
  json out;
  out["mesh"] = {{"tets", sc.problem.mesh.num_tets()},
                 {"vertices", sc.problem.mesh.num_vertices()},
                 {"dof", 3 * sc.problem.mesh.num_vertices()},
                 {"tets_per_vertex", static_cast<double>(sc.problem.mesh.num_tets()) / sc.problem.mesh.num_vertices()}};
  out["scenario"] = sc.description;
  out["beam_elements"] = sc.problem.vessels ? static_cast<int>(sc.problem.vessels->segments.size()) : 0;
  out["frames"] = frames;
  out["threads"] = threads;
  const BlasInfo blas = blas_info();
  out["blas"] = blas.openblas ? blas.config + " (threads " + std::to_string(blas.threads) + ")"
                              : std::string("not OpenBLAS (reference BLAS: single-threaded)");
  double ref_motion = 0;
  for (const auto& c : ref.centroid) ref_motion = std::max(ref_motion, (c - ref.centroid.front()).norm());
  out["reference_tumour_motion_mm"] = ref_motion;
  json rows = json::array();
  for (const Variant& v : variants) {
    const RunResult r = v.label == "direct_every_step" ? ref : run(sc, v.c, frames, v.options, v.label == trace);
    double err = 0;
    for (std::size_t f = 0; f < r.centroid.size(); ++f) err = std::max(err, (r.centroid[f] - ref.centroid[f]).norm());
    const double vertex_err = (r.final_x - ref.final_x).colwise().norm().maxCoeff();
    rows.push_back({{"label", v.label},
                    {"linear_solver", v.c.linear_solver},
                    {"refactor_every", v.c.refactor_every},
                    {"max_iterations", v.c.iterations},
                    {"tolerance", v.c.tolerance},
                    {"median_step_ms", median(r.step_ms)},
                    {"refactor_in_background", v.c.refactor_in_background},
                    {"single_precision_preconditioner", v.c.single_precision_preconditioner},
                    {"median_initial_residual", median(r.initial_residual)},
                    {"median_step_cpu_ms", median(r.step_cpu_ms)},
                    {"median_step_thread_cpu_ms", median(r.step_thread_cpu_ms)},
                    {"frames_within_60hz_wall", std::count_if(r.step_ms.begin(), r.step_ms.end(),
                                                              [](double ms) { return ms <= 1000.0 / 60.0; })},
                    {"max_step_ms_after_first", r.step_ms.size() > 1 ? *std::max_element(r.step_ms.begin() + 1, r.step_ms.end()) : 0.0},
                    {"p90_step_thread_cpu_ms", percentile(r.step_thread_cpu_ms, 0.9)},
                    {"cpu_ms_per_frame_all_threads", r.cpu_ms_per_frame_all_threads},
                    {"median_factor_age", median(r.factor_age)},
                    {"inline_factorizations", r.inline_factorizations},
                    {"background_factorizations", r.background_factorizations},
                    {"p90_step_cpu_ms", percentile(r.step_cpu_ms, 0.9)},
                    {"p90_step_ms", percentile(r.step_ms, 0.9)},
                    {"max_step_ms", *std::max_element(r.step_ms.begin(), r.step_ms.end())},
                    {"median_assemble_ms", median(r.assemble_ms)},
                    {"median_solve_ms", median(r.solve_ms)},
                    {"median_assemble_cpu_ms", median(r.assemble_cpu_ms)},
                    {"median_solve_cpu_ms", median(r.solve_cpu_ms)},
                    {"median_iterations", median(r.iterations)},
                    {"median_final_residual", median(r.residual)},
                    {"max_tumour_centroid_error_mm", err},
                    {"final_max_vertex_error_mm", vertex_err},
                    {"unhealthy_steps", r.unhealthy},
                    {"last_warning", r.last_warning}});
    std::cerr << v.label << " done\n";
  }
  out["results"] = rows;
  if (csv) {
    std::cout << "label,median_step_ms,p90_step_ms,median_step_cpu_ms,median_step_thread_cpu_ms,p90_step_thread_cpu_ms,"
                 "cpu_ms_per_frame_all_threads,median_assemble_ms,median_solve_ms,median_iterations,median_factor_age,"
                 "inline_factorizations,background_factorizations,max_tumour_centroid_error_mm,final_max_vertex_error_mm,"
                 "unhealthy_steps\n";
    for (const auto& r : rows) {
      std::cout << r["label"].get<std::string>() << ',' << r["median_step_ms"] << ',' << r["p90_step_ms"] << ','
                << r["median_step_cpu_ms"] << ',' << r["median_step_thread_cpu_ms"] << ',' << r["p90_step_thread_cpu_ms"]
                << ',' << r["cpu_ms_per_frame_all_threads"] << ',' << r["median_assemble_ms"] << ','
                << r["median_solve_ms"] << ',' << r["median_iterations"] << ',' << r["median_factor_age"] << ','
                << r["inline_factorizations"] << ',' << r["background_factorizations"] << ','
                << r["max_tumour_centroid_error_mm"] << ',' << r["final_max_vertex_error_mm"] << ','
                << r["unhealthy_steps"] << '\n';
    }
  } else {
    std::cout << out.dump(2) << '\n';
  }
  return 0;
}

// ---------------------------------------------------------------- conditioning
// The realtime block with a branching vessel tree (trunk + 4 branches, radius 4 -> 2 mm)
// whose Young's modulus is `contrast` times the parenchyma's. One quasi-static solve from
// rest under gravity: Jacobi-PCG and factor-PCG iterations to 1e-8, Lanczos kappa estimate.
int conditioning(const std::vector<double>& contrasts, int nx, int ny, int nz, int threads) {
  json rows = json::array();
  for (const double contrast : contrasts) {
    SimProblem p;
    p.mesh = make_box_tet_mesh(nx, ny, nz, Eigen::Vector3d(160, 120, 80));
    p.region_materials = {Material{}};
    p.fixed_vertices = where(p.mesh, [](const Eigen::Vector3d& q) { return q.z() == 0.0; });
    VesselTree tree;
    tree.nodes_World_mm.resize(3, 6);
    tree.nodes_World_mm << 20, 80, 140, 140, 120, 130,  //
        61, 60, 30, 90, 60, 60,                         //
        41, 40, 35, 45, 20, 65;
    tree.radius_mm = {4, 3.5, 2, 2, 2, 2};
    tree.segments = {{0, 1}, {1, 2}, {1, 3}, {1, 4}, {1, 5}};
    p.vessels = tree;
    p.vessel_material = Material{.youngs_modulus_kPa = contrast * Material{}.youngs_modulus_kPa, .poisson_ratio = 0.45};
    FemOptions options;
    options.beams.max_element_length_mm = 8.0;
    json row{{"contrast", contrast}};
    for (const std::string solver : {"pcg_jacobi", "pcg"}) {
      ModelConfig c{.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = solver};
      c.iterations = 100000;
      c.tolerance = 1e-8;
      c.threads = threads;
      CorotationalFem model(p, c, options);
      model.set_estimate_condition(solver == "pcg_jacobi");
      const auto t0 = std::chrono::steady_clock::now();
      const StepSummary s = model.step(1.0);
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      row[solver + "_iterations"] = s.iterations;
      row[solver + "_ms"] = ms;
      row[solver + "_termination"] = s.termination;
      if (solver == "pcg_jacobi") row["jacobi_kappa_estimate"] = model.last_linear_solve().condition_estimate;
      row["beam_elements"] = model.num_beam_elements();
    }
    rows.push_back(row);
    std::cerr << "contrast " << contrast << " done\n";
  }
  std::cout << json{{"conditioning", rows}}.dump(2) << '\n';
  return 0;
}

// ---------------------------------------------------------------- cantilever
// Tip deflection / Timoshenko reference for n x n x 10n cells (reference-figures.md).
int cantilever(int max_n, int threads) {
  const double E = 1e5, nu = 0.3, L = 100, b = 10, P = 1.0;
  const double I = b * b * b * b / 12, A = b * b, G = E / (2 * (1 + nu));
  const double ref = P * L * L * L / (3 * E * I) + P * L / (5.0 / 6.0 * G * A);
  json rows = json::array();
  for (int n = 1; n <= max_n; ++n) {
    SimProblem p;
    p.mesh = make_box_tet_mesh(10 * n, n, n, Eigen::Vector3d(L, b, b));
    p.region_materials = {Material{.youngs_modulus_kPa = E, .poisson_ratio = nu}};
    p.gravity_World_mm_s2.setZero();
    p.fixed_vertices = where(p.mesh, [](const Eigen::Vector3d& q) { return q.x() == 0.0; });
    ModelConfig c{.kind = "corotational_fem", .integrator = "quasi_static", .linear_solver = "cholmod"};
    c.threads = threads;
    CorotationalFem model(p, c);
    // End load: consistent nodal forces of a uniform shear traction on the x = L face,
    // applied as constant forces (springs to targets 1e6 mm away).
    Eigen::Matrix3Xd nodal = Eigen::Matrix3Xd::Zero(3, p.mesh.num_vertices());
    for (const auto& tri : p.mesh.surface_tris) {
      const Eigen::Vector3d a = p.mesh.rest_positions_World_mm.col(tri[0]), bb = p.mesh.rest_positions_World_mm.col(tri[1]),
                            cc = p.mesh.rest_positions_World_mm.col(tri[2]);
      if (a.x() != L || bb.x() != L || cc.x() != L) continue;
      for (int v : tri) nodal(2, v) -= P / (b * b) * 0.5 * (bb - a).cross(cc - a).norm() / 3.0;
    }
    for (int i = 0; i < p.mesh.num_vertices(); ++i) {
      const double f = nodal.col(i).norm();
      if (f == 0) continue;
      const Eigen::Vector3d x = p.mesh.rest_positions_World_mm.col(i);
      model.add_attachment({.point = {{i}, {1.0}}, .target_World_mm = x + 1e6 * nodal.col(i) / f, .stiffness_mN_per_mm = f / 1e6});
    }
    const auto t0 = std::chrono::steady_clock::now();
    for (int k = 0; k < 20; ++k) {
      const Eigen::Matrix3Xd before = model.positions_World_mm();
      model.step(1.0);
      if ((model.positions_World_mm() - before).cwiseAbs().maxCoeff() < 1e-12) break;
    }
    double sum = 0;
    int count = 0;
    for (int i = 0; i < p.mesh.num_vertices(); ++i)
      if (p.mesh.rest_positions_World_mm(0, i) == L) sum += p.mesh.rest_positions_World_mm(2, i) - model.positions_World_mm()(2, i), ++count;
    rows.push_back({{"cells", std::to_string(n) + "x" + std::to_string(n) + "x" + std::to_string(10 * n)},
                    {"tets", p.mesh.num_tets()},
                    {"tip_over_timoshenko", sum / count / ref},
                    {"solve_ms", std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count()}});
    std::cerr << "n = " << n << " done\n";
  }
  std::cout << json{{"cantilever_end_load", rows}}.dump(2) << '\n';
  return 0;
}

// ---------------------------------------------------------------- factor
// CHOLMOD on the implicit-Euler matrix of the scene after one step from rest: symbolic
// analysis, numeric factorisation and one solve, per ordering (AMD, METIS, CHOLMOD's
// nested dissection) and factor kind (supernodal LL^T, simplicial LDL^T). Reports the
// factor's nonzeros and flop count, wall and process CPU time (the BLAS may use threads).
double process_cpu_ms_now() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

int factor(const std::string& scene_file, int repeats, int threads, bool cholmod_openmp) {
  const Scene scene = load_scene(scene_file);
  // As FemLinearSolver does (fem_linear_solver.cpp): CHOLMOD's own OpenMP regions serial.
  if (!cholmod_openmp) omp_set_max_active_levels(0);
  ModelConfig c{.kind = "corotational_fem", .integrator = "implicit_euler", .linear_solver = "cholmod"};
  c.threads = threads;
  CorotationalFem model(scene.problem, c);
  model.step(1.0 / 60.0);
  SparseMatrixLower A = model.system_matrix();
  A.makeCompressed();
  const int n = static_cast<int>(A.rows());
  json rows = json::array();
  struct Ord {
    const char* name;
    int ordering;
  };
  for (const Ord ord : {Ord{"amd", CHOLMOD_AMD}, Ord{"metis", CHOLMOD_METIS}, Ord{"nesdis", CHOLMOD_NESDIS}}) {
    for (const bool super : {true, false}) {
      cholmod_common cm;
      cholmod_start(&cm);
      cm.print = 0;
      cm.nmethods = 1;
      cm.method[0].ordering = ord.ordering;
      cm.postorder = 1;
      cm.supernodal = super ? CHOLMOD_SUPERNODAL : CHOLMOD_SIMPLICIAL;
      cholmod_sparse As{};
      As.nrow = As.ncol = static_cast<std::size_t>(n);
      As.nzmax = static_cast<std::size_t>(A.nonZeros());
      As.p = A.outerIndexPtr();
      As.i = A.innerIndexPtr();
      As.x = A.valuePtr();
      As.stype = -1;  // lower triangle stored
      As.itype = CHOLMOD_INT;
      As.xtype = CHOLMOD_REAL;
      As.dtype = CHOLMOD_DOUBLE;
      As.sorted = 1;
      As.packed = 1;
      auto t0 = std::chrono::steady_clock::now();
      cholmod_factor* L = cholmod_analyze(&As, &cm);
      const double analyze_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      const double lnz = cm.lnz, flops = cm.fl;
      std::vector<double> fwall, fcpu, swall, scpu;
      cholmod_dense* b = cholmod_ones(As.nrow, 1, CHOLMOD_REAL, &cm);
      double residual = 0;
      for (int r = 0; r < repeats; ++r) {
        t0 = std::chrono::steady_clock::now();
        double c0 = process_cpu_ms_now();
        cholmod_factorize(&As, L, &cm);
        fwall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        fcpu.push_back(process_cpu_ms_now() - c0);
        for (int k = 0; k < 5; ++k) {
          t0 = std::chrono::steady_clock::now();
          c0 = process_cpu_ms_now();
          cholmod_dense* x = cholmod_solve(CHOLMOD_A, L, b, &cm);
          swall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
          scpu.push_back(process_cpu_ms_now() - c0);
          const Eigen::Map<const Eigen::VectorXd> xv(static_cast<double*>(x->x), n);
          residual = (Eigen::VectorXd::Ones(n) - A.selfadjointView<Eigen::Lower>() * xv).norm() / std::sqrt(double(n));
          cholmod_free_dense(&x, &cm);
        }
      }
      // Single-precision copy of the supernodal factor (the PCG preconditioner option).
      double float_solve_ms = 0, float_solve_cpu_ms = 0, float_rel_error = 0;
      if (super) {
        SinglePrecisionFactor single;
        single.assign(*L);
        const Eigen::VectorXd ones = Eigen::VectorXd::Ones(n);
        Eigen::VectorXd xf;
        std::vector<double> fw, fc;
        for (int k = 0; k < 5 * repeats; ++k) {
          t0 = std::chrono::steady_clock::now();
          const double c0 = process_cpu_ms_now();
          single.solve(ones, xf);
          fc.push_back(process_cpu_ms_now() - c0);
          fw.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        }
        float_solve_ms = median(fw);
        float_solve_cpu_ms = median(fc);
        cholmod_dense* x = cholmod_solve(CHOLMOD_A, L, b, &cm);
        const Eigen::Map<const Eigen::VectorXd> xd(static_cast<double*>(x->x), n);
        float_rel_error = (xf - xd).norm() / xd.norm();
        cholmod_free_dense(&x, &cm);
      }
      rows.push_back({{"ordering", ord.name},
                      {"median_float_solve_ms", float_solve_ms},
                      {"median_float_solve_cpu_ms", float_solve_cpu_ms},
                      {"float_solve_relative_error", float_rel_error},
                      {"factor", super ? "supernodal_llt" : "simplicial_ldlt"},
                      {"factor_ok", L->minor == L->n},
                      {"nnz_L", lnz},
                      {"flops_factor", flops},
                      {"analyze_ms", analyze_ms},
                      {"median_factor_ms", median(fwall)},
                      {"median_factor_cpu_ms", median(fcpu)},
                      {"median_solve_ms", median(swall)},
                      {"median_solve_cpu_ms", median(scpu)},
                      {"solve_residual_rms", residual}});
      cholmod_free_dense(&b, &cm);
      cholmod_free_factor(&L, &cm);
      cholmod_finish(&cm);
      std::cerr << ord.name << (super ? " supernodal" : " simplicial") << " done\n";
    }
  }
  const BlasInfo blas = blas_info();
  std::cout << json{{"matrix", {{"dof", n}, {"nnz_lower", A.nonZeros()}, {"scene", scene_file}}},
                    {"blas", blas.openblas ? blas.config + " (threads " + std::to_string(blas.threads) + ")" : "not OpenBLAS"},
                    {"cholmod_openmp", cholmod_openmp},
                    {"factor", rows}}
                   .dump(2)
            << '\n';
  return 0;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"Co-rotational FEM benchmarks: solver error vs run time, vessel conditioning, cantilever refinement"};
  app.require_subcommand(1);
  int nx = 20, ny = 15, nz = 13, frames = 90, threads = 2, max_n = 8;
  bool csv = false, with_ldlt = false, settle_scene = false;
  std::string scene_file;
  std::vector<double> contrasts{1, 10, 100, 1000, 10000};
  auto* rt = app.add_subcommand("realtime", "solver strategies vs the direct-every-step reference (JSON or CSV)");
  rt->add_option("--nx", nx, "cells along x (160 mm)")->check(CLI::PositiveNumber);
  rt->add_option("--ny", ny, "cells along y (120 mm)")->check(CLI::PositiveNumber);
  rt->add_option("--nz", nz, "cells along z (80 mm)")->check(CLI::PositiveNumber);
  rt->add_option("--frames", frames, "60 Hz frames to simulate")->check(CLI::PositiveNumber);
  rt->add_option("--threads", threads, "assembly threads")->check(CLI::PositiveNumber);
  rt->add_flag("--csv", csv, "CSV instead of JSON");
  rt->add_flag("--settle", settle_scene, "with --scene: start from the gravity equilibrium instead of the rest shape");
  rt->add_option("--scene", scene_file, "scene file (e.g. data/liver/liver.scene.yaml) instead of the box")->check(CLI::ExistingFile);
  rt->add_flag("--with-eigen-ldlt", with_ldlt, "also time Eigen's simplicial LDLT every step (slow)");
  std::vector<std::string> only;
  int blas_threads = 0;
  std::string trace;
  rt->add_option("--trace", trace, "print every frame of this variant to stderr (times, iterations, factor age, refactorisations)");
  rt->add_option("--only", only, "run only these variants (labels as in the output; the reference always runs)");
  rt->add_option("--blas-threads", blas_threads, "OpenBLAS threads (model key blas_threads; 0 = as the environment sets)")
      ->check(CLI::NonNegativeNumber);
  auto* cond = app.add_subcommand("conditioning", "PCG iterations and kappa vs vessel/parenchyma stiffness contrast");
  cond->add_option("--contrasts", contrasts, "E_vessel / E_parenchyma values")->delimiter(',');
  cond->add_option("--nx", nx)->check(CLI::PositiveNumber);
  cond->add_option("--ny", ny)->check(CLI::PositiveNumber);
  cond->add_option("--nz", nz)->check(CLI::PositiveNumber);
  cond->add_option("--threads", threads)->check(CLI::PositiveNumber);
  auto* cant = app.add_subcommand("cantilever", "tip deflection / Timoshenko for n x n x 10n cells, n = 1..max-n");
  cant->add_option("--max-n", max_n, "largest n")->check(CLI::Range(1, 12));
  cant->add_option("--threads", threads)->check(CLI::PositiveNumber);
  int repeats = 5;
  auto* fac = app.add_subcommand("factor", "CHOLMOD ordering / factor kind: factor size, factorisation and solve time");
  fac->add_option("--scene", scene_file, "scene file")->required()->check(CLI::ExistingFile);
  fac->add_option("--repeats", repeats, "numeric factorisations per variant (5 solves each)")->check(CLI::PositiveNumber);
  fac->add_option("--threads", threads)->check(CLI::PositiveNumber);
  bool cholmod_openmp = false;
  fac->add_flag("--cholmod-openmp", cholmod_openmp, "leave CHOLMOD's internal OpenMP regions on (FemLinearSolver turns them off)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return e.get_exit_code() == 0 ? 0 : (code == 0 ? 0 : 2);
  }
  try {
    if (*rt) return realtime(nx, ny, nz, frames, threads, csv, with_ldlt, scene_file, settle_scene, only, blas_threads, trace);
    if (*cond) return conditioning(contrasts, nx, ny, nz, threads);
    if (*fac) return factor(scene_file, repeats, threads, cholmod_openmp);
    return cantilever(max_n, threads);
  } catch (const std::invalid_argument& e) {  // bad option value or model setting: usage error
    std::cerr << "arnav-fem-bench: " << e.what() << '\n';
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-fem-bench: " << e.what() << '\n';
    return 1;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-fem-bench", [&] { return main_body(argc, argv); });
}
