// End to end on the CAN bench: the real arnav-appliance with a `can:` configuration
// against arnav-can-sim, over both production paths: the SocketCAN code (through the
// test-only can_shim, as these machines have no AF_CAN) and slcan on a pty through
// libserialport. Input events are read over LCM udpm in a private network namespace.
// Each press gives exactly one event; bounce is filtered; device loss releases a held
// input within its timeout; bus-off is recovered; garbage, dropped characters, error
// frames and floods crash nothing and press nothing. Timing bounds are generous (a loaded
// 2-core machine) and printed.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>

#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/scenarios/can_run.hpp"
#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/clock.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

constexpr std::int8_t kPressed = input_event_t::STATE_PRESSED;
constexpr std::int8_t kReleased = input_event_t::STATE_RELEASED;

std::string path_name(CanPath p) { return p == CanPath::SocketCan ? "SocketCan" : "Slcan"; }

class CanE2e : public ::testing::TestWithParam<CanPath> {
 protected:
  void start(CanRunOptions o = {}) {
    o.path = GetParam();
    const std::string why = run.start(o);
    ARNAV_BENCH_OR_SKIP(why);
    ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_ALIVE") >= 2; }, 30.0))
        << "devices never seen\n" << run.lcm().event_log() << run.logs();
  }
  bool wait_inputs(const std::string& name, std::int8_t state, std::size_t n, double timeout_s = 10.0) {
    return run.lcm().wait_for([&](const CanCapture& c) { return c.count_inputs(name, state) >= n; }, timeout_s);
  }
  void inject(const std::string& cmd) { ASSERT_EQ(run.inject(cmd), "OK") << cmd; }
  CanRun run;
};

TEST_P(CanE2e, EachPressGivesExactlyOneEvent) {
  start();
  inject("train pedal_cut 30 120");
  ASSERT_TRUE(wait_inputs("pedal_cut", kReleased, 30, 30.0)) << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), 30u);
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kReleased), 30u);
  EXPECT_EQ(run.lcm().count_inputs("pedal_accept", kPressed), 0u) << "a neighbouring bit must not move";
  // Alternating, sequence numbers without gaps, times ordered, the right source.
  const auto inputs = run.lcm().inputs();
  std::int8_t expect = kPressed;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const auto& e = inputs[i];
    EXPECT_EQ(e.sequence, static_cast<std::int64_t>(i + 1));
    EXPECT_EQ(e.source_interface, run.bus_name());
    EXPECT_EQ(e.device, "pedal");
    EXPECT_EQ(e.state, expect) << i;
    expect = expect == kPressed ? kReleased : kPressed;
    EXPECT_LE(e.receive_time_mono_us, e.decided_time_mono_us);
    EXPECT_LE(e.decided_time_mono_us, e.publish_time_mono_us);
    if (e.state == kPressed) {
      EXPECT_GE(e.decided_time_mono_us - e.receive_time_mono_us, 20000) << "debounce not held";
    }
    if (GetParam() == CanPath::SocketCan && e.cause == +input_event_t::CAUSE_FRAME) {
      EXPECT_GT(e.device_time_wall_us, 0);
    }
  }
  // Health: frames counted, latency reported, devices named.
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return !c.health().empty(); }, 5.0));
  const auto h = run.lcm().health().back();
  EXPECT_EQ(h.link_state, +device_health_t::LINK_TRACKING) << h.detail;
  EXPECT_GT(h.frames_total, 60);
  EXPECT_NE(h.detail.find("pedal=alive"), std::string::npos) << h.detail;
  // The state snapshots agree: released, numbered after the last change.
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) {
    for (const auto& st : c.states())
      if (st.input_name == "pedal_cut" && st.sequence == 60) return true;
    return false;
  }, 5.0));
  for (const auto& st : run.lcm().states())
    if (st.input_name == "pedal_cut" && st.sequence == 60) {
      EXPECT_EQ(st.state, kReleased);
      EXPECT_EQ(st.cause, +input_event_t::CAUSE_STATE);
    }
}

TEST_P(CanE2e, ContactBounceIsFiltered) {
  // Debounce works on the appliance's receive clock: a delivery stall longer than the
  // debounce time in the middle of the chatter would split it (slcan frames carry no
  // timestamps). 12 ms of chatter against 60 ms of debounce leaves a loaded bench room.
  CanRunOptions o;
  o.pedal_debounce_ms = 60;
  start(o);
  inject("bounce pedal_cut 6 2");  // 13 edges 2 ms apart, settles pressed
  ASSERT_TRUE(wait_inputs("pedal_cut", kPressed, 1)) << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  inject("bounce pedal_cut 6 2");  // settles released
  ASSERT_TRUE(wait_inputs("pedal_cut", kReleased, 1)) << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), 1u) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kReleased), 1u) << run.lcm().event_log();
}

TEST_P(CanE2e, DeviceLossReleasesAHeldInputWithinItsTimeout) {
  start();
  inject("press pedal_cut");
  ASSERT_TRUE(wait_inputs("pedal_cut", kPressed, 1)) << run.lcm().event_log() << run.logs();
  const std::int64_t off = monotonic_us();
  inject("node pedal off");
  ASSERT_TRUE(wait_inputs("pedal_cut", kReleased, 1, 5.0)) << run.lcm().event_log() << run.logs();
  const auto inputs = run.lcm().inputs();
  const auto& rel = inputs.back();
  EXPECT_EQ(rel.cause, +input_event_t::CAUSE_DEVICE_LOST);
  const double after_ms = static_cast<double>(rel.publish_time_mono_us - off) / 1000.0;
  std::printf("[ can ] %s: held pedal released %.1f ms after the device went silent (timeout 300 ms, heartbeat 100 ms)\n",
              path_name(GetParam()).c_str(), after_ms);
  // Silent from `off`, its last heartbeat at most one period (100 ms) before: lost by 300 ms
  // after that heartbeat; 250 ms of slack for a loaded machine.
  EXPECT_LE(after_ms, 300.0 + 250.0);
  EXPECT_GE(run.lcm().count_events("CAN_DEVICE_LOST"), 1u);
  inject("node pedal on");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_BACK") >= 1; }, 5.0)) << run.lcm().event_log();
  // The level held before the loss is forgotten: only a new press counts.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), 1u);
  inject("release pedal_cut");
  inject("press pedal_cut");
  ASSERT_TRUE(wait_inputs("pedal_cut", kPressed, 2)) << run.lcm().event_log();
}

TEST_P(CanE2e, BusOffReleasesAndIsRecovered) {
  start();
  inject("press pedal_cut");
  ASSERT_TRUE(wait_inputs("pedal_cut", kPressed, 1)) << run.lcm().event_log() << run.logs();
  inject("bus_off 0.5");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_BUS_OFF") >= 1; }, 5.0)) << run.lcm().event_log() << run.logs();
  ASSERT_TRUE(wait_inputs("pedal_cut", kReleased, 1, 5.0));
  const auto first_release = run.lcm().inputs().back();
  EXPECT_TRUE(first_release.cause == +input_event_t::CAUSE_BUS_OFF || first_release.cause == +input_event_t::CAUSE_DEVICE_LOST)
      << static_cast<int>(first_release.cause);
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_BUS_RECOVERED") >= 1; }, 10.0))
      << run.lcm().event_log() << run.logs();
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) {
    const auto h = c.health();
    return !h.empty() && h.back().link_state == +device_health_t::LINK_TRACKING && h.back().resets >= 1;
  }, 10.0)) << run.lcm().event_log();
  // Working again: a fresh press after the devices are back.
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_BACK") >= 1 || c.count_events("CAN_DEVICE_LOST") == 0; }, 5.0));
  inject("release pedal_cut");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  inject("press pedal_cut");
  ASSERT_TRUE(wait_inputs("pedal_cut", kPressed, 2)) << run.lcm().event_log() << run.logs();
}

TEST_P(CanE2e, NothingCrashesOrPressesOnGarbage) {
  start();
  if (GetParam() == CanPath::Slcan) {
    inject("garbage 20000");
    inject("drop_chars 40");
  }
  inject("error_frames 50");
  inject("flood 3000 2");
  for (int i = 0; i < 10; ++i) {
    if (GetParam() == CanPath::Slcan) inject("garbage 500");
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), 0u) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().count_inputs("pedal_accept", kPressed), 0u) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().count_inputs("grasper_close", kPressed), 0u) << run.lcm().event_log();
  // Still working, exactly.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  const std::size_t before = run.lcm().count_inputs("pedal_cut", kPressed);
  inject("train pedal_cut 10 120");
  ASSERT_TRUE(wait_inputs("pedal_cut", kReleased, 10, 20.0)) << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), before + 10);
  const auto h = run.lcm().health().back();
  if (GetParam() == CanPath::Slcan) {
    EXPECT_GT(h.garbage_bytes, 10000) << h.detail;
    EXPECT_GT(h.crc_errors, 0) << "no malformed slcan lines counted";
    EXPECT_EQ(h.detail.find("unrelated frames 0,"), std::string::npos) << "slcan has no filters: the flood reaches the decoder";
  } else {
    EXPECT_GE(h.error_replies, 50) << "error frames not counted";
    // CAN_RAW_FILTER (applied with the kernel's rules by the shim) keeps the flood of
    // unrelated ids away from the appliance entirely.
    EXPECT_NE(h.detail.find("unrelated frames 0,"), std::string::npos) << h.detail;
  }
  EXPECT_GE(run.lcm().count_events("CAN_ERROR_PASSIVE"), 1u) << run.lcm().event_log();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  EXPECT_GE(run.lcm().count_events("CAN_CLOSED"), 1u);
}

TEST_P(CanE2e, AnalogueAndPeriodicDevice) {
  start();
  inject("value pedal_analog 900");
  ASSERT_TRUE(wait_inputs("pedal_analog", kPressed, 1)) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().inputs().back().value, 900.0);
  inject("value pedal_analog 500");  // inside the hysteresis band: still pressed
  inject("value pedal_analog 100");
  ASSERT_TRUE(wait_inputs("pedal_analog", kReleased, 1)) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().count_inputs("pedal_analog", kPressed), 1u);
  inject("press grasper_close");
  ASSERT_TRUE(wait_inputs("grasper_close", kPressed, 1)) << run.lcm().event_log();
  inject("heartbeat grasper off");  // its periodic frame stops: lost after 100 ms
  ASSERT_TRUE(wait_inputs("grasper_close", kReleased, 1, 5.0)) << run.lcm().event_log();
  EXPECT_EQ(run.lcm().inputs().back().cause, +input_event_t::CAUSE_DEVICE_LOST);
}

// The scripted session (hil_tests/can_sim/scenarios/pedal_session.yaml) from start to end.
TEST_P(CanE2e, ScriptedPedalSession) {
  CanRunOptions o;
  o.sim_args = {"--scenario", std::string(ARNAV_CAN_SCENARIO_DIR) + "/pedal_session.yaml"};
  o.pedal_debounce_ms = 60;  // well above the scripted chatter (see ContactBounceIsFiltered)
  start(o);
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_BUS_RECOVERED") >= 1 && c.count_inputs("grasper_close", kReleased) >= 2; }, 30.0))
      << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(800));
  const CanCapture& c = run.lcm();
  EXPECT_EQ(c.count_inputs("pedal_cut", kPressed), 2u) << c.event_log();
  EXPECT_EQ(c.count_inputs("pedal_cut", kReleased), 2u) << c.event_log();
  EXPECT_EQ(c.count_inputs("pedal_accept", kPressed), 1u) << c.event_log();
  EXPECT_EQ(c.count_inputs("pedal_accept", kReleased), 1u) << c.event_log();
  // The grasper's button is still held after the bus-off, and its periodic frame (its
  // liveness) says so: pressed again after the recovery, released at 6 s. The pedal sends
  // on change only: after its return nothing presses pedal_cut again.
  EXPECT_EQ(c.count_inputs("grasper_close", kPressed), 2u) << c.event_log();
  EXPECT_EQ(c.count_inputs("grasper_close", kReleased), 2u) << c.event_log();
  std::size_t lost = 0, bus_off = 0;
  for (const auto& e : c.inputs()) {
    lost += e.cause == +input_event_t::CAUSE_DEVICE_LOST;
    bus_off += e.cause == +input_event_t::CAUSE_BUS_OFF;
  }
  // The vanished pedal's forced release, and the grasper's at the bus-off (over slcan the
  // bus-off is seen at the next status poll, which may come after the grasper's 100 ms
  // timeout: then that release is a device loss too).
  EXPECT_EQ(lost + bus_off, 2u) << c.event_log();
  if (GetParam() == CanPath::SocketCan) {
    EXPECT_EQ(bus_off, 1u) << c.event_log();
  }
  // Every device lost (the pedal, then both during the bus-off) came back.
  EXPECT_GE(c.count_events("CAN_DEVICE_LOST"), 2u) << c.event_log();
  EXPECT_EQ(c.count_events("CAN_DEVICE_BACK"), c.count_events("CAN_DEVICE_LOST")) << c.event_log();
}

INSTANTIATE_TEST_SUITE_P(Paths, CanE2e, ::testing::Values(CanPath::SocketCan, CanPath::Slcan),
                         [](const ::testing::TestParamInfo<CanPath>& p) { return path_name(p.param); });

// Without the shim the production SocketCAN code meets this kernel as it is: no AF_CAN.
// The appliance says so once and keeps running; with real AF_CAN the interface is missing.
TEST(CanE2eNoAfCan, SaidOnceAndTheApplianceKeepsRunning) {
  CanRun run;
  CanRunOptions o;
  o.with_shim = false;
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) {
    return c.count_events("CAN_UNAVAILABLE") + c.count_events("CAN_OPEN_FAILED") >= 1 && c.health().size() >= 5;
  }, 20.0)) << run.lcm().event_log() << run.logs();
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  if (run.lcm().count_events("CAN_UNAVAILABLE") == 0)
    GTEST_SKIP() << "this kernel has AF_CAN (the bench's vcan0 is not a kernel interface)";
  EXPECT_EQ(run.lcm().count_events("CAN_UNAVAILABLE"), 1u) << "said once";
  const auto events = run.lcm().events();
  for (const auto& e : events)
    if (e.code == "CAN_UNAVAILABLE") {
      EXPECT_NE(e.text.find("vcan0"), std::string::npos) << e.text;
      EXPECT_NE(e.text.find("slcan"), std::string::npos) << e.text;
    }
  const auto h = run.lcm().health().back();
  EXPECT_EQ(h.link_state, +device_health_t::LINK_DOWN);
  EXPECT_NE(h.detail.find("unavailable"), std::string::npos) << h.detail;
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
}

// NDI and CAN in one appliance on a kernel without AF_CAN: the CAN path says so once and
// the NDI path tracks as if it were not there.
TEST(CanE2eNoAfCan, NdiKeepsTracking) {
  HilRun run;
  HilRunOptions o;
  o.extra_config = "can:\n  interface: vcan0\n  nodes: [{name: pedal, heartbeat: 0x10, timeout_ms: 300}]\n"
                   "  inputs: [{name: pedal_cut, node: pedal, id: 0x190, bit: 0}]\n";
  const std::int64_t t0 = monotonic_us();
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.wait_all_valid(120, t0, 90.0)) << "no tracking within 90 s\n" << run.lcm().event_log() << run.logs();
  const std::size_t unavailable = run.lcm().events_after("CAN_UNAVAILABLE", t0);
  if (unavailable == 0 && run.lcm().events_after("CAN_OPEN_FAILED", t0) > 0)
    GTEST_SKIP() << "this kernel has AF_CAN (no vcan0 interface here)";
  EXPECT_EQ(unavailable, 1u) << run.lcm().event_log();
  bool can_health = false;
  for (const auto& h : run.lcm().health())
    if (h.msg.device == "can") {
      can_health = true;
      EXPECT_EQ(h.msg.link_state, +device_health_t::LINK_DOWN);
    }
  EXPECT_TRUE(can_health) << "no ARNAV_HEALTH_can";
  const std::int64_t t1 = monotonic_us();
  ASSERT_TRUE(run.wait_all_valid(60, t1, 30.0)) << "NDI stopped tracking";
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  EXPECT_EQ(run.stop_simulator(), 0) << run.logs();  // SIGTERM: it takes its mounts over /dev/ttyS0 down
}

// A candump capture replayed onto the bench bus with arnav-can reaches the appliance, and
// arnav-can decode predicts the same presses offline.
TEST(CanE2eTools, ReplayedCaptureGivesTheRecordedPresses) {
  CanRun run;
  CanRunOptions o;
  o.sim_args = {"--heartbeat-ms", "60000"};  // the capture carries its own heartbeats
  o.path = CanPath::SocketCan;
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  // The appliance must be on the bus before the capture is sent (frames before are lost).
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_OPEN") >= 1; }, 30.0)) << run.logs();
  const std::string log = run.dir() + "/capture.log";
  {
    std::ofstream out(log);
    out << "# pedal: heartbeat every 100 ms, pressed twice\n";
    std::int64_t t = 1700000000000000;
    for (int k = 0; k < 20; ++k) {
      char line[128];
      std::snprintf(line, sizeof line, "(%lld.%06lld) can0 710#05\n", static_cast<long long>(t / 1000000), static_cast<long long>(t % 1000000));
      out << line;
      const char* data = (k == 3 || k == 4 || k == 10 || k == 11) ? "03" : "02";
      std::snprintf(line, sizeof line, "(%lld.%06lld) can0 190#%s\n", static_cast<long long>((t + 50000) / 1000000),
                    static_cast<long long>((t + 50000) % 1000000), data);
      out << line;
      t += 100000;
    }
  }
  ChildProcess decode({can_tool_exe(), "decode", log, "--config", run.appliance_config()}, {}, run.dir() + "/decode.log", true);
  std::size_t offline_presses = 0;
  while (auto line = decode.read_line(10.0))
    if (line->find("INPUT pedal_cut pressed") != std::string::npos) ++offline_presses;
  EXPECT_EQ(decode.wait(10.0).value_or(-1), 0) << decode.log_tail();
  EXPECT_EQ(offline_presses, 2u);
  ChildProcess replay({can_tool_exe(), "replay", log, "vcan0"}, run.shim_env(), run.dir() + "/replay.log");
  EXPECT_EQ(replay.wait(30.0).value_or(-1), 0) << replay.log_tail();
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_inputs("pedal_cut", kReleased) >= 2; }, 10.0))
      << run.lcm().event_log() << run.logs() << "\n--- replay ---\n" << replay.log_tail();
  EXPECT_EQ(run.lcm().count_inputs("pedal_cut", kPressed), 2u);
  // A bad capture line is refused before anything is sent, naming file and line.
  {
    std::ofstream bad(run.dir() + "/bad.log");
    bad << "(1.000000) can0 710#05\n(1.100000) can0 7G0#05\n";
  }
  ChildProcess refused({can_tool_exe(), "replay", run.dir() + "/bad.log", "vcan0"}, run.shim_env(), run.dir() + "/refused.log");
  EXPECT_EQ(refused.wait(10.0).value_or(-1), 2);
  EXPECT_NE(refused.log_tail().find("bad.log:2: bad CAN id"), std::string::npos) << refused.log_tail();
}

}  // namespace
}  // namespace arnav::hil
