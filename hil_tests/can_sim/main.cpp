// arnav-can-sim: simulated CAN devices for the HIL bench (docs/can.md). Prints
// "READY <bus socket | pty slave>" once the bus exists and serves until SIGTERM/SIGINT.
//   arnav-can-sim --config APPLIANCE.yaml --socketcan DIR [--interface vcan0] ...
//   arnav-can-sim --config APPLIANCE.yaml --pty-link PATH [--bind-over /dev/ttyS0] ...
//   arnav-can-sim inject --control SOCKET "press pedal_cut"
// Usage and configuration errors exit 2 naming the file or option.
#include <CLI/CLI.hpp>


#include <csignal>
#include <iostream>

#include "hil_tests/bench/control_client.hpp"
#include "hil_tests/can_sim/can_sim.hpp"
#include "protocol/guarded_main.hpp"

namespace {

volatile bool g_stop = false;
void on_signal(int) { g_stop = true; }

}  // namespace

static int main_body(int argc, char** argv) {
  using namespace arnav;
  CLI::App app{"arnav-can-sim: simulated CAN pedal and instrument buttons (slcan on a pty, or a SocketCAN bus for the can_shim)"};
  app.footer("Commands (--do AT_S:COMMAND, scenario steps, inject):\n" + hil::commands_help());
  hil::CanSimOptions o;
  std::string config, scenario;
  std::vector<std::string> steps;
  app.add_option("--config", config, "appliance configuration whose can: section names the devices and inputs");
  app.add_option("--socketcan", o.socketcan_dir, "serve a SocketCAN bus at DIR/IFACE.sock (for libarnav_hil_can_shim.so)");
  app.add_option("--interface", o.interface, "interface name of the bus (default vcan0)");
  app.add_option("--pty-link", o.pty_link, "slcan adapter on a pty; symlink to its slave");
  app.add_option("--bind-over", o.bind_over, "also bind-mount the pty slave over this node (root, private mount namespace)");
  app.add_option("--scenario", scenario, "YAML scenario: steps: [{at_s, do}]");
  std::int64_t epoch_mono_us = -1;
  app.add_option("--epoch-mono-us", epoch_mono_us,
                 "steps at this CLOCK_MONOTONIC time (us) + at_s instead of the start (the bench's world clock, docs/hil.md)")
      ->check(CLI::Range(std::int64_t{0}, std::int64_t{9'000'000'000'000'000}));
  app.add_option("--do", steps, "AT_S:COMMAND, a step given on the command line");
  app.add_option("--control", o.control_socket, "unix datagram socket accepting commands");
  app.add_option("--log", o.log_path, "candump log of every frame on the simulated bus");
  app.add_option("--heartbeat-ms", o.heartbeat_period_ms, "heartbeat period (default 100)")->check(CLI::Range(1, 60000));
  app.add_option("--periodic-ms", o.periodic_period_ms, "period of periodic devices' frames (default 20)")->check(CLI::Range(1, 60000));
  app.add_option("--seed", o.seed, "random seed (garbage, dropped characters, flood ids)");
  auto* inject = app.add_subcommand("inject", "send one command to a running simulator");
  std::string inject_socket, inject_command;
  inject->add_option("--control", inject_socket, "the simulator's control socket")->required();
  inject->add_option("command", inject_command, "e.g. \"press pedal_cut\"")->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }
  if (*inject) return arnav::hil::send_control_command("arnav-can-sim", inject_socket, inject_command);
  if (config.empty()) {
    std::cerr << "arnav-can-sim: --config APPLIANCE.yaml is required (its can: section names the devices)\n";
    return 2;
  }
  if (o.socketcan_dir.empty() == o.pty_link.empty()) {
    std::cerr << "arnav-can-sim: give exactly one of --socketcan DIR and --pty-link PATH\n";
    return 2;
  }
  try {
    auto cfg = can::load_can_config(config);
    if (!cfg) {
      std::cerr << "arnav-can-sim: " << config << ": no can: section\n";
      return 2;
    }
    hil::CanSim sim(o, std::move(*cfg));
    std::vector<hil::ScenarioStep> plan;
    if (!scenario.empty()) plan = hil::load_can_scenario(scenario);
    for (const auto& s : steps) {
      const auto colon = s.find(':');
      hil::ScenarioStep st;
      try {
        st.at_s = std::stod(s.substr(0, colon));
      } catch (...) {
        std::cerr << "arnav-can-sim: --do '" << s << "': expected AT_S:COMMAND\n";
        return 2;
      }
      if (colon == std::string::npos) {
        std::cerr << "arnav-can-sim: --do '" << s << "': expected AT_S:COMMAND\n";
        return 2;
      }
      st.command = s.substr(colon + 1);
      plan.push_back(st);
    }
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    std::signal(SIGPIPE, SIG_IGN);
    const std::string where = sim.start();
    // Check every step now: a typo must fail before the run, not half way through it.
    for (const auto& st : plan) {
      const std::string check = sim.command(st.command, true);
      if (check != "OK") {
        std::cerr << "arnav-can-sim: step at " << st.at_s << " s '" << st.command << "': " << check << "\n";
        return 2;
      }
      if (epoch_mono_us >= 0)
        sim.schedule_from_epoch(epoch_mono_us, st.at_s, st.command);
      else
        sim.schedule(st.at_s, st.command);
    }
    std::cout << "READY " << where << std::endl;
    sim.run(g_stop);
    std::cerr << "arnav-can-sim: stopped, " << sim.frames_sent() << " frames sent\n";
    return 0;
  } catch (const can::CanConfigError& e) {
    std::cerr << "arnav-can-sim: configuration error: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "arnav-can-sim: " << e.what() << "\n";
    return 2;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-can-sim", [&] { return main_body(argc, argv); });
}
