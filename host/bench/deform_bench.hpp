#pragma once
// arnav-bench deform: error against run time of the tissue models on the bundled liver.
// For each scenario, model setting and mesh: median wall time per 1/60 s frame, and the
// tumour-centroid and maximum surface errors against a reference solution (co-rotational
// FEM relaxed to its static equilibrium with an exact CHOLMOD solve per step, on a finer mesh).
// Frame World, units mm, s.
#include <string>
#include <vector>

#include "host/sim/model_config.hpp"

namespace arnav::host {

struct DeformBenchOptions {
  std::string data_dir;        // folder with liver/*.scene.yaml
  bool quick = false;          // CI smoke run: coarse mesh, few settings, short runs
  int frames = 45;             // simulated frames per run (0.75 s at 60 Hz)
  int threads = 1;             // model threads (1: CPU time = unloaded wall time)
  std::vector<std::string> scenarios = {"gravity_sag", "lobe_pull", "vessel_stiffened"};
  std::vector<std::string> setting_prefixes;  // run only settings whose label starts with one (empty: all)
  std::vector<std::string> meshes = {"coarse", "fine"};  // model meshes to run (quick: coarse only)
  // Scene set, relative to data_dir: <set>_coarse / <set> / <set>_reference .scene.yaml
  // ("liver/liver": the bundled liver; "patients/sksurgery_liver" etc.: other patients).
  std::string scene_set = "liver/liver";
};

struct DeformBenchRow {
  std::string scenario, label, mesh;
  ModelConfig config;
  int vertices = 0, tets = 0, frames_run = 0;
  double median_frame_ms = 0, p90_frame_ms = 0;  // wall time (inflated when the machine is shared)
  double median_frame_cpu_ms = 0;                // process CPU time per frame (all threads)
  double tumour_error_mm = 0, max_surface_error_mm = 0;
  double reference_tumour_displacement_mm = 0, reference_max_surface_displacement_mm = 0;
  int reference_tets = 0;
  bool healthy = true, vessels_modelled = false;
  // Inverted elements (a counted warning, docs/sim.md): frames that ended with some and
  // the longest run of such frames (the worst recovery time, s). Written into the note.
  int frames_with_inverted = 0;
  double worst_inverted_run_s = 0.0;
  std::string note;
};

struct ReferenceInfo {
  std::string scenario, scene;
  int vertices = 0, tets = 0, iterations = 0;
  double last_max_increment_mm = 0, wall_s = 0;
  bool converged = false;
};

struct DeformBenchResult {
  std::vector<DeformBenchRow> rows;
  std::vector<ReferenceInfo> references;
};

// Runs the benchmark; progress goes to stderr. Throws LoadError / std::invalid_argument
// when the scenes or models cannot be built.
DeformBenchResult run_deform_bench(const DeformBenchOptions& options);

void write_deform_csv(const std::string& path, const DeformBenchResult& result);
// Reads a CSV written by write_deform_csv (for re-plotting); throws naming the line.
DeformBenchResult read_deform_csv(const std::string& path);

}  // namespace arnav::host
