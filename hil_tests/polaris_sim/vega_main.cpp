// arnav-vega-sim: a simulated NDI Polaris Vega (Ethernet tracker) on TCP (docs/hil.md).
//   arnav-vega-sim [--port N] [--scenario FILE] [--tool NAME=ROM]... [--rate HZ] [--fault AT_S:KIND]...
// prints "READY 127.0.0.1:<port>" once it listens and serves until SIGTERM/SIGINT.
#include <algorithm>
#include <atomic>
#include <csignal>
#include <iostream>

#include <CLI/CLI.hpp>

#include "hil_tests/polaris_sim/vega_server.hpp"
#include "protocol/guarded_main.hpp"

namespace {
std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }
}  // namespace

static int main_body(int argc, char** argv) {
  using namespace arnav::hil;
  CLI::App app{"Simulated NDI Polaris Vega on TCP: Combined API (API revision G.003), polled BX2 and STREAM BX2 "
               "on a CLOCK_MONOTONIC frame clock. Faults (AT_S after the first STREAM): reset, stall S, bad_crc [N], "
               "split [N], skip [N], duplicate [N]. See docs/hil.md."};
  VegaOptions opt;
  std::string scenario_file;
  std::vector<std::string> tool_specs, fault_specs;
  double rate_hz = 0.0;
  app.add_option("--bind", opt.bind_address, "IPv4 address to listen on (default 127.0.0.1)");
  app.add_option("--port", opt.port, "TCP port (default 0: any free port, printed in READY; a real Vega uses 8765)")
      ->check(CLI::Range(0, 65535));
  app.add_option("--scenario", scenario_file, "YAML scenario: tools, motion, frame rate (docs/hil.md)")->check(CLI::ExistingFile);
  app.add_option("--tool", tool_specs, "add a tool NAME=ROM_PATH with a default motion (repeatable)");
  app.add_option("--rate", rate_hz, "frame rate in Hz (1-400; default 60 or the scenario's)")->check(CLI::Range(1.0, kMaxFrameRateHz));
  app.add_option("--fault", fault_specs, "timed fault 'AT_S:KIND [ARG]' (repeatable)");
  app.add_option("--api-revision", opt.api_revision, "APIREV answer (default G.003.005; below G.003: no BX2, no STREAM)");
  app.add_flag("--no-stream", [&](std::int64_t) { opt.stream_supported = false; }, "answer STREAM with ERROR01 (polled BX2 only)");
  app.add_option("--ustream-race", opt.ustream_race_packets, "stream packets sent after USTREAM before its OKAY (default 2)")
      ->check(CLI::Range(0, 1000));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  std::vector<VegaFault> faults;
  std::unique_ptr<PolarisModel> model;
  try {
    Scenario scenario = scenario_file.empty() ? Scenario{} : load_scenario(scenario_file);
    for (const auto& spec : tool_specs) add_tool_spec(scenario, spec);
    if (rate_hz > 0) scenario.frame_rate_hz = rate_hz;
    if (!scenario.faults.empty())
      throw ScenarioError("the scenario's faults: section is for the serial simulator; give Vega faults with --fault");
    for (const auto& spec : fault_specs) faults.push_back(parse_vega_fault(spec));
    model = std::make_unique<PolarisModel>(std::move(scenario));
  } catch (const ScenarioError& e) {
    std::cerr << "arnav-vega-sim: " << e.what() << "\n";
    return 2;
  }
  std::signal(SIGTERM, on_signal);
  std::signal(SIGINT, on_signal);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    VegaServer server(*model, opt, faults);
    const int port = server.start();
    std::cout << "READY " << opt.bind_address << ":" << port << std::endl;
    server.run(g_stop);
    const auto& s = server.stats();
    std::cerr << "arnav-vega-sim: stopped: " << s.connections << " connections, " << s.commands << " commands, "
              << s.stream_packets << " stream packets, " << s.frames_skipped << " frame numbers skipped, " << s.resets
              << " connection resets, " << s.faults << " faults\n";
    // The simulator's own share of device time -> published: frame due -> handed to the kernel.
    std::vector<float> late = server.send_lateness_us();
    if (!late.empty()) {
      std::sort(late.begin(), late.end());
      auto at = [&](double q) { return late[std::min(late.size() - 1, static_cast<std::size_t>(q * static_cast<double>(late.size())))]; };
      std::cerr << "arnav-vega-sim: send lateness (frame due -> sent) over " << late.size() << " frames: p50 " << at(0.5)
                << " us, p99 " << at(0.99) << " us, p99.9 " << at(0.999) << " us, max " << late.back() << " us\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "arnav-vega-sim: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-vega-sim", [&] { return main_body(argc, argv); });
}
