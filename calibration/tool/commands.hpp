#pragma once
// arnav-calib subcommands. Each registers its options on the CLI11 app and returns the
// function that runs it. Exit codes: 0 done, 2 usage or unreadable/invalid input,
// 3 calibration rejected (degenerate data: the message says what to record again).
#include <functional>

#include <CLI/CLI.hpp>

namespace arnav::calib::tool {

using Run = std::function<void()>;

Run add_board_command(CLI::App& app);
Run add_intrinsics_command(CLI::App& app);
Run add_pivot_command(CLI::App& app);
Run add_handeye_command(CLI::App& app);
Run add_register_command(CLI::App& app);
Run add_ar_accuracy_command(CLI::App& app);

}  // namespace arnav::calib::tool
