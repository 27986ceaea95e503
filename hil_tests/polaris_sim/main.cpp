// arnav-polaris-sim: a simulated NDI Polaris on a pseudo-terminal (docs/hil.md).
//   arnav-polaris-sim --pty-link PATH [--scenario FILE] [--tool NAME=ROM]... [options]
// prints "READY <slave path>" once the port exists and serves until SIGTERM/SIGINT.
//   arnav-polaris-sim inject --control SOCKET "cable_pull 2"
// sends a fault command to a running simulator and prints its answer.

#include <atomic>
#include <csignal>
#include <iostream>
#include <optional>

#include <CLI/CLI.hpp>

#include "hil_tests/bench/control_client.hpp"
#include "hil_tests/polaris_sim/device_model.hpp"
#include "hil_tests/polaris_sim/replay_device.hpp"
#include "hil_tests/polaris_sim/simulator.hpp"
#include "protocol/guarded_main.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

}  // namespace

static int main_body(int argc, char** argv) {
  using namespace arnav::hil;
  CLI::App app{"Simulated NDI Polaris (Combined API) on a pseudo-terminal, with scripted tool motion, "
               "ground truth and fault injection. Fault commands: cable_pull S, reset, drop_bytes [N], garble [N], "
               "bad_crc [N], partial, chunked S, garbage [N], missing TOOL S, out_of_volume TOOL S, slow S [N], "
               "no_reply [N], error HEX [N], baud_mismatch [BAUD]. See docs/hil.md."};
  app.require_subcommand(0, 1);
  SimulatorOptions opt;
  std::string scenario_file, replay_file;
  std::vector<std::string> tool_specs, fault_specs;
  double rate_hz = 0.0;
  app.add_option("--pty-link", opt.pty_link, "symlink to create for the pty slave (agreed contract)");
  app.add_option("--scenario", scenario_file, "YAML scenario: tools, motion, frame rate, timed faults")->check(CLI::ExistingFile);
  app.add_option("--tool", tool_specs, "add a tool NAME=ROM_PATH with a default motion (repeatable)");
  app.add_option("--rate", rate_hz, "frame rate in Hz (1-400; default 60 or the scenario's)")->check(CLI::Range(1.0, kMaxFrameRateHz));
  app.add_option("--fault", fault_specs, "timed fault 'AT_S:COMMAND', AT_S after the first TSTART, e.g. '6:cable_pull 2' (repeatable)");
  app.add_option("--replay", replay_file, "act out a recorded session instead of the model (arnav-ndi record transcript or IGSTK log)")
      ->check(CLI::ExistingFile);
  app.add_option("--bind-over", opt.bind_over, "also bind-mount the slave over this tty node (root, private mount namespace; HIL bench)");
  app.add_option("--break-socket", opt.break_socket, "unix datagram socket on which the test interposer reports serial breaks");
  app.add_option("--control", opt.control_socket, "unix datagram socket accepting fault commands");
  app.add_option("--truth", opt.truth_csv, "write ground truth (per frame and handle) to this CSV file");
  app.add_option("--events", opt.events_jsonl, "write faults and link events to this JSON-lines file");
  app.add_option("--trace", opt.trace, "write the session (commands, replies, host baud changes) as an arnav-ndi transcript");
  app.add_option("--reset-delay", opt.reset_delay_s, "seconds from break release to RESET (default 0.3)")->check(CLI::Range(0.0, 10.0));
  app.add_flag("--wire-timing", opt.wire_timing, "pace output at the device baud rate (10 bits a byte)");
  app.add_option("--seed", opt.seed, "seed of the random fault positions");
  std::string sensors;
  std::optional<std::uint64_t> sensor_seed;
  app.add_option("--sensors", sensors, "how tools are measured: 'realistic' (marker noise, fitted pose, dropouts) or 'ideal' "
                                       "(true pose); default: the scenario's measurement block, ideal without one (docs/hil.md)")
      ->check(CLI::IsMember({"ideal", "realistic"}));
  app.add_option("--sensor-seed", sensor_seed, "seed of the marker noise and dropouts (replaces the scenario's)");

  auto* inject = app.add_subcommand("inject", "send a fault command to a running simulator");
  std::string inject_socket, inject_command;
  inject->add_option("--control", inject_socket, "the simulator's control socket")->required();
  inject->add_option("command", inject_command, "fault command, e.g. \"cable_pull 2\"")->required();

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (*inject)
    return arnav::hil::send_control_command("arnav-polaris-sim", inject_socket, inject_command,
                                            ": start it with --control " + inject_socket);
  if (opt.pty_link.empty()) {
    std::cerr << "arnav-polaris-sim: --pty-link PATH is required (see --help)\n";
    return 2;
  }

  std::unique_ptr<PolarisModel> model;
  std::unique_ptr<SimDevice> device;
  std::vector<TimedFault> timeline;
  try {
    if (!replay_file.empty()) {
      if (!scenario_file.empty() || !tool_specs.empty())
        throw ScenarioError("--replay acts out a recording: it cannot be combined with --scenario or --tool");
      device = std::make_unique<ReplayDevice>(load_replay(replay_file));
    } else {
      Scenario scenario = scenario_file.empty() ? Scenario{} : load_scenario(scenario_file);
      for (const auto& spec : tool_specs) add_tool_spec(scenario, spec);
      if (rate_hz > 0) scenario.frame_rate_hz = rate_hz;
      set_sensors(scenario, sensors, sensor_seed);
      std::cerr << "arnav-polaris-sim: measurement " << scenario.measurement.describe() << "\n";
      timeline = scenario.faults;
      model = std::make_unique<PolarisModel>(std::move(scenario));
      device = std::make_unique<ModelDevice>(*model);
    }
    for (const auto& spec : fault_specs) {
      const auto colon = spec.find(':');
      if (colon == std::string::npos) throw ScenarioError("--fault '" + spec + "': expected AT_S:COMMAND, e.g. '6:reset'");
      TimedFault tf;
      try {
        tf.at_s = std::stod(spec.substr(0, colon));
      } catch (const std::exception&) {
        throw ScenarioError("--fault '" + spec + "': AT_S must be a number of seconds");
      }
      tf.fault = parse_fault(spec.substr(colon + 1), "--fault '" + spec + "'");
      timeline.push_back(tf);
    }
    for (const auto& tf : timeline) {
      if ((tf.fault.kind == FaultCommand::Kind::kMissing || tf.fault.kind == FaultCommand::Kind::kOutOfVolume) && model &&
          !model->knows_tool(tf.fault.tool))
        throw ScenarioError("fault '" + tf.fault.text + "' names tool '" + tf.fault.tool + "', which the scenario does not have");
    }
  } catch (const ScenarioError& e) {
    std::cerr << "arnav-polaris-sim: " << e.what() << "\n";
    return 2;
  }

  std::signal(SIGTERM, on_signal);
  std::signal(SIGINT, on_signal);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    Simulator sim(*device, timeline, opt);
    if (model) model->on_truth = [&sim](const TruthRow& row) { sim.record_truth(row); };
    const std::string slave = sim.start();
    std::cout << "READY " << slave << std::endl;
    sim.run(g_stop);
    const auto& s = sim.stats();
    std::cerr << "arnav-polaris-sim: stopped: " << s.commands << " commands, " << s.replies << " replies, " << s.bytes_in
              << " bytes in, " << s.bytes_out << " bytes out, " << s.noise_bytes_in << " noise bytes in, " << s.noise_bytes_out
              << " noise bytes out, " << s.breaks << " breaks, " << s.faults << " faults\n";
  } catch (const std::exception& e) {
    std::cerr << "arnav-polaris-sim: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-polaris-sim", [&] { return main_body(argc, argv); });
}
