// arnav-host (minimal for now): subscribes to the appliance's poses, health and events
// over LCM, tracks freshness per tool and prints a status table. --summary-json writes
// what it saw at exit (used by scripts/demo and the HIL bench).
#include <atomic>
#include <chrono>
#include <csignal>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "host/app/status_report.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop.store(true); }

struct Handler {
  arnav::host::ToolFreshnessTracker& tracker;
  bool print_events;
  void pose(const lcm::ReceiveBuffer*, const std::string&, const arnav::tool_pose_t* msg) { tracker.on_pose(*msg, arnav::monotonic_us()); }
  void health(const lcm::ReceiveBuffer*, const std::string&, const arnav::device_health_t* msg) {
    tracker.on_health(*msg, arnav::monotonic_us());
  }
  void event(const lcm::ReceiveBuffer*, const std::string&, const arnav::appliance_event_t* msg) {
    tracker.on_event(*msg);
    if (print_events) std::cout << "event " << msg->source << " " << msg->code << ": " << msg->text << std::endl;
  }
};

nlohmann::json summary(const arnav::host::ToolFreshnessTracker& tracker, double run_s) {
  nlohmann::json j;
  j["run_s"] = run_s;
  j["stale_after_ms"] = static_cast<double>(tracker.stale_after_us()) * 1e-3;
  for (const auto& [name, t] : tracker.tools()) {
    j["tools"][name] = {{"messages", t.messages},
                        {"valid", t.valid},
                        {"mean_valid_rate_hz", run_s > 0 ? static_cast<double>(t.valid) / run_s : 0.0},
                        {"duplicate_frames", t.duplicate_frames},
                        {"frame_gaps", t.frame_gaps},
                        {"counter_restarts", t.counter_restarts},
                        {"sequence_gaps", t.sequence_gaps},
                        {"stale_episodes", t.stale_episodes},
                        {"max_valid_gap_ms", static_cast<double>(t.max_valid_gap_us) * 1e-3},
                        {"stale_at_exit", t.stale}};
  }
  for (const auto& [device, h] : tracker.health()) {
    j["health"][device] = {{"link_state", h.link_state},   {"frame_rate_hz", h.frame_rate_hz}, {"frames_total", h.frames_total},
                           {"crc_errors", h.crc_errors},   {"timeouts", h.timeouts},           {"resyncs", h.resyncs},
                           {"garbage_bytes", h.garbage_bytes}, {"error_replies", h.error_replies}, {"resets", h.resets},
                           {"reconnects", h.reconnects},   {"dropped_frames", h.dropped_frames},
                           {"latency_p50_us", h.latency_p50_us}, {"latency_p99_us", h.latency_p99_us},
                           {"latency_max_us", h.latency_max_us}, {"detail", h.detail}};
  }
  j["events"] = nlohmann::json::array();
  for (const auto& e : tracker.events())
    j["events"].push_back({{"source", e.source}, {"severity", e.severity}, {"code", e.code}, {"text", e.text}, {"time_mono_us", e.time_mono_us}});
  return j;
}

}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"arnav-host (minimal): subscribes to poses, health and events, tracks per-tool freshness, prints a status table"};
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  double stale_after_ms = 250.0, print_period_s = 1.0, duration_s = 0.0;
  std::string summary_path;
  bool quiet = false, events = false, print_summary = false;
  app.add_option("--lcm-url", lcm_url, "LCM URL (default: the appliance's, TTL 0)");
  app.add_option("--stale-after-ms", stale_after_ms, "a tool is stale when its last valid pose is older (default 250)")
      ->check(CLI::Range(1.0, 600000.0));
  app.add_option("--print-period", print_period_s, "seconds between status tables (default 1)")->check(CLI::Range(0.05, 3600.0));
  app.add_option("--duration", duration_s, "exit after this many seconds (default: run until SIGINT/SIGTERM)")->check(CLI::Range(0.0, 1e7));
  app.add_option("--summary-json", summary_path, "write a JSON summary (per tool, per device, events) at exit");
  app.add_flag("--quiet", quiet, "no periodic table (final table only)");
  app.add_flag("--events", events, "print appliance events as they arrive");
  app.add_flag("--summary", print_summary, "print a summary at exit (rates, outages, device counters, latency, events)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  lcm::LCM bus(lcm_url);
  if (!bus.good()) {
    std::cerr << "arnav-host: cannot open LCM at '" << lcm_url
              << "': check the URL (udpm needs a multicast route, e.g. 224.0.0.0/4 on the interface)\n";
    return 2;
  }
  arnav::host::ToolFreshnessTracker tracker(static_cast<std::int64_t>(stale_after_ms * 1000.0));
  Handler handler{tracker, events};
  bus.subscribe(std::string(arnav::channels::kPoseRegex), &Handler::pose, &handler);
  bus.subscribe(std::string(arnav::channels::kHealthRegex), &Handler::health, &handler);
  bus.subscribe(std::string(arnav::channels::kEvents), &Handler::event, &handler);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  const std::int64_t t0 = arnav::monotonic_us();
  std::int64_t next_print = t0 + static_cast<std::int64_t>(print_period_s * 1e6);
  while (!g_stop.load()) {
    if (bus.handleTimeout(20) < 0) {
      std::cerr << "arnav-host: LCM receive failed\n";
      return 1;
    }
    const std::int64_t now = arnav::monotonic_us();
    tracker.update(now);
    if (!quiet && now >= next_print) {
      std::cout << format_status_table(tracker, now) << std::endl;
      next_print += static_cast<std::int64_t>(print_period_s * 1e6);
    }
    if (duration_s > 0 && now - t0 >= static_cast<std::int64_t>(duration_s * 1e6)) break;
  }
  const std::int64_t now = arnav::monotonic_us();
  tracker.update(now);
  const double run_s = static_cast<double>(now - t0) * 1e-6;
  std::cout << format_status_table(tracker, now) << std::flush;
  if (print_summary) std::cout << format_summary(tracker, run_s) << std::flush;
  if (!summary_path.empty()) {
    std::ofstream out(summary_path);
    out << summary(tracker, run_s).dump(2) << "\n";
    if (!out) {
      std::cerr << "arnav-host: cannot write " << summary_path << "\n";
      return 1;
    }
  }
  return 0;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-host", [&] { return main_body(argc, argv); });
}
