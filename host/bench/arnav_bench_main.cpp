// arnav-bench: benchmarks that print error against run time.
//   arnav-bench deform [--quick] [--out DIR]   tissue models on the bundled liver
//   arnav-bench plot deform.csv out.png          redraw the plot from a CSV
//   arnav-bench register [--quick] [--out DIR]  in-silico registration (TRE vs run time)
//   arnav-bench track [--frames N] [--out DIR]  per-frame tracking (TRE and frame time)
//   arnav-bench cut [--quick] [--out DIR]      the scalpel cutting the liver, every model
// Writes DIR/deform.csv and DIR/deform_pareto.png and prints the CSV rows' summary as
// JSON on stdout. Exit 0 done, 1 nothing measured (every scenario skipped: the reasons are
// printed, no plot written), 2 usage or scene errors, 3 internal error.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <fstream>
#include <iostream>

#include "host/bench/cut_bench.hpp"
#include "host/bench/cut_reference.hpp"
#include "host/bench/deform_bench.hpp"
#include "host/bench/pareto_plot.hpp"
#include "host/bench/register_bench.hpp"
#include "host/bench/register_hard_bench.hpp"
#include "host/bench/transection_bench.hpp"
#include "host/mesh/load_error.hpp"
#include "protocol/guarded_main.hpp"

// Runs one subcommand: a bad input file exits 2, any other failure 1, each with its message.
static int exit_code_of(const std::function<int()>& body) {
  try {
    return body();
  } catch (const arnav::host::LoadError& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 1;
  }
}

// arnav-bench register --hard: the cases of register_hard_bench.hpp; prints per split and
// method the mean TRE, the worst case and the cases worse than the reference.
static int run_hard(const arnav::host::RegisterBenchOptions& ro, arnav::host::RegisterHardOptions ho, const std::string& out_dir) {
  using namespace arnav::host;
  ho.data_dir = ro.data_dir;
  ho.scene_dir = ro.scene_dir;
  ho.registration_scene = ro.registration_scene;
  ho.truth_scene = ro.truth_scene;
  ho.quick = ro.quick;
  try {
    const std::vector<RegisterHardRow> rows = run_register_hard_bench(ho);
    std::filesystem::create_directories(out_dir);
    write_register_hard_csv(out_dir + "/register_hard.csv", rows);
    std::cout << "{\"csv\":\"" << out_dir << "/register_hard.csv\",\"methods\":[";
    bool first = true;
    for (const std::string split : {"dev", "held-out"})
      for (const bool aligned : {true, false})
        for (const std::string m : {"none", "landmark_rigid", "surface_rigid", "surface_rigid_prior", "loads", "loads_prior"}) {
          double mean = 0, worst = 0, wall = 0, ref = 0;
          int n = 0, worse = 0;
          for (const auto& r : rows)
            if (r.split == split && r.aligned == aligned && r.method == m) {
              mean += r.tre.mean;
              ref += r.reference_mean_mm;
              worst = std::max(worst, r.tre.mean);
              wall += r.wall_s;
              worse += r.tre.mean > r.reference_mean_mm + 1e-9 ? 1 : 0;
              ++n;
            }
          if (n == 0) continue;
          std::cout << (first ? "" : ",") << "{\"split\":\"" << split << "\",\"aligned\":" << (aligned ? "true" : "false") << ",\"method\":\"" << m
                    << "\",\"cases\":" << n << ",\"tre_mean_mm\":" << mean / n << ",\"reference_mean_mm\":" << ref / n
                    << ",\"worst_case_mean_mm\":" << worst << ",\"worse_than_reference\":" << worse << ",\"wall_s\":" << wall / n << "}";
          first = false;
        }
    std::cout << "]}\n";
  } catch (const LoadError& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

static int main_body(int argc, char** argv) {
  using namespace arnav::host;
  CLI::App app{"arnav-bench: error against run time (docs/benchmarks.md)"};
  app.require_subcommand(1);
  DeformBenchOptions options;
  options.data_dir = ARNAV_DEFAULT_DATA_DIR;
  std::string out_dir = "bench_out";
  CLI::App* deform = app.add_subcommand("deform", "tissue models on the bundled liver: frame time vs error against a reference");
  deform->add_flag("--quick", options.quick, "CI smoke run: coarse mesh, two settings, 5 frames, coarse reference (numbers not meaningful)");
  deform->add_option("-o,--out", out_dir, "output folder for deform.csv and deform_pareto.png");
  deform->add_option("--data", options.data_dir, "data folder with liver/*.scene.yaml");
  deform->add_option("--patient", options.scene_set,
                     "scene set under the data folder: <set>_coarse, <set> and <set>_reference .scene.yaml (default liver/liver; "
                     "other patients: patients/sksurgery_liver, patients/sksurgery_liver_fine)");
  deform->add_option("--frames", options.frames, "frames per run (1/60 s each)")->check(CLI::PositiveNumber);
  deform->add_option("--threads", options.threads, "model threads")->check(CLI::PositiveNumber);
  deform->add_option("--scenario", options.scenarios, "scenarios to run (gravity_sag, lobe_pull, vessel_stiffened)");
  deform->add_option("--setting", options.setting_prefixes,
                     "run only the settings whose label starts with this (repeatable), e.g. 'fem', 'xpbd s4'");
  deform->add_option("--mesh", options.meshes, "model meshes to run (coarse, fine)")
      ->check(CLI::IsMember({"coarse", "fine"}));
  std::string csv_in, png_out;
  CLI::App* plot = app.add_subcommand("plot", "redraw the Pareto PNG from a deform.csv");
  plot->add_option("csv", csv_in, "deform.csv written by 'arnav-bench deform'")->required()->check(CLI::ExistingFile);
  plot->add_option("png", png_out, "PNG to write")->required();
  RegisterBenchOptions reg_options;
  reg_options.data_dir = ARNAV_DEFAULT_DATA_DIR;
  CLI::App* reg = app.add_subcommand("register", "in-silico registration: TRE (mean/median/p90/max) against run time");
  reg->add_flag("--quick", reg_options.quick, "CI smoke run: one state, 30 % coverage, 1 mm noise");
  reg->add_option("-o,--out", out_dir, "output folder for register.csv and the PNG plots");
  reg->add_option("--data", reg_options.data_dir, "data folder with liver/*.scene.yaml");
  reg->add_option("--states", reg_options.states, "deformed states (1-3)")->check(CLI::Range(1, 3));
  reg->add_option("--coverage", reg_options.coverages, "surface coverages (fractions)")->check(CLI::Range(0.05, 0.9));
  reg->add_option("--noise", reg_options.noises_mm, "point noise, per-axis sigma in mm")->check(CLI::Range(0.0, 10.0));
  reg->add_option("--model", reg_options.model_kind, "registering tissue model kind (default: the registration scene's)");
  reg->add_option("--schedule", reg_options.schedule, "data-weight schedule, stiff to flexible")->check(CLI::PositiveNumber);
  reg->add_option("--scene", reg_options.registration_scene, "registration scene in data/liver");
  std::string reg_patient;
  reg->add_option("--patient", reg_patient,
                  "another patient: patients/NAME registers on data/patients/NAME_coarse.scene.yaml against states of NAME.scene.yaml "
                  "(patients/sksurgery_liver, patients/sksurgery_liver_fine)");
  reg->add_option("--method", reg_options.methods, "non-rigid methods: energy (rows 'nonrigid'), loads (rows 'nonrigid_loads'); default both")
      ->check(CLI::IsMember({"energy", "loads"}));
  reg->add_option("--patches", reg_options.basis_patches, "loads: surface patches of the load basis")->check(CLI::PositiveNumber);
  reg->add_option("--support-clusters", reg_options.support_clusters, "loads: parts of the fixed region translated (0: none)")->check(CLI::NonNegativeNumber);
  reg->add_flag("--no-gravity-modes", reg_options.no_gravity_modes, "loads: no gravity-change modes");
  reg->add_flag("--fixed-pose", reg_options.loads_fixed_pose, "loads: keep the ICP pose, fit the weights only");
  reg->add_option("--landmark-error", reg_options.landmark_error_mm, "loads: landmark error (mm RMS) weighting the landmark term; 0: landmarks not used by the fit")
      ->check(CLI::NonNegativeNumber);
  reg->add_option("--prior-strain", reg_options.prior_strain, "loads: RMS strain of the deformation prior (MAP regularisation); 0: discrepancy principle")
      ->check(CLI::NonNegativeNumber);
  reg->add_flag("--prebuilt-basis", reg_options.prebuilt_basis, "loads: build the basis once per run (as before surgery); case times exclude it");
  reg->add_flag("--scene-boundary", reg_options.scene_boundary, "hold the scene's fixed vertices during the non-rigid stage");
  reg->add_flag("--gravity-change", reg_options.gravity_change, "with a held boundary, fit a change of gravity (3 numbers) first");
  reg->add_flag("--no-self-contact", reg_options.no_self_contact, "switch the self-contact term off");
  reg->add_flag("--model-error", reg_options.model_error, "stop the schedule at sqrt(noise^2 + the volume surface's error^2)");
  reg->add_flag("--anchored-boundary", reg_options.anchored_boundary, "free fit, rigid part corrected by the fixed vertices' motion, then a fit holding them");
  reg->add_option("--seed", reg_options.seed, "random seed");
  reg->add_option("--export", reg_options.export_dir, "write the first case's inputs for arnav-register (surface.xyz, landmarks.csv, targets.csv, truth_targets.csv)");
  reg->add_option("--updates", reg_options.updates_per_level, "correspondence updates per level")->check(CLI::PositiveNumber);
  reg->add_option("--steps", reg_options.steps_per_update, "model steps per correspondence update")->check(CLI::PositiveNumber);
  reg->add_flag("--pose-prior", reg_options.pose_prior, "the start's uncertainty (the landmark fit's covariance) as a prior of the surface fits (issue 22)");
  reg->add_flag("--estimate-noise", reg_options.estimate_noise, "the noise estimated from the points instead of told");
  bool reg_hard = false;
  RegisterHardOptions hard_options;
  reg->add_flag("--hard", reg_hard,
                "cases the method cannot share (issue 22): perturbed preoperative shape, other supports, a 20-40 mm local push, 15-25 % "
                "coverage, aligned and misaligned, noise not told; development and held-out cases (register_hard.csv)");
  reg->add_option("--hard-dev", hard_options.dev_cases, "--hard: development cases (seeds 1..)")->check(CLI::Range(0, 50));
  reg->add_option("--hard-heldout", hard_options.heldout_cases, "--hard: held-out cases (seeds 1001..)")->check(CLI::Range(0, 50));
  RegisterBenchOptions track_options;
  track_options.data_dir = ARNAV_DEFAULT_DATA_DIR;
  int track_frames = 600;
  CLI::App* track = app.add_subcommand("track", "per-frame tracking over a 10 s deforming sequence: TRE and frame time");
  track->add_option("-o,--out", out_dir, "output folder for track.csv and track.png");
  track->add_option("--data", track_options.data_dir, "data folder with liver/*.scene.yaml");
  track->add_option("--frames", track_frames, "frames at 60 Hz (default 600 = 10 s)")->check(CLI::PositiveNumber);
  track->add_flag("--scene-model-settings", track_options.track_scene_model_settings,
                  "step the scene's own model settings instead of the recommended real-time ones");
  CutBenchOptions cut_options;
  cut_options.data_dir = ARNAV_DEFAULT_DATA_DIR;
  CLI::App* cut = app.add_subcommand("cut", "the scalpel cutting the liver: topology update, frame time, quality, volume, cut-path error in the material");
  cut->add_flag("--quick", cut_options.quick, "CI smoke run: coarse mesh, XPBD, right-lobe path, 150 frames");
  cut->add_option("-o,--out", out_dir, "output folder for cut.csv and cut_frames.csv (per frame)");
  cut->add_option("--data", cut_options.data_dir, "data folder with liver/*.scene.yaml and liver/scalpel_*.csv");
  cut->add_option("--mesh", cut_options.meshes, "meshes (coarse: 4,768 tets; paper: 26,054 tets)")->check(CLI::IsMember({"coarse", "paper"}));
  cut->add_option("--scenario", cut_options.scenarios, "scenarios (right_lobe, ring: data/liver/scalpel_*.csv; ring_scene: ring and bottom cut made from the scene round the tumour, clear of the fixed vertices; ring_follow: the same with the blade following the tumour, docs/cut.md)")
      ->check(CLI::IsMember({"right_lobe", "ring", "ring_scene", "ring_follow"}));
  cut->add_option("--setting", cut_options.setting_prefixes, "run only the models whose label starts with this (repeatable)");
  cut->add_option("--reference", cut_options.reference_mesh, "also cut each run's path on this mesh with the same model: tumour-centroid and cut-surface error (cut_reference.csv, cut_reference.png)")
      ->check(CLI::IsMember({"coarse", "paper"}));
  cut->add_option("--frames", cut_options.max_frames, "cap the frames per run")->check(CLI::PositiveNumber);
  cut->add_option("--min-dihedral", cut_options.min_dihedral_deg,
                  "quality bound in degrees, overriding the scene's cutting.min_dihedral_deg (0: no embedded treatment, the elements as cut)")
      ->check(CLI::Range(0.0, 30.0));
  cut->add_option("--sagitta", cut_options.chord_sagitta_mm,
                  "refinement ahead of the blade where the cut curves: chord sagitta in mm, overriding the scene's cutting.chord_sagitta_mm "
                  "(0: cut the mesh as it is)")
      ->check(CLI::Range(0.0, 100.0));
  TransectionBenchOptions transection_options;
  CLI::App* transection = app.add_subcommand("transection", "a full transection of patient livers by the blade, every model, free and held: false stops, side volumes, frame time (JSON lines)");
  transection->add_option("--scene", transection_options.scenes, "scene files (default: data/patients/sksurgery_liver.scene.yaml, sksurgery_liver_fine.scene.yaml, data/liver/liver.scene.yaml)");
  transection->add_option("--setting", transection_options.setting_prefixes, "run only the models whose label starts with this (repeatable)");
  transection->add_option("--support", transection_options.supports, "free (no gravity, nothing fixed) and/or held (the scene's fixed vertices and gravity)")
      ->check(CLI::IsMember({"free", "held"}));
  transection->add_option("--threads", transection_options.threads, "model threads")->check(CLI::PositiveNumber);
  transection->add_option("--margin", transection_options.margin_mm, "mm the blade reaches beyond the organ on each side (default 30)")
      ->check(CLI::NonNegativeNumber);
  std::string rebuild = "inline";
  std::string local_updates = "on";
  cut->add_option("--fem-cut-rings", cut_options.fem_cut_region_rings,
                  "co-rotational FEM after a cut, while PCG runs on the old factor: rings of neighbours of the changed vertices "
                  "solved exactly on the current matrix (-1: no correction; default: the model's, 1; label +cut_rings N)")
      ->check(CLI::Range(-1, 5));
  cut->add_flag("--fem-background-refactor", cut_options.fem_background_refactor,
                "run the co-rotational FEM with refactor_in_background (the recommended real-time setting; label +background_refactor)");
  cut->add_option("--local-updates", local_updates,
                  "update the models in place after a cut where they can (on), rebuild them always (off), or both: each local run is then compared with the rebuilt one frame by frame (state difference)")
      ->check(CLI::IsMember({"on", "off", "both"}));
  cut->add_option("--rebuild", rebuild, "model rebuild after a cut: inline, background or both")->check(CLI::IsMember({"inline", "background", "both"}));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;  // --help: 0; usage errors: 2
  }

  if (plot->parsed()) {
    try {
      write_pareto_png(png_out, read_deform_csv(csv_in));
    } catch (const std::runtime_error& e) {
      std::cerr << "arnav-bench: " << e.what() << "\n";
      return 2;
    }
    return 0;
  }

  if (track->parsed()) {
    try {
      std::string model;
      const std::vector<TrackBenchRow> rows = run_track_bench(track_options, track_frames, model);
      std::filesystem::create_directories(out_dir);
      std::ofstream csv(out_dir + "/track.csv");
      csv << "frame,t_s,tre_tracked_mm,tre_max_tracked_mm,tre_static_mm,frame_ms,model_ms,tracked,healthy\n";
      std::vector<double> ft, mt, tre, tre_static;
      int unhealthy = 0;
      for (const auto& r : rows) {
        csv << r.frame << ',' << r.t_s << ',' << r.tre_tracked_mm << ',' << r.tre_max_tracked_mm << ',' << r.tre_static_mm << ',' << r.frame_ms
            << ',' << r.model_ms << ',' << r.tracked << ',' << (r.healthy ? 1 : 0) << '\n';
        ft.push_back(r.frame_ms);
        mt.push_back(r.model_ms);
        tre.push_back(r.tre_tracked_mm);
        tre_static.push_back(r.tre_static_mm);
        unhealthy += r.healthy ? 0 : 1;
      }
      auto q = [](std::vector<double> v, double p) {
        std::sort(v.begin(), v.end());
        return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
      };
      auto mean = [](const std::vector<double>& v) {
        double s = 0;
        for (double x : v) s += x;
        return s / static_cast<double>(v.size());
      };
      write_track_plot(out_dir + "/track.png", rows);
      std::cout << "{\"csv\":\"" << out_dir << "/track.csv\",\"model\":\"" << model << "\",\"frames\":" << rows.size()
                << ",\"tre_mean_tracked_mm\":" << mean(tre) << ",\"tre_max_frame_mean_tracked_mm\":" << q(tre, 1.0)
                << ",\"tre_mean_static_mm\":" << mean(tre_static) << ",\"tre_max_frame_mean_static_mm\":" << q(tre_static, 1.0)
                << ",\"frame_ms_median\":" << q(ft, 0.5) << ",\"frame_ms_p90\":" << q(ft, 0.9) << ",\"frame_ms_p99\":" << q(ft, 0.99)
                << ",\"frame_ms_max\":" << q(ft, 1.0) << ",\"model_ms_median\":" << q(mt, 0.5) << ",\"model_ms_p99\":" << q(mt, 0.99)
                << ",\"frames_over_16_7_ms\":" << std::count_if(ft.begin(), ft.end(), [](double v) { return v > 1000.0 / 60.0; })
                << ",\"unhealthy_frames\":" << unhealthy << "}\n";
    } catch (const LoadError& e) {
      std::cerr << "arnav-bench: " << e.what() << "\n";
      return 2;
    } catch (const std::exception& e) {
      std::cerr << "arnav-bench: " << e.what() << "\n";
      return 1;
    }
    return 0;
  }
  if (reg->parsed()) {
    if (!reg_patient.empty()) {
      const auto slash = reg_patient.find_last_of('/');
      if (slash == std::string::npos || slash == 0 || slash + 1 == reg_patient.size()) {
        std::cerr << "arnav-bench register: --patient wants DIR/NAME (e.g. patients/sksurgery_liver), got '" << reg_patient << "'\n";
        return 2;
      }
      reg_options.scene_dir = reg_patient.substr(0, slash);
      reg_options.truth_scene = reg_patient.substr(slash + 1) + ".scene.yaml";
      reg_options.registration_scene = reg_patient.substr(slash + 1) + "_coarse.scene.yaml";
    }
    if (reg_hard) return run_hard(reg_options, hard_options, out_dir);
    return exit_code_of([&] {
      const std::vector<RegisterBenchRow> rows = run_register_bench(reg_options);
      std::filesystem::create_directories(out_dir);
      write_register_csv(out_dir + "/register.csv", rows);
      write_register_plots(out_dir, rows);
      // Summary: mean over cases of each statistic, per method.
      const auto cases = std::count_if(rows.begin(), rows.end(), [](const RegisterBenchRow& r) { return r.method == "optimal_rigid"; });
      std::cout << "{\"csv\":\"" << out_dir << "/register.csv\",\"cases\":" << cases << ",\"methods\":{";
      bool first = true;
      for (const std::string m : {"optimal_rigid", "landmark_rigid", "surface_rigid", "nonrigid", "nonrigid_loads"}) {
        double mean = 0, median = 0, p90 = 0, max = 0, wall = 0, worst_mean = 0;
        int n = 0;
        for (const auto& r : rows)
          if (r.method == m) {
            mean += r.tre.mean;
            median += r.tre.median;
            p90 += r.tre.p90;
            max += r.tre.max;
            wall += r.wall_s;
            worst_mean = std::max(worst_mean, r.tre.mean);
            ++n;
          }
        if (n == 0) continue;
        std::cout << (first ? "" : ",") << "\"" << m << "\":{\"tre_mean_mm\":" << mean / n << ",\"tre_median_mm\":" << median / n
                  << ",\"tre_p90_mm\":" << p90 / n << ",\"tre_max_mm\":" << max / n << ",\"worst_case_mean_mm\":" << worst_mean
                  << ",\"wall_s\":" << wall / n << "}";
        first = false;
      }
      std::cout << "}}\n";
      return 0;
    });
  }

  if (transection->parsed()) {
    if (transection_options.scenes.empty())
      transection_options.scenes = {std::string(ARNAV_DEFAULT_DATA_DIR) + "/patients/sksurgery_liver.scene.yaml",
                                    std::string(ARNAV_DEFAULT_DATA_DIR) + "/patients/sksurgery_liver_fine.scene.yaml",
                                    std::string(ARNAV_DEFAULT_DATA_DIR) + "/liver/liver.scene.yaml"};
    return exit_code_of([&] { return run_transection_bench(transection_options) == 0 ? 0 : 1; });
  }

  if (cut->parsed()) {
    cut_options.local_updates = local_updates == "on" ? std::vector<bool>{true} : local_updates == "off" ? std::vector<bool>{false} : std::vector<bool>{false, true};
    cut_options.background = rebuild == "inline" ? std::vector<bool>{false} : rebuild == "background" ? std::vector<bool>{true} : std::vector<bool>{false, true};
    std::vector<CutBenchRow> rows;
    try {
      rows = run_cut_bench(cut_options);
      std::filesystem::create_directories(out_dir);
      write_cut_csv(out_dir + "/cut.csv", rows);
      write_cut_frames_csv(out_dir + "/cut_frames.csv", rows);
      if (!cut_options.reference_mesh.empty()) {
        write_cut_reference_csv(out_dir + "/cut_reference.csv", rows);
        write_cut_reference_png(out_dir + "/cut_reference.png", rows);
      }
    } catch (const std::exception& e) {
      std::cerr << "arnav-bench: " << e.what() << "\n";
      return 2;
    }
    std::cout << "{\"csv\":\"" << out_dir << "/cut.csv\",\"rows\":[";
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const auto& r = rows[i];
      std::cout << (i ? "," : "") << "{\"mesh\":\"" << r.mesh << "\",\"scenario\":\"" << r.scenario << "\",\"model\":\"" << r.label
                << "\",\"background_rebuild\":" << (r.background ? "true" : "false") << ",\"frames\":" << r.frames << ",\"topology_p99_ms\":" << r.topology_p99_ms << ",\"frame_median_ms\":" << r.frame_median_ms
                << ",\"frame_p99_ms\":" << r.frame_p99_ms << ",\"chord_sagitta_mm\":" << r.chord_sagitta_mm << ",\"tets_after\":" << r.tets_after << ",\"min_dihedral_deg\":" << r.min_dihedral_deg << ",\"min_dihedral_active_deg\":" << r.min_dihedral_active_deg
                << ",\"embedded_tets\":" << r.embedded_tets << ",\"embedded_volume_fraction\":" << r.embedded_volume_fraction << ",\"volume_change_rel\":"
                << r.volume_change_rel << ",\"path_error_mm\":{\"p50\":" << r.path_error_p50_mm << ",\"p95\":" << r.path_error_p95_mm << ",\"max\":" << r.path_error_max_mm << ",\"vertices\":" << r.cut_vertices_measured << "},\"cutter_snap_deviation_mm\":" << r.path_fidelity_mm << ",\"completion_deviation_mm\":" << r.completion_deviation_mm << ",\"pieces\":" << r.pieces << ",\"tumours_freed\":" << r.tumours_freed << ",\"tumours_separated\":" << r.tumours_separated << ",\"freed_drop_mm\":" << r.freed_drop_mm << ",\"organ_drift_mm\":" << r.organ_drift_mm << ",\"local_updates\":" << r.local_updates << ",\"rebuilds\":" << r.rebuilds
                << ",\"local_updates_enabled\":" << (r.local_updates_enabled ? "true" : "false") << ",\"local_median_ms\":" << r.local_median_ms
                << ",\"local_p99_ms\":" << r.local_p99_ms << ",\"rebuild_median_ms\":" << r.rebuild_median_ms << ",\"rebuild_p99_ms\":" << r.rebuild_p99_ms
                << ",\"state_diff_max_mm\":" << r.state_diff_max_mm << ",\"state_diff_final_mm\":" << r.state_diff_final_mm
                << ",\"mesh_valid\":" << (r.mesh_valid ? "true" : "false") << ",\"healthy\":" << (r.healthy ? "true" : "false") << "}";
    }
    std::cout << "]}\n";
    return 0;
  }

  DeformBenchResult result;
  try {
    result = run_deform_bench(options);
  } catch (const LoadError& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 2;
  } catch (const std::invalid_argument& e) {
    std::cerr << "arnav-bench: " << e.what() << "\n";
    return 2;
  }
  std::filesystem::create_directories(out_dir);
  write_deform_csv(out_dir + "/deform.csv", result);
  if (result.rows.empty()) {
    // Nothing was measured: say why (each skipped scenario's reason), write no plot, exit 1.
    std::cerr << "arnav-bench deform: no benchmark rows:\n";
    if (result.references.empty()) std::cerr << "  no scenario was run (--scenario)\n";
    for (const auto& r : result.references) {
      if (r.tets == 0) std::cerr << "  " << r.scenario << ": skipped: " << r.scene << "\n";
      else std::cerr << "  " << r.scenario << ": reference solved, but no setting matched --setting/--mesh\n";
    }
    std::cerr << "arnav-bench deform: fix the scene (docs/scene.md) or pick other --scenario/--setting/--mesh values; "
              << out_dir << "/deform.csv holds the header only\n";
    return 1;
  }
  write_pareto_png(out_dir + "/deform_pareto.png", result);
  std::cout << "{\"csv\":\"" << out_dir << "/deform.csv\",\"png\":\"" << out_dir << "/deform_pareto.png\",\"rows\":" << result.rows.size()
            << ",\"references\":[";
  for (std::size_t i = 0; i < result.references.size(); ++i) {
    const auto& r = result.references[i];
    std::cout << (i ? "," : "") << "{\"scenario\":\"" << r.scenario << "\",\"tets\":" << r.tets << ",\"iterations\":" << r.iterations
              << ",\"last_max_increment_mm\":" << r.last_max_increment_mm << ",\"converged\":" << (r.converged ? "true" : "false")
              << ",\"wall_s\":" << r.wall_s << "}";
  }
  std::cout << "]}\n";
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-bench", [&] { return main_body(argc, argv); });
}
