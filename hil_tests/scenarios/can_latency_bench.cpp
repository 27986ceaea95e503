// arnav-can-latency: CAN frame received -> input_event_t published, on the CAN bench
// (arnav-can-sim + the real arnav-appliance, LCM in a private network namespace). The
// simulator presses and releases an input --presses times; every event carries the
// appliance's own timestamps, so the figures are the appliance's, not the bench's:
//   frame_to_publish: publish - receive (the appliance read the frame; publish is stamped
//                     just before lcm publish), for events a frame decided (debounce 0);
//   frame_to_subscriber: a subscriber in another process got it - receive (includes the
//                     LCM publish call, UDP multicast on loopback and the subscriber's wake-up);
//   health_window_*: the appliance's own receive -> publish returned percentiles, one per
//                     health period (device_health_t), as the NDI path reports them;
//   deadline_to_publish: publish - end of debounce, for presses decided by the debounce timer;
//   kernel_to_read (SocketCAN): receive - kernel receive timestamp (socket delivery).
// Prints JSON; exit 1 when an event is missing or duplicated. Needs root.
#include <algorithm>
#include <iostream>
#include <thread>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "hil_tests/scenarios/can_run.hpp"
#include "protocol/clock.hpp"
#include "protocol/guarded_main.hpp"

namespace {

nlohmann::json summary(std::vector<double> v) {
  if (v.empty()) return {{"n", 0}};
  std::sort(v.begin(), v.end());
  auto pct = [&](double p) { return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5))]; };
  return {{"n", v.size()}, {"p50_us", pct(0.5)}, {"p90_us", pct(0.9)}, {"p99_us", pct(0.99)}, {"max_us", v.back()}};
}

}  // namespace

static int main_body(int argc, char** argv) {
  using namespace arnav::hil;
  CLI::App app{"CAN frame -> input_event_t latency on the CAN bench (JSON on stdout). Needs root."};
  int presses = 10000, period_ms = 6;
  std::string path = "socketcan";
  CanRunOptions o;
  app.add_option("--presses", presses, "press/release cycles (default 10000)")->check(CLI::Range(1, 1000000));
  app.add_option("--period-ms", period_ms, "cycle period, ms (default 6)")->check(CLI::Range(2, 10000));
  app.add_option("--path", path, "socketcan (shim) or slcan (pty, libserialport)")->check(CLI::IsMember({"socketcan", "slcan"}));
  app.add_option("--debounce-ms", o.pedal_debounce_ms, "debounce of the pressed input (default 0: every event decided by a frame)")
      ->check(CLI::Range(0, 1000));
  app.add_option("--priority", o.appliance_priority, "appliance can.priority (SCHED_FIFO; default 50 as shipped, 0: normal)")->check(CLI::Range(0, 99));
  app.add_option("--sim-priority", o.sim_priority, "simulator SCHED_FIFO priority (default 0)")->check(CLI::Range(0, 99));
  o.pedal_debounce_ms = 0;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  o.path = path == "slcan" ? CanPath::Slcan : CanPath::SocketCan;
  if (o.pedal_debounce_ms * 2 >= period_ms) {
    std::cerr << "arnav-can-latency: --debounce-ms must be under half of --period-ms\n";
    return 2;
  }
  CanRun run;
  try {
    if (const std::string why = run.start(o); !why.empty()) {
      std::cerr << "arnav-can-latency: cannot run the bench here: " << why << "\n";
      return 1;
    }
    if (!run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_ALIVE") >= 2; }, 30.0)) {
      std::cerr << "arnav-can-latency: devices never seen\n" << run.logs();
      return 1;
    }
    const std::string answer = run.inject("train pedal_cut " + std::to_string(presses) + " " + std::to_string(period_ms));
    if (answer != "OK") {
      std::cerr << "arnav-can-latency: simulator: " << answer << "\n";
      return 1;
    }
    const double expected_s = presses * period_ms / 1000.0;
    const bool complete = run.lcm().wait_for(
        [&](const CanCapture& c) { return c.count_inputs("pedal_cut", arnav::input_event_t::STATE_RELEASED) >= static_cast<std::size_t>(presses); },
        expected_s * 2 + 30.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    std::vector<double> frame_to_publish, deadline_to_publish, kernel_to_read, frame_to_subscriber;
    std::size_t pressed = 0, released = 0, forced = 0;
    const auto inputs = run.lcm().inputs();
    const auto arrivals = run.lcm().input_arrivals();
    for (std::size_t k = 0; k < inputs.size(); ++k) {
      const auto& e = inputs[k];
      if (e.input_name != "pedal_cut") continue;
      (e.state == arnav::input_event_t::STATE_PRESSED ? pressed : released) += 1;
      if (e.cause == arnav::input_event_t::CAUSE_FRAME) {
        frame_to_publish.push_back(static_cast<double>(e.publish_time_mono_us - e.receive_time_mono_us));
        frame_to_subscriber.push_back(static_cast<double>(arrivals[k] - e.receive_time_mono_us));
        if (e.device_time_wall_us > 0) kernel_to_read.push_back(static_cast<double>(e.receive_time_wall_us - e.device_time_wall_us));
      } else if (e.cause == arnav::input_event_t::CAUSE_DEBOUNCE) {
        deadline_to_publish.push_back(static_cast<double>(e.publish_time_mono_us - e.decided_time_mono_us));
      } else {
        ++forced;
      }
    }
    const auto health = run.lcm().health();
    std::vector<double> window_p50, window_p99, window_max;
    for (const auto& h : health)
      if (h.latency_max_us > 0) {
        window_p50.push_back(h.latency_p50_us);
        window_p99.push_back(h.latency_p99_us);
        window_max.push_back(h.latency_max_us);
      }
    nlohmann::json out = {
        {"path", path},
        {"presses_sent", presses},
        {"period_ms", period_ms},
        {"debounce_ms", o.pedal_debounce_ms},
        {"priority", o.appliance_priority},
        {"pressed_events", pressed},
        {"released_events", released},
        {"forced_releases", forced},
        {"frame_to_publish", summary(frame_to_publish)},
        {"deadline_to_publish", summary(deadline_to_publish)},
        {"kernel_to_read", summary(kernel_to_read)},
        {"frame_to_subscriber", summary(frame_to_subscriber)},
        {"health_window_p50_us", summary(window_p50)},
        {"health_window_p99_us", summary(window_p99)},
        {"health_window_max_us", summary(window_max)},
        {"appliance_health_last", health.empty() ? nlohmann::json() : nlohmann::json{{"frames_total", health.back().frames_total}, {"detail", health.back().detail}}},
    };
    std::cout << out.dump(2) << std::endl;
    const bool exact = complete && pressed == static_cast<std::size_t>(presses) && released == static_cast<std::size_t>(presses) && forced == 0;
    if (!exact) std::cerr << "arnav-can-latency: expected " << presses << " presses and releases\n" << run.logs();
    run.stop_appliance();
    return exact ? 0 : 1;
  } catch (const std::exception& e) {
    std::cerr << "arnav-can-latency: " << e.what() << "\n";
    return 1;
  }
}

int main(int argc, char** argv) {
  return arnav::guarded_main("arnav-can-latency", [&] { return main_body(argc, argv); });
}
