// arnav-calib: the calibration technicians' program. Every command writes its
// calibration files, a readable report.txt and PNG plots into --out (docs/calibration.md).
#include <iostream>
#include <map>
#include <string>

#include <CLI/CLI.hpp>

#include "calibration/lib/calib_error.hpp"
#include "calibration/tool/commands.hpp"
#include "protocol/guarded_main.hpp"

static int main_body(int argc, char** argv) {
  using namespace arnav::calib;
  CLI::App app{"arnav-calib: ARNav calibration (boards, intrinsics, pivot, hand-eye, registration, AR accuracy).\n"
               "Units: mm and degrees on the command line; files in mm/radians. See docs/calibration.md."};
  app.require_subcommand(1);
  std::map<std::string, tool::Run> runs;
  runs["board"] = tool::add_board_command(app);
  runs["intrinsics"] = tool::add_intrinsics_command(app);
  runs["pivot"] = tool::add_pivot_command(app);
  runs["handeye"] = tool::add_handeye_command(app);
  runs["register"] = tool::add_register_command(app);
  runs["ar-accuracy"] = tool::add_ar_accuracy_command(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  try {
    for (auto* sub : app.get_subcommands()) runs.at(sub->get_name())();
  } catch (const DegenerateInput& e) {
    std::cerr << "arnav-calib: calibration rejected: " << e.what() << "\n";
    return 3;
  } catch (const CalibError& e) {
    std::cerr << "arnav-calib: error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-calib: error: " << e.what() << "\n";
    return 2;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-calib", [&] { return main_body(argc, argv); });
}
