// arnav-phantom-record: runs the bench's reference deformation (a grasper pulling the liver
// phantom; hil_tests/phantom/phantom_record.hpp) and writes the phantom recording the
// synthetic camera films and the simulated Polaris tracks (docs/hil.md, "Deforming
// phantom"). Prints a JSON summary. Exit 2 on bad input.
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "hil_tests/phantom/phantom_record.hpp"
#include "protocol/guarded_main.hpp"

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-phantom-record: the bench's reference deformation -> phantom recording (docs/hil.md)"};
  std::string scene, out;
  arnav::hil::PhantomScript s;
  std::vector<double> near{s.grasp_near_mm.x(), s.grasp_near_mm.y(), s.grasp_near_mm.z()};
  std::vector<double> pull{s.pull_mm.x(), s.pull_mm.y(), s.pull_mm.z()};
  bool quiet = false;
  std::string compare_scene;
  int compare_substeps = 6;
  app.add_option("--scene", scene, "reference scene (another mesh/model/material than the host's), e.g. "
                                   "hil_tests/scenarios/ar_demo/phantom_reference.scene.yaml")->required();
  app.add_option("--out", out, "phantom recording to write")->required();
  app.add_option("--fps", s.fps, "recorded frames per second")->capture_default_str();
  app.add_option("--duration", s.duration_s, "recording length, s")->capture_default_str();
  app.add_option("--grasp-near", near, "grasp the surface point nearest to this Model point (mm)")->expected(3);
  app.add_option("--grasp-radius", s.grasp_radius_mm, "grasped patch radius, mm")->capture_default_str();
  app.add_option("--stiffness", s.grasp_stiffness_mN_per_mm, "grasp spring per vertex, mN/mm")->capture_default_str();
  app.add_option("--pull", pull, "peak pull of the grasper, Model mm")->expected(3);
  app.add_option("--start", s.start_s, "pull starts at, s")->capture_default_str();
  app.add_option("--ramp", s.ramp_s, "pull ramp up/down, s")->capture_default_str();
  app.add_option("--hold", s.hold_s, "pull held, s")->capture_default_str();
  app.add_option("--rest", s.rest_s, "released between pulls, s")->capture_default_str();
  app.add_option("--substeps", s.substeps, "model steps per recorded frame")->capture_default_str();
  app.add_flag("--skip-rest-frames", s.skip_rest_frames,
               "neither solve nor write the frames at rest before the pull (frame 0 and the last one before it are kept)");
  app.add_flag("--gravity", s.gravity, "apply the scene's gravity (default off: frame 0 is the rest shape the host registered)");
  app.add_flag("--quiet", quiet, "no progress on stderr");
  app.add_option("--compare-scene", compare_scene,
                 "also run this scene (e.g. the host's) under the same grasp and report how far its tumour centroid is from "
                 "the reference's, next to a rigid (non-deforming) model");
  app.add_option("--compare-substeps", compare_substeps, "model steps per recorded frame for --compare-scene")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  s.grasp_near_mm = Eigen::Vector3d(near[0], near[1], near[2]);
  s.pull_mm = Eigen::Vector3d(pull[0], pull[1], pull[2]);
  const std::filesystem::path out_dir = std::filesystem::path(out).parent_path();
  if (!out_dir.empty() && !std::filesystem::is_directory(out_dir)) {
    std::cerr << "arnav-phantom-record: --out " << out << ": folder " << out_dir << " does not exist (create it first)\n";
    return 2;
  }
  arnav::hil::PhantomRecordStats st;
  nlohmann::json compare;
  try {
    const auto rec = arnav::hil::record_phantom(scene, s, st, [&](int k, int n) {
      if (!quiet && (k % 15 == 0 || k + 1 == n)) std::cerr << "arnav-phantom-record: frame " << k + 1 << " of " << n << "\n";
    });
    arnav::camera_sim::write_phantom_recording(out, rec);
    if (!compare_scene.empty()) {
      arnav::hil::PhantomScript cs = s;
      cs.substeps = compare_substeps;
      arnav::hil::PhantomRecordStats cst;
      const auto other = arnav::hil::record_phantom(compare_scene, cs, cst, [&](int k, int n) {
        if (!quiet && (k % 15 == 0 || k + 1 == n)) std::cerr << "arnav-phantom-record: compare frame " << k + 1 << " of " << n << "\n";
      });
      const auto cmp = arnav::hil::compare_tumour_centroids(rec, other);
      compare = {{"scene", compare_scene},
                 {"model", cst.model},
                 {"volume_vertices", cst.volume_vertices},
                 {"median_step_ms", cst.median_step_ms},
                 {"healthy", cst.healthy},
                 {"model_vs_reference_mm", {{"mean", cmp.model_mean_mm}, {"p95", cmp.model_p95_mm}, {"max", cmp.model_max_mm}}},
                 {"rigid_vs_reference_mm", {{"mean", cmp.rigid_mean_mm}, {"p95", cmp.rigid_p95_mm}, {"max", cmp.rigid_max_mm}}}};
    }
  } catch (const std::exception& e) {
    std::cerr << "arnav-phantom-record: " << e.what() << "\n";
    return 2;
  }
  nlohmann::json j{{"recording", out},
                   {"frames", st.frames},
                   {"model", st.model},
                   {"volume_vertices", st.volume_vertices},
                   {"volume_tets", st.volume_tets},
                   {"surface_vertices", st.surface_vertices},
                   {"grasped_vertices", st.grasped_vertices},
                   {"max_tumour_displacement_mm", st.max_tumour_displacement_mm},
                   {"max_surface_displacement_mm", st.max_surface_displacement_mm},
                   {"median_step_ms", st.median_step_ms},
                   {"surface_min_mm", {st.surface_min_mm.x(), st.surface_min_mm.y(), st.surface_min_mm.z()}},
                   {"surface_max_mm", {st.surface_max_mm.x(), st.surface_max_mm.y(), st.surface_max_mm.z()}},
                   {"tumour_rest_mm", {st.tumour_rest_mm.x(), st.tumour_rest_mm.y(), st.tumour_rest_mm.z()}},
                   {"grasp_centre_mm", {st.grasp_centre_mm.x(), st.grasp_centre_mm.y(), st.grasp_centre_mm.z()}},
                   {"healthy", st.healthy},
                   {"warning", st.warning}};
  if (!compare.is_null()) j["compare"] = compare;
  std::cout << j.dump(2) << std::endl;
  return st.healthy ? 0 : 1;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-phantom-record", [&] { return main_body(argc, argv); });
}
