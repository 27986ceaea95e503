// arnav-ar-error: AR error of a recorded bench session (overlay.csv against the synthetic
// camera's ground truth); prints JSON. Used by scripts/demo (docs/hil.md).
#include <fstream>
#include <iostream>

#include <CLI/CLI.hpp>

#include "hil_tests/scenarios/ar_error.hpp"
#include "protocol/guarded_main.hpp"

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-ar-error: overlay tumour centroid vs the synthetic camera's ground truth (JSON)"};
  std::string session, truth, csv;
  app.add_option("--session", session, "the host's session file")->required();
  app.add_option("--ground-truth", truth, "the synthetic camera's ground_truth.csv")->required();
  app.add_option("--overlay-csv", csv, "the host's overlay.csv (--record)")->required();
  std::string frames_csv, surfaces;
  app.add_option("--tumour-surfaces", surfaces, "the host's tumour_Cam.bin (--record): adds the tumour surface distance");
  app.add_option("--frames-csv", frames_csv, "also write one row per camera frame (availability, 2-D and 3-D errors) to this CSV");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  try {
    const arnav::hil::ArErrorReport rep = arnav::hil::evaluate_ar_error(session, truth, csv, surfaces);
    if (!frames_csv.empty()) {
      std::ofstream out(frames_csv);
      out << rep.frames_csv();
      if (!out) throw std::runtime_error("--frames-csv " + frames_csv + ": cannot write the file (check the folder)");
    }
    std::cout << rep.summary().dump(2) << std::endl;
  } catch (const std::exception& e) {
    std::cerr << "arnav-ar-error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-ar-error", [&] { return main_body(argc, argv); });
}
