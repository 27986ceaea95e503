// arnav-sim: runs a patient scene headless for N frames, writes positions (VTK or OBJ
// sequences) and a per-frame summary CSV, so results can be looked at (ParaView, MeshLab).
// Exit codes: 0 done, 1 the model became unhealthy (files up to that frame are written),
// 2 usage or scene errors.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"
#include "host/tools/sim_run.hpp"
#include "protocol/guarded_main.hpp"

static int main_body(int argc, char** argv) {
  using namespace arnav::host;
  CLI::App app{"arnav-sim: run a patient scene (YAML, see docs/scene.md) headless and write the results"};
  std::string scene_path;
  int frames = -1;
  SimRunOptions options;
  std::string model_kind;
  int iterations = 0, substeps = 0;
  app.add_option("scene", scene_path, "scene file, e.g. data/liver/liver.scene.yaml")->required();
  app.add_option("-n,--frames", frames, "frames to run (default: the scene's 'frames')")->check(CLI::NonNegativeNumber);
  app.add_option("-o,--out", options.out_dir, "output folder for position sequences and frames.csv (default: none, CSV to stdout)");
  app.add_option("-f,--format", options.format, "position files: vtk (volume, organ, tumours, vessels) or obj (surfaces)")
      ->check(CLI::IsMember({"vtk", "obj"}));
  app.add_option("--every", options.write_every, "write positions every N frames")->check(CLI::PositiveNumber);
  app.add_option("--model", model_kind,
                 "run this model kind instead of the scene's (mass_spring, xpbd, corotational_fem), with that kind's "
                 "recommended settings (docs/sim.md); --iterations/--substeps override them");
  app.add_option("--iterations", iterations, "override model.iterations")->check(CLI::PositiveNumber);
  app.add_option("--substeps", substeps, "override model.substeps")->check(CLI::PositiveNumber);
  std::string scalpel_path;
  app.add_option("--scalpel", scalpel_path,
                 "scalpel path CSV (t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z[,cutting], World mm): cut the organ "
                 "(the scene needs a 'cutting:' section, docs/cut.md)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;  // --help: 0; usage errors: 2
  }

  Scene scene;
  try {
    scene = load_scene(scene_path);
  } catch (const LoadError& e) {
    std::cerr << "arnav-sim: " << e.what() << "\n";
    return 2;
  }
  for (const auto& note : scene.notes) std::cerr << "arnav-sim: " << note << "\n";
  if (!model_kind.empty() && model_kind != scene.model.kind) {
    // The scene's solver settings belong to its own kind (an FEM integrator means nothing
    // to XPBD): start from the new kind's recommended settings.
    try {
      scene.model = recommended_model_config(model_kind);
    } catch (const std::invalid_argument& e) {
      std::cerr << "arnav-sim: --model: " << e.what() << "\n";
      return 2;
    }
  }
  if (iterations > 0) scene.model.iterations = iterations;
  if (substeps > 0) scene.model.substeps = substeps;
  options.frames = frames >= 0 ? frames : scene.frames;
  if (!scalpel_path.empty()) {
    if (!scene.cutting) {
      std::cerr << "arnav-sim: " << scene_path << " has no 'cutting:' section: add one to cut with --scalpel (docs/cut.md)\n";
      return 2;
    }
    try {
      options.scalpel = cut::load_scalpel_csv(scalpel_path);
    } catch (const LoadError& e) {
      std::cerr << "arnav-sim: " << e.what() << "\n";
      return 2;
    }
  }

  std::ofstream csv_file;
  if (!options.out_dir.empty()) {
    std::filesystem::create_directories(options.out_dir);
    csv_file.open(options.out_dir + "/frames.csv");
    if (!csv_file) {
      std::cerr << "arnav-sim: cannot write " << options.out_dir << "/frames.csv: check the folder\n";
      return 2;
    }
  }
  std::ostream& csv = options.out_dir.empty() ? std::cout : csv_file;
  SimRunResult r;
  try {
    r = run_scene(scene, options, csv);
  } catch (const std::invalid_argument& e) {
    std::cerr << "arnav-sim: " << scene_path << ": the model could not be built: " << e.what() << "\n";
    return 2;
  }
  std::ostringstream json;
  json << "{\"scene\":\"" << scene_path << "\",\"model\":\"" << scene.model.kind << "\",\"vertices\":" << scene.problem.mesh.num_vertices()
       << ",\"tetrahedra\":" << scene.problem.mesh.num_tets() << ",\"frames\":" << r.frames_run << ",\"dt_s\":" << scene.time_step_s
       << ",\"median_step_ms\":" << r.median_step_ms << ",\"max_displacement_mm\":" << r.max_displacement_mm
       << ",\"tumour_displacement_mm\":[" << r.tumour_displacement_mm.x() << "," << r.tumour_displacement_mm.y() << ","
       << r.tumour_displacement_mm.z() << "],\"frames_with_inverted\":" << r.frames_with_inverted
       << ",\"step_control_frames\":" << r.step_control_frames
       << ",\"peak_inverted\":" << r.peak_inverted << ",\"worst_inverted_run_s\":" << r.worst_inverted_run_s
       << ",\"peak_strain\":" << r.peak_strain << ",\"mesh_quality\":{\"min_dihedral_deg\":" << scene.mesh_quality.min_dihedral_deg
       << ",\"p01_dihedral_deg\":" << scene.mesh_quality.p01_dihedral_deg << ",\"max_dihedral_deg\":" << scene.mesh_quality.max_dihedral_deg
       << ",\"max_radius_edge_ratio\":" << scene.mesh_quality.max_radius_edge_ratio
       << ",\"min_volume_mm3\":" << scene.mesh_quality.min_volume_mm3 << ",\"slivers\":" << scene.mesh_quality.slivers
       << "},\"healthy\":" << (r.healthy ? "true" : "false");
  if (options.scalpel) {
    json << ",\"cut\":{\"tets\":" << r.tets << ",\"vertices\":" << r.vertices << ",\"pieces\":" << r.pieces << ",\"events\":" << r.cut_events
         << ",\"max_topology_update_ms\":" << r.max_topology_update_ms << "}";
  }
  json << "}";
  (options.out_dir.empty() ? std::cerr : std::cout) << json.str() << "\n";
  if (!r.healthy) {
    std::cerr << "arnav-sim: the model became unhealthy at frame " << r.frames_run << ": " << r.warning
              << " (try more substeps/iterations, a smaller time_step_s or another model)\n";
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-sim", [&] { return main_body(argc, argv); });
}
