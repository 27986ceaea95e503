// arnav-sim-bench: frame time of the tissue models on a synthetic box of ~24k tets (the
// size of the liver mesh), or on a scene's own problem (--scene). Prints JSON.
// Scenario per frame (1/60 s): gravity, bottom face clamped (a scene: its fixed vertices),
// one top corner (a scene: the lowest vertex) grasped and pulled 25 mm over the first
// second, then held. Frame time = wall time of step(); also
// the process CPU time of the step (all threads), less sensitive to a shared machine.
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <ctime>
#include <fstream>
#include <iostream>
#include <optional>

#include "host/mesh/box_mesh.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/reshape.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/bench/stress_matrix.hpp"
#include "host/sim/model_factory.hpp"
#include "protocol/guarded_main.hpp"

namespace {

using namespace arnav::host;

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5));
  return v[i];
}

// Process CPU time (all threads) in ms: on a shared machine it shows the work a frame
// costs, where wall time also holds the time the scheduler gave to other processes.
double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

// The --scene, reshaped when --mesh-scale / --mesh-warp-mm ask (another patient from ours,
// host/scene/reshape.hpp); nullopt after saying why not.
std::optional<Scene> load_bench_scene(const std::string& path, const SceneReshape& reshape) {
  try {
    Scene scene = load_scene(path);
    if (reshape.scale != 1.0 || reshape.warp_mm != 0.0) scene = reshaped_scene(scene, reshape);
    return scene;
  } catch (const LoadError& e) {
    std::cerr << "arnav-sim-bench: " << e.what() << "\n";
  } catch (const std::invalid_argument& e) {
    std::cerr << "arnav-sim-bench: --mesh-scale / --mesh-warp-mm: " << e.what() << "\n";
  }
  return std::nullopt;
}

// --stress-matrix: the matrix on a scene (stress_matrix.hpp).
int stress_matrix_main(const std::string& scene_path, const SceneReshape& reshape, const std::string& csv_path,
                       const std::vector<std::string>& cases, const std::vector<std::string>& models, int frames,
                       int reference_factor, int substeps) {
  if (scene_path.empty()) {
    std::cerr << "arnav-sim-bench: --stress-matrix needs --scene (e.g. data/patients/sksurgery_liver_coarse.scene.yaml)\n";
    return 2;
  }
  const std::optional<Scene> loaded = load_bench_scene(scene_path, reshape);
  if (!loaded) return 2;
  const Scene& scene = *loaded;
  std::ofstream file;
  if (csv_path != "-") {
    file.open(csv_path);
    if (!file) {
      std::cerr << "arnav-sim-bench: cannot write --stress-matrix " << csv_path << "\n";
      return 2;
    }
  }
  StressMatrixOptions o;
  o.frames = frames;
  o.models = models;
  o.cases = cases;
  o.reference_factor = reference_factor;
  o.substeps = substeps;
  try {
    const nlohmann::json summary = run_stress_matrix(scene, o, csv_path == "-" ? std::cout : file, std::cerr);
    std::cout << summary.dump(2) << "\n";
  } catch (const std::invalid_argument& e) {
    std::cerr << "arnav-sim-bench: " << e.what() << "\n";
    return 2;
  }
  return 0;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"Frame time of the tissue models (mass-spring, XPBD, ...) on a synthetic ~24k-tet box; JSON to stdout"};
  int nx = 20, ny = 20, nz = 10, frames = 120;
  std::vector<int> threads{1, 2};
  std::vector<std::string> models;
  int iterations = 0, substeps = 0;
  std::string positions_csv, energy;
  double tolerance = -1.0;
  std::string scene_path;
  double damping_per_s = -1.0;
  double grasp_stiffness = 200.0;
  std::string linear_solver;
  app.add_option("--nx", nx, "cells along x (6 tets per cell)")->check(CLI::PositiveNumber);
  app.add_option("--ny", ny, "cells along y")->check(CLI::PositiveNumber);
  app.add_option("--nz", nz, "cells along z")->check(CLI::PositiveNumber);
  app.add_option("--frames", frames, "frames of 1/60 s to time (--stress-matrix: frames per case)")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "thread counts to run")->check(CLI::PositiveNumber);
  app.add_option("--model", models, "variant labels (default: every variant of model_variants())");
  app.add_option("--iterations", iterations, "override iterations (XPBD sweeps per substep, CG max)");
  app.add_option("--substeps", substeps, "override substeps per frame (--stress-matrix: every variant's configured substeps)");
  app.add_option("--energy", energy, "override the XPBD energy (neo_hookean, corotated)");
  app.add_option("--tolerance", tolerance, "override the tolerance (early stop; 0 = run all iterations)");
  app.add_option("--positions-csv", positions_csv,
                 "write the final vertex positions (mm) of the last run to this CSV, to measure the error of a "
                 "cheap setting against a converged run");
  app.add_option("--scene", scene_path,
                 "time the scene's own problem (mesh, materials, fixed vertices, gravity) instead of the box; the "
                 "grasped vertex is the lowest one");
  app.add_option("--damping", damping_per_s, "override every region's mass damping (Rayleigh alpha, 1/s)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--grasp-stiffness", grasp_stiffness, "stiffness of the grasp in mN/mm (0: no grasp, gravity only)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--linear-solver", linear_solver,
                 "override the linear solver (corotational_fem: cholmod, pcg, ...; mass_spring/semi_implicit: jacobi, "
                 "laplacian)");
  std::string stress_csv;
  std::vector<std::string> stress_cases_wanted;
  app.add_option("--stress-matrix", stress_csv,
                 "run the stress matrix of issue 29 on --scene (every --model x nu, stiffness contrast, time step, load, "
                 "sudden 50 mm pull; each held, refused at load or stopped; docs/benchmarks.md \"Stress matrix\"): one CSV "
                 "row per case to this file (- for stdout), the JSON summary to stdout; --frames per case (default 60)");
  app.add_option("--stress-case", stress_cases_wanted, "with --stress-matrix: only these cases (e.g. baseline nu_0.499 pull_50mm)");
  int reference_factor = 0;
  app.add_option("--reference-factor", reference_factor,
                 "with --stress-matrix: compare the adapted runs and each baseline frame by frame with the same case at "
                 "this factor times the run's largest substep count (and half that, to show it converged); 0: none")
      ->check(CLI::NonNegativeNumber);
  SceneReshape reshape;
  app.add_option("--mesh-scale", reshape.scale,
                 "with --scene: scale its volume about the centroid (another patient's size; host/scene/reshape.hpp)")
      ->check(CLI::PositiveNumber);
  app.add_option("--mesh-warp-mm", reshape.warp_mm,
                 "with --scene: warp its volume by a smooth random field moving the farthest vertex this far (mm)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--mesh-seed", reshape.seed, "the warp's random field (default 1)");
  CLI11_PARSE(app, argc, argv);
  if (!stress_csv.empty())
    return stress_matrix_main(scene_path, reshape, stress_csv, stress_cases_wanted, models, app.count("--frames") ? frames : 60,
                              reference_factor, substeps);

  SimProblem problem;
  int grasp = 0;
  if (scene_path.empty()) {
    problem.mesh = make_box_tet_mesh(nx, ny, nz, Eigen::Vector3d(200, 200, 100));
    problem.region_materials = {Material{.youngs_modulus_kPa = 5.0, .poisson_ratio = 0.45, .damping_mass_per_s = 5.0}};
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) problem.fixed_vertices.push_back(box_vertex_index(nx, ny, i, j, 0));
    grasp = box_vertex_index(nx, ny, nx, ny, nz);
  } else {
    const std::optional<Scene> scene = load_bench_scene(scene_path, reshape);
    if (!scene) return 2;
    problem = scene->problem;
    const Eigen::Matrix3Xd& X = problem.mesh.rest_positions_World_mm;
    for (Eigen::Index i = 1; i < X.cols(); ++i)
      if (X(2, i) < X(2, grasp)) grasp = static_cast<int>(i);
  }
  if (damping_per_s >= 0.0)
    for (Material& m : problem.region_materials) m.damping_mass_per_s = damping_per_s;
  const Eigen::Vector3d grasp_rest = problem.mesh.rest_positions_World_mm.col(grasp);

  std::vector<ModelVariant> variants;
  for (const ModelVariant& v : model_variants())
    if (models.empty() || std::find(models.begin(), models.end(), v.label) != models.end()) variants.push_back(v);
  if (variants.empty()) {
    std::cerr << "arnav-sim-bench: no model variant matches --model; available:";
    for (const ModelVariant& v : model_variants()) std::cerr << " " << v.label;
    std::cerr << "\n";
    return 2;
  }

  nlohmann::json out;
  out["mesh"] = {{"tets", problem.mesh.num_tets()}, {"vertices", problem.mesh.num_vertices()}};
  if (scene_path.empty()) {
    out["mesh"]["size_mm"] = {200, 200, 100};
    out["mesh"]["cells"] = {nx, ny, nz};
  } else {
    out["mesh"]["scene"] = scene_path;
  }
  out["frame_s"] = 1.0 / 60.0;
  out["runs"] = nlohmann::json::array();
  for (const ModelVariant& variant : variants) {
    for (int t : threads) {
      ModelConfig config = variant.config;
      config.threads = t;
      if (iterations > 0) config.iterations = iterations;
      if (substeps > 0) config.substeps = substeps;
      if (tolerance >= 0.0) config.tolerance = tolerance;
      if (!linear_solver.empty()) config.linear_solver = linear_solver;
      if (!energy.empty() && config.kind == "xpbd") config.energy = energy;
      auto model = make_tissue_model(problem, config);
      const AttachmentId id =
          grasp_stiffness > 0.0
              ? model->add_attachment(
                    {.point = {{grasp}, {1.0}}, .target_World_mm = grasp_rest, .stiffness_mN_per_mm = grasp_stiffness})
              : -1;
      std::vector<double> ms, cpu_ms;
      double iters = 0.0, final_residual = 0.0;
      int unhealthy = 0;
      std::string warning, last_warning;
      for (int f = 0; f < frames; ++f) {
        const double pull = std::min(1.0, (f + 1) / 60.0);
        if (id >= 0) model->set_attachment_target(id, grasp_rest + Eigen::Vector3d(25.0 * pull, 0, 0));
        const double cpu0 = process_cpu_ms();
        const StepSummary s = model->step(1.0 / 60.0);
        cpu_ms.push_back(process_cpu_ms() - cpu0);
        ms.push_back(s.wall_time_ms);
        iters += s.iterations;
        final_residual = s.final_residual;
        last_warning = s.warning;
        if (!s.healthy) {
          ++unhealthy;
          if (warning.empty()) warning = s.warning;
        }
      }
      const double median = percentile(ms, 0.5);
      out["runs"].push_back({{"model", variant.label},
                             {"threads", t},
                             {"iterations", config.iterations},
                             {"substeps", config.substeps},
                             {"linear_solver", config.linear_solver},
                             {"energy", config.energy},
                             {"median_frame_ms", median},
                             {"p90_frame_ms", percentile(ms, 0.9)},
                             {"min_frame_ms", percentile(ms, 0.0)},
                             {"median_cpu_ms", percentile(cpu_ms, 0.5)},
                             {"median_rate_hz", median > 0 ? 1000.0 / median : 0.0},
                             {"mean_iterations_per_frame", iters / frames},
                             {"final_residual", final_residual},
                             {"unhealthy_frames", unhealthy},
                             {"first_warning", warning},
                             {"last_warning", last_warning}});
      std::cerr << variant.label << " threads=" << t << " median " << median << " ms\n";
      if (!positions_csv.empty()) {
        std::ofstream csv(positions_csv);
        if (!csv) {
          std::cerr << "arnav-sim-bench: cannot write --positions-csv " << positions_csv << "\n";
          return 2;
        }
        csv.precision(17);
        const Eigen::Matrix3Xd& x = model->positions_World_mm();
        for (Eigen::Index i = 0; i < x.cols(); ++i) csv << x(0, i) << "," << x(1, i) << "," << x(2, i) << "\n";
      }
    }
  }
  std::cout << out.dump(2) << "\n";
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-sim-bench", [&] { return main_body(argc, argv); });
}
