// CanService over an in-process LCM (memq://) with a queue transport: what the appliance
// publishes for presses, releases, device loss and return, bus-off, a lost link, a kernel
// without AF_CAN, and health.
#include <gtest/gtest.h>

#include <lcm/lcm-cpp.hpp>

#include "appliance/can/can_runtime.hpp"
#include "appliance/can/test/fake_adapter.hpp"
#include "appliance/can/test/test_config.hpp"
#include "protocol/channels.hpp"

namespace arnav::can {
namespace {

struct Bus {
  seal::SealedLcm lcm{"memq://", seal::BusSecurity::off()};
  std::vector<input_event_t> inputs;
  std::vector<appliance_event_t> events;
  std::vector<device_health_t> health;
  std::vector<input_event_t> states;
  Bus() {
    lcm.subscribe(std::string(channels::kInputState), &Bus::on_state, this);
    lcm.subscribe(std::string(channels::kInput), &Bus::on_input, this);
    lcm.subscribe(std::string(channels::kEvents), &Bus::on_event, this);
    lcm.subscribe(channels::health("can"), &Bus::on_health, this);
  }
  void on_input(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m) { inputs.push_back(*m); }
  void on_state(const lcm::ReceiveBuffer*, const std::string&, const input_event_t* m) { states.push_back(*m); }
  void on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m) { events.push_back(*m); }
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) { health.push_back(*m); }
  void drain() {
    while (lcm.handleTimeout(0) > 0) {
    }
  }
  std::size_t count(const std::string& code) const {
    std::size_t n = 0;
    for (const auto& e : events) n += e.code == code;
    return n;
  }
};

CanFrame frame(std::uint32_t id, std::vector<std::uint8_t> bytes) {
  CanFrame f;
  f.id = id;
  f.dlc = static_cast<std::uint8_t>(bytes.size());
  for (std::size_t i = 0; i < bytes.size(); ++i) f.data[i] = bytes[i];
  return f;
}

class Service : public ::testing::Test {
 protected:
  Service() {
    auto cfg = *parse_can_config(test::kPedalConfig, "t.yaml");
    service = std::make_unique<CanService>(cfg, bus.lcm, [this]() -> std::unique_ptr<CanTransport> {
      ++opens;
      if (refuse) throw CanUnavailable(refuse_kind, "vcan0: refused by the test");
      return std::make_unique<test::QueueTransport>(q);
    }, 20.0);
  }
  void push(const CanFrame& f) {
    std::lock_guard lock(q->m);
    q->frames.push_back(f);
  }
  void run_for(double seconds) {
    const std::int64_t end = monotonic_us() + static_cast<std::int64_t>(seconds * 1e6);
    while (monotonic_us() < end) service->step(std::chrono::milliseconds(5));
    bus.drain();
  }
  Bus bus;
  std::shared_ptr<test::QueueState> q = std::make_shared<test::QueueState>();
  std::unique_ptr<CanService> service;
  int opens = 0;
  bool refuse = false;
  CanUnavailable::Kind refuse_kind = CanUnavailable::Kind::NoAfCan;
};

TEST_F(Service, OnePressOneEventWithTimesAndLatency) {
  push(frame(0x710, {0x05}));
  push(frame(0x190, {0x03}));  // cut pressed (debounce 20 ms), accept released (active low)
  run_for(0.1);
  ASSERT_EQ(bus.inputs.size(), 1u);
  const input_event_t& e = bus.inputs[0];
  EXPECT_EQ(e.input_name, "pedal_cut");
  EXPECT_EQ(e.state, +input_event_t::STATE_PRESSED);
  EXPECT_EQ(e.cause, +input_event_t::CAUSE_DEBOUNCE);
  EXPECT_EQ(e.device, "pedal");
  EXPECT_EQ(e.source_interface, "vcan0");
  EXPECT_EQ(e.sequence, 1);
  EXPECT_GE(e.decided_time_mono_us - e.receive_time_mono_us, 20000);
  EXPECT_GE(e.publish_time_mono_us, e.decided_time_mono_us);
  EXPECT_LT(e.publish_time_mono_us - e.decided_time_mono_us, 20000) << "published late after the debounce deadline";
  EXPECT_EQ(bus.count("CAN_OPEN"), 1u);
  EXPECT_EQ(bus.count("CAN_DEVICE_ALIVE"), 1u);
  push(frame(0x190, {0x02}));
  run_for(0.05);
  ASSERT_EQ(bus.inputs.size(), 2u);
  EXPECT_EQ(bus.inputs[1].state, +input_event_t::STATE_RELEASED);
  EXPECT_EQ(bus.inputs[1].cause, +input_event_t::CAUSE_FRAME);
  EXPECT_EQ(bus.inputs[1].decided_time_mono_us, bus.inputs[1].receive_time_mono_us);
  EXPECT_GT(bus.inputs[1].device_time_wall_us, 0);
  EXPECT_EQ(bus.inputs[1].sequence, 2);
  ASSERT_FALSE(bus.health.empty());
  const device_health_t& h = bus.health.back();
  EXPECT_EQ(h.device, "can");
  EXPECT_EQ(h.link_state, +device_health_t::LINK_TRACKING);
  EXPECT_EQ(h.frames_total, 3);
  EXPECT_NE(h.detail.find("pedal=alive(operational)"), std::string::npos) << h.detail;
  // Snapshots: one per input and health period, the current state, the last change's number.
  run_for(0.12);
  ASSERT_GE(bus.states.size(), 4u);
  const input_event_t& last_cut = [&]() -> const input_event_t& {
    for (auto it = bus.states.rbegin(); it != bus.states.rend(); ++it)
      if (it->input_name == "pedal_cut") return *it;
    return bus.states.front();
  }();
  EXPECT_EQ(last_cut.input_name, "pedal_cut");
  EXPECT_EQ(last_cut.cause, +input_event_t::CAUSE_STATE);
  EXPECT_EQ(last_cut.state, +input_event_t::STATE_RELEASED);
  EXPECT_EQ(last_cut.sequence, 2);
}

TEST_F(Service, DeviceLossReleasesAndIsReportedThenReturns) {
  push(frame(0x710, {0x05}));
  push(frame(0x190, {0x03}));
  run_for(0.1);
  ASSERT_EQ(bus.inputs.size(), 1u);
  run_for(0.35);  // heartbeat timeout 300 ms
  ASSERT_EQ(bus.inputs.size(), 2u);
  EXPECT_EQ(bus.inputs[1].state, +input_event_t::STATE_RELEASED);
  EXPECT_EQ(bus.inputs[1].cause, +input_event_t::CAUSE_DEVICE_LOST);
  EXPECT_EQ(bus.count("CAN_DEVICE_LOST"), 1u);
  EXPECT_EQ(bus.count("CAN_INPUT_FORCED_RELEASE"), 1u);
  push(frame(0x710, {0x05}));
  run_for(0.05);
  EXPECT_EQ(bus.count("CAN_DEVICE_BACK"), 1u);
  EXPECT_NE(bus.health.back().detail.find("pedal=alive"), std::string::npos);
  EXPECT_EQ(bus.health.back().timeouts, 1);
}

TEST_F(Service, BusOffReleasesAndRecovers) {
  push(frame(0x710, {0x05}));
  push(frame(0x190, {0x03}));
  run_for(0.1);
  CanFrame off;
  off.error = true;
  off.id = err::kBusOff;
  off.dlc = 8;
  push(off);
  run_for(0.1);
  EXPECT_EQ(bus.count("CAN_BUS_OFF"), 1u);
  ASSERT_EQ(bus.inputs.size(), 2u);
  EXPECT_EQ(bus.inputs[1].cause, +input_event_t::CAUSE_BUS_OFF);
  EXPECT_EQ(bus.health.back().link_state, +device_health_t::LINK_RECOVERING);
  off.id = err::kRestarted;
  push(off);
  run_for(0.1);
  EXPECT_EQ(bus.count("CAN_BUS_RECOVERED"), 1u);
  EXPECT_EQ(bus.health.back().link_state, +device_health_t::LINK_TRACKING);
  EXPECT_EQ(bus.health.back().resets, 1);
}

TEST_F(Service, LinkLostReleasesAndReopens) {
  push(frame(0x710, {0x05}));
  push(frame(0x190, {0x03}));
  run_for(0.1);
  {
    std::lock_guard lock(q->m);
    q->lost = true;
  }
  run_for(0.05);
  EXPECT_EQ(bus.count("CAN_LINK_LOST"), 1u);
  ASSERT_EQ(bus.inputs.size(), 2u);
  EXPECT_EQ(bus.inputs[1].cause, +input_event_t::CAUSE_LINK_LOST);
  {
    std::lock_guard lock(q->m);
    q->lost = false;
  }
  run_for(0.4);
  EXPECT_EQ(opens, 2);
  EXPECT_EQ(bus.health.back().reconnects, 1);
}

TEST_F(Service, NoAfCanIsSaidOnceAndHealthKeepsComing) {
  refuse = true;
  run_for(1.5);
  EXPECT_EQ(opens, 1);
  EXPECT_EQ(bus.count("CAN_UNAVAILABLE"), 1u);
  EXPECT_GE(bus.health.size(), 10u);
  EXPECT_EQ(bus.health.back().link_state, +device_health_t::LINK_DOWN);
  EXPECT_NE(bus.health.back().detail.find("unavailable"), std::string::npos);
}

TEST_F(Service, MissingInterfaceIsRetriedAndReportedOnce) {
  refuse = true;
  refuse_kind = CanUnavailable::Kind::NoInterface;
  run_for(2.2);
  EXPECT_GE(opens, 3);
  EXPECT_EQ(bus.count("CAN_OPEN_FAILED"), 1u);
  refuse = false;
  run_for(1.1);
  EXPECT_EQ(bus.count("CAN_OPEN"), 1u);
}

TEST_F(Service, ShutdownReleasesPressedInputs) {
  push(frame(0x710, {0x05}));
  push(frame(0x190, {0x03}));
  run_for(0.1);
  service->shutdown();
  bus.drain();
  ASSERT_EQ(bus.inputs.size(), 2u);
  EXPECT_EQ(bus.inputs[1].state, +input_event_t::STATE_RELEASED);
  EXPECT_EQ(bus.inputs[1].cause, +input_event_t::CAUSE_LINK_LOST);
}

}  // namespace
}  // namespace arnav::can
