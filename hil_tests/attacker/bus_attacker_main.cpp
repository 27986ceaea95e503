// arnav-bus-attacker: forges, replays, tampers with and moves messages on the bench's bus
// without the key, at a given rate until a count or a duration, and writes what it sent as
// JSON (by the verdict a receiver with the key must reach). Bench only (docs/hil.md); run it
// inside the bench's private network namespace.
#include <CLI/CLI.hpp>

#include <chrono>
#include <csignal>
#include <fstream>
#include <iostream>
#include <thread>

#include "hil_tests/attacker/bus_attacker.hpp"
#include "protocol/guarded_main.hpp"

namespace {
volatile std::sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }
}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App cli{"arnav-bus-attacker: attacks on the sealed bus, for the HIL bench (docs/hil.md)"};
  std::string url = "udpm://239.255.76.67:7667?ttl=0", report;
  arnav::hil::AttackPlan plan;
  double rate_hz = 1000, duration_s = 60;
  std::uint64_t count = 10000;
  double wait_capture_s = 10;
  cli.add_option("--lcm-url", url, "the bench's bus (ttl=0, inside the bench namespace)");
  cli.add_option("--tool", plan.tool, "forge poses of this tool (and of 'scalpel')");
  cli.add_option("--camera", plan.camera, "forge frames of this camera");
  cli.add_option("--earlier-log", plan.earlier_log, "an earlier session's lcm-logger log (its sealed messages are sent once each: stale)");
  cli.add_option("--frame-bytes", plan.frame_bytes, "payload of a forged frame")->check(CLI::Range(16, 4000000));
  cli.add_option("--rate", rate_hz, "injections per second")->check(CLI::Range(1.0, 100000.0));
  cli.add_option("--count", count, "stop after this many injections");
  cli.add_option("--duration", duration_s, "stop after this many seconds")->check(CLI::Range(0.1, 36000.0));
  cli.add_option("--wait-capture", wait_capture_s, "wait up to this long for sealed traffic to capture before starting")->check(CLI::Range(0.0, 600.0));
  cli.add_option("--report", report, "write the counts here (JSON)")->required();
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e) == 0 ? 0 : 2;
  }
  if (url.find("ttl=0") == std::string::npos) {
    std::cerr << "arnav-bus-attacker: --lcm-url must keep ttl=0 (bench only, never beyond this host)\n";
    return 2;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  lcm::LCM bus(url);
  if (!bus.good()) {
    std::cerr << "arnav-bus-attacker: cannot open LCM at '" << url << "'\n";
    return 2;
  }
  arnav::hil::BusAttacker attacker(bus, plan);
  bus.subscribe(".*", &arnav::hil::BusAttacker::on_message, &attacker);
  std::cout << "arnav-bus-attacker: ready" << std::endl;
  const auto t0 = std::chrono::steady_clock::now();
  while (!g_stop && attacker.captured() < 8 && std::chrono::steady_clock::now() - t0 < std::chrono::duration<double>(wait_capture_s))
    bus.handleTimeout(20);
  const auto start = std::chrono::steady_clock::now();
  const auto period = std::chrono::duration<double>(1.0 / rate_hz);
  auto next = start;
  while (!g_stop && attacker.counts().total() < count && std::chrono::steady_clock::now() - start < std::chrono::duration<double>(duration_s)) {
    while (bus.handleTimeout(0) > 0) {
    }
    const auto now = std::chrono::steady_clock::now();
    if (now < next) {
      std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(next - now, std::chrono::milliseconds(1)));
      continue;
    }
    attacker.inject();
    next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
  }
  nlohmann::json j = attacker.counts().json();
  j["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::ofstream out(report);
  out << j.dump(2) << "\n";
  std::cout << "arnav-bus-attacker: sent " << j.dump() << std::endl;
  return out ? 0 : 2;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-bus-attacker", [&] { return main_body(argc, argv); });
}
