// arnav-hil-latency: appliance latency on the HIL bench, as the appliance itself measures
// it (last byte of a BX/TX reply read -> LCM publish returned) and publishes it in
// device_health_t once a second. Runs the bench (simulated Polaris, real arnav-appliance
// on the libserialport path, LCM in a private network namespace) for --seconds and
// prints JSON: per-period percentiles and their medians over the run. Needs root.
#include <algorithm>
#include <chrono>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {
double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}
}  // namespace

static int main_body(int argc, char** argv) {
  CLI::App app{"Appliance latency on the HIL bench (JSON on stdout). Needs root: private mount and network namespaces."};
  double seconds = 30.0;
  arnav::hil::HilRunOptions o;
  int tools = 2;
  app.add_option("--seconds", seconds, "measurement time after tracking starts (default 30)")->check(CLI::Range(3.0, 3600.0));
  app.add_option("--rate", o.rate_hz, "device frame rate and polling rate, Hz (default 60)")->check(CLI::Range(1.0, 400.0));
  app.add_option("--tools", tools, "number of tools, 1-6 (default 2)")->check(CLI::Range(1, 6));
  app.add_option("--reply-mode", o.reply_mode, "bx or tx (default bx)")->check(CLI::IsMember({"bx", "tx"}));
  app.add_option("--cpu-latency-us", o.cpu_latency_us, "appliance realtime.cpu_latency_us (default 0; -1: no request)")
      ->check(CLI::Range(-1, 100000));
  app.add_option("--priority", o.priority, "appliance realtime.priority, SCHED_FIFO 1-99, 0: normal scheduling (default 50, as shipped)")
      ->check(CLI::Range(0, 99));
  app.add_option("--sim-priority", o.sim_priority, "simulator SCHED_FIFO priority (default 0: normal scheduling)")
      ->check(CLI::Range(0, 99));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  static const char* roms[] = {"8700340.rom", "8700339.rom", "8700248.rom", "8700302.rom", "8700449.rom", "8700340.rom"};
  o.tools.clear();
  for (int i = 0; i < tools; ++i) o.tools.push_back({"tool" + std::to_string(i + 1), roms[i]});

  arnav::hil::HilRun run;
  try {
    const std::int64_t t0 = arnav::monotonic_us();
    if (const std::string why = run.start(o); !why.empty()) {
      std::cerr << "arnav-hil-latency: cannot run the bench here: " << why << "\n";
      return 1;
    }
    if (!run.wait_all_valid(10, t0, 90.0)) {
      std::cerr << "arnav-hil-latency: no tracking within 90 s\n" << run.logs();
      return 1;
    }
    const std::int64_t t_start = arnav::monotonic_us();
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
    const std::int64_t t_end = arnav::monotonic_us();
    nlohmann::json periods = nlohmann::json::array();
    std::vector<double> p50, p99, mx, rate;
    std::int64_t frames0 = -1, frames1 = -1, dropped0 = 0, dropped1 = 0;
    for (const auto& h : run.lcm().health()) {
      // Whole periods inside the window, while tracking.
      if (h.arrival_us < t_start + 1'100'000 || h.arrival_us > t_end || h.msg.link_state != arnav::device_health_t::LINK_TRACKING) continue;
      if (frames0 < 0) {
        frames0 = h.msg.frames_total;
        dropped0 = h.msg.dropped_frames;
      }
      frames1 = h.msg.frames_total;
      dropped1 = h.msg.dropped_frames;
      p50.push_back(h.msg.latency_p50_us);
      p99.push_back(h.msg.latency_p99_us);
      mx.push_back(h.msg.latency_max_us);
      rate.push_back(h.msg.frame_rate_hz);
      periods.push_back({{"p50_us", h.msg.latency_p50_us}, {"p99_us", h.msg.latency_p99_us}, {"max_us", h.msg.latency_max_us},
                         {"frame_rate_hz", h.msg.frame_rate_hz}});
    }
    const int stop_rc = run.stop_appliance();
    run.stop_simulator();
    nlohmann::json j{{"bench", "appliance_latency"},
                     {"reply_mode", o.reply_mode},
                     {"rate_hz", o.rate_hz},
                     {"cpu_latency_us", o.cpu_latency_us},
                     {"priority", o.priority},
                     {"sim_priority", o.sim_priority},
                     {"tools", tools},
                     {"seconds", seconds},
                     {"periods", periods.size()},
                     {"median_p50_us", median(p50)},
                     {"median_p99_us", median(p99)},
                     {"worst_p99_us", p99.empty() ? 0.0 : *std::max_element(p99.begin(), p99.end())},
                     {"worst_max_us", mx.empty() ? 0.0 : *std::max_element(mx.begin(), mx.end())},
                     {"median_frame_rate_hz", median(rate)},
                     {"frames", frames1 - frames0},
                     {"dropped_frames", dropped1 - dropped0},
                     {"appliance_exit_code", stop_rc},
                     {"per_period", periods}};
    std::cout << j.dump(2) << std::endl;
    return periods.empty() ? 1 : 0;
  } catch (const std::exception& e) {
    std::cerr << "arnav-hil-latency: " << e.what() << "\n" << run.logs();
    return 1;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-hil-latency", [&] { return main_body(argc, argv); });
}
