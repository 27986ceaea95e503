// arnav-bench: benchmarks that print error against run time.
//   arnav-bench deform [--quick] [--out DIR]   tissue models on the bundled liver
//   arnav-bench plot deform.csv out.png          redraw the plot from a CSV
//   arnav-bench cut [--quick] [--out DIR]      the scalpel cutting the liver, every model
// Writes DIR/deform.csv and DIR/deform_pareto.png and prints the CSV rows' summary as
// JSON on stdout. Exit 2 on usage or scene errors.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <iostream>

#include "host/bench/cut_bench.hpp"
#include "host/bench/deform_bench.hpp"
#include "host/bench/pareto_plot.hpp"
#include "host/scene/load_error.hpp"

int main(int argc, char** argv) {
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
  CutBenchOptions cut_options;
  cut_options.data_dir = ARNAV_DEFAULT_DATA_DIR;
  CLI::App* cut = app.add_subcommand("cut", "the scalpel cutting the liver: topology update, frame time, quality, volume, path fidelity");
  cut->add_flag("--quick", cut_options.quick, "CI smoke run: coarse mesh, XPBD, right-lobe path, 150 frames");
  cut->add_option("-o,--out", out_dir, "output folder for cut.csv");
  cut->add_option("--data", cut_options.data_dir, "data folder with liver/*.scene.yaml and liver/scalpel_*.csv");
  cut->add_option("--mesh", cut_options.meshes, "meshes (coarse: 4,768 tets; paper: 26,054 tets)")->check(CLI::IsMember({"coarse", "paper"}));
  cut->add_option("--scenario", cut_options.scenarios, "scenarios (right_lobe, ring)")->check(CLI::IsMember({"right_lobe", "ring"}));
  cut->add_option("--setting", cut_options.setting_prefixes, "run only the models whose label starts with this (repeatable)");
  cut->add_option("--frames", cut_options.max_frames, "cap the frames per run")->check(CLI::PositiveNumber);
  std::string rebuild = "inline";
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

  if (cut->parsed()) {
    cut_options.background = rebuild == "inline" ? std::vector<bool>{false} : rebuild == "background" ? std::vector<bool>{true} : std::vector<bool>{false, true};
    std::vector<CutBenchRow> rows;
    try {
      rows = run_cut_bench(cut_options);
      std::filesystem::create_directories(out_dir);
      write_cut_csv(out_dir + "/cut.csv", rows);
    } catch (const std::exception& e) {
      std::cerr << "arnav-bench: " << e.what() << "\n";
      return 2;
    }
    std::cout << "{\"csv\":\"" << out_dir << "/cut.csv\",\"rows\":[";
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const auto& r = rows[i];
      std::cout << (i ? "," : "") << "{\"mesh\":\"" << r.mesh << "\",\"scenario\":\"" << r.scenario << "\",\"model\":\"" << r.label
                << "\",\"background_rebuild\":" << (r.background ? "true" : "false") << ",\"frames\":" << r.frames << ",\"topology_p99_ms\":" << r.topology_p99_ms << ",\"frame_median_ms\":" << r.frame_median_ms
                << ",\"frame_p99_ms\":" << r.frame_p99_ms << ",\"min_dihedral_deg\":" << r.min_dihedral_deg << ",\"volume_change_rel\":"
                << r.volume_change_rel << ",\"path_fidelity_mm\":" << r.path_fidelity_mm << ",\"pieces\":" << r.pieces
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
