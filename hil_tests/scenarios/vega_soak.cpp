// arnav-hil-vega-soak: the simulated Vega at --rate Hz with --tools tools through the real
// arnav-appliance over TCP, in the bench's private network namespace, for --seconds.
// Prints JSON (also written to OUT_DIR/vega_soak.json) and one line:
//   vega soak: F frames, L lost, p99 latency X us
// (device timestamp -> published). Exit 0 when no frame was lost or repeated, every pose
// was valid and the appliance stopped cleanly. Needs root (namespaces).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "hil_tests/scenarios/vega_run.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

static int main_body(int argc, char** argv) {
  using namespace arnav::hil;
  CLI::App app{"Vega soak on the HIL bench (arnav-vega-sim over TCP -> arnav-appliance -> LCM). Needs root."};
  double seconds = 600.0, warmup_s = 2.0;
  std::string out_dir;
  VegaRunOptions o;
  app.add_option("--seconds", seconds, "measured time after warm-up (default 600)")->check(CLI::Range(1.0, 86400.0));
  app.add_option("--out", out_dir, "folder for vega_soak.json and the logs")->required();
  app.add_option("--rate", o.rate_hz, "device frame rate, Hz (default 400)")->check(CLI::Range(1.0, 400.0));
  app.add_option("--tools", o.tools, "tools, 1-6 (default 6)")->check(CLI::Range(1, 6));
  app.add_option("--warmup", warmup_s, "seconds of tracking before counting starts (default 2)")->check(CLI::Range(0.0, 60.0));
  app.add_option("--fault", o.sim_faults, "arnav-vega-sim fault AT_S:KIND (repeatable; a soak has none)");
  app.add_option("--sim-priority", o.sim_priority, "SCHED_FIFO priority of arnav-vega-sim, standing in for the device's own clock (default 0: normal)")
      ->check(CLI::Range(0, 99));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  std::filesystem::create_directories(out_dir);
  VegaRun run;
  if (const std::string why = run.start(o); !why.empty()) {
    std::cerr << "arnav-hil-vega-soak: cannot run the bench here: " << why << "\n";
    return 1;
  }
  const std::int64_t t0 = arnav::monotonic_us();
  while (run.monitor().snapshot().frames < 10) {
    if (arnav::monotonic_us() - t0 > 60'000'000) {
      std::cerr << "arnav-hil-vega-soak: no poses within 60 s\n" << run.logs();
      return 1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  std::this_thread::sleep_for(std::chrono::duration<double>(warmup_s));
  run.monitor().reset();
  const std::int64_t start_us = arnav::monotonic_us();
  const std::int64_t frames_at_start = run.monitor().snapshot().appliance_frames_total;
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const double measured_s = static_cast<double>(arnav::monotonic_us() - start_us) * 1e-6;
  VegaStats s = run.monitor().snapshot();
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));  // one more health message (1 Hz)
  const VegaStats health = run.monitor().snapshot();
  s.appliance_dropped_frames = health.appliance_dropped_frames;
  s.appliance_frames_total = health.appliance_frames_total;
  s.appliance_reconnects = health.appliance_reconnects;
  const std::int64_t lost = s.appliance_dropped_frames;  // since bring-up, warm-up included
  const int appliance_rc = run.stop_appliance();
  run.stop_simulator();

  nlohmann::json j;
  j["rate_hz"] = o.rate_hz;
  j["tools"] = o.tools;
  j["sim_priority"] = o.sim_priority;
  j["measured_s"] = measured_s;
  j["frames_published"] = s.frames;  // new frame numbers of tool1 seen by the subscriber in the window
  j["expected_frames"] = static_cast<std::uint64_t>(measured_s * o.rate_hz);
  j["appliance_frames_total"] = s.appliance_frames_total;  // since bring-up
  j["appliance_frames_in_window"] = s.appliance_frames_total - frames_at_start;  // health is 1 Hz: about +1.2 s of frames
  j["lost"] = lost;
  j["lcm_gaps"] = s.lcm_gaps;
  j["repeated"] = s.repeated;
  j["poses"] = s.poses;
  j["not_valid"] = s.not_valid;
  j["bad_device_time"] = s.bad_device_time;
  j["max_gap_ms"] = s.max_gap_s * 1e3;
  j["appliance_dropped_frames"] = s.appliance_dropped_frames;
  j["appliance_reconnects"] = s.appliance_reconnects;
  j["appliance_exit_code"] = appliance_rc;
  auto lat = [](const std::vector<float>& v) {
    return nlohmann::json{{"p50", percentile(v, 50)}, {"p99", percentile(v, 99)}, {"p99_9", percentile(v, 99.9)},
                          {"max", percentile(v, 100)}, {"count", v.size()}};
  };
  j["device_time_to_publish_us"] = lat(s.publish_latency_us);
  j["device_time_to_subscriber_us"] = lat(s.arrival_latency_us);
  std::ofstream(out_dir + "/vega_soak.json") << j.dump(2) << "\n";
  std::filesystem::copy_file(run.dir() + "/appliance.log", out_dir + "/appliance.log", std::filesystem::copy_options::overwrite_existing);
  std::filesystem::copy_file(run.dir() + "/sim.log", out_dir + "/sim.log", std::filesystem::copy_options::overwrite_existing);
  std::cout << j.dump(2) << "\n";
  std::printf("vega soak: %lld frames, %lld lost, p99 latency %.0f us\n", static_cast<long long>(s.appliance_frames_total),
              static_cast<long long>(lost), percentile(s.publish_latency_us, 99));
  const bool ok = s.frames > 0 && lost == 0 && s.repeated == 0 && s.not_valid == 0 && s.bad_device_time == 0 && appliance_rc == 0;
  return ok ? 0 : 1;
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-hil-vega-soak", [&] { return main_body(argc, argv); });
}
