// Input decoder: debounce (exactly one event per press, bounce filtered), active levels,
// analogue hysteresis, liveness (heartbeat and periodic, loss releases held inputs, return
// reported, stale levels forgotten), bus-off, error frames, unrelated and short frames.
#include <gtest/gtest.h>

#include "appliance/can/input_decoder.hpp"
#include "appliance/can/test/test_config.hpp"

namespace arnav::can {
namespace {

constexpr std::int64_t ms = 1000;

struct Recorder : DecoderSink {
  std::vector<InputChange> inputs;
  std::vector<NodeChange> nodes;
  std::vector<BusChange> bus;
  void on_input(const InputChange& c) override { inputs.push_back(c); }
  void on_node(const NodeChange& c) override { nodes.push_back(c); }
  void on_bus(const BusChange& c) override { bus.push_back(c); }
  std::size_t count(std::size_t input, bool pressed) const {
    std::size_t n = 0;
    for (const auto& c : inputs) n += c.input == input && c.pressed == pressed;
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
CanFrame heartbeat(std::uint8_t state = 0x05) { return frame(0x710, {state}); }
CanFrame pedal(std::uint8_t bits) { return frame(0x190, {bits}); }
constexpr std::uint8_t kAcceptReleased = 0x02;  // pedal_accept is active low

class Decoder : public ::testing::Test {
 protected:
  Decoder() : d(*parse_can_config(test::kPedalConfig, "t.yaml")) {}
  // Feeds a frame at t and runs every deadline up to t first (as the appliance does).
  void at(std::int64_t t, const CanFrame& f) {
    advance(t);
    d.on_frame(f, t, rec);
  }
  void advance(std::int64_t t) {
    while (d.next_deadline_us() <= t) {
      const std::int64_t dl = d.next_deadline_us();
      d.tick(dl, rec);
      if (d.next_deadline_us() == dl) break;
    }
    d.tick(t, rec);
  }
  InputDecoder d;
  Recorder rec;
};

TEST_F(Decoder, PressCountsAfterDebounceReleaseAtOnce) {
  at(0, heartbeat());
  at(1 * ms, pedal(kAcceptReleased | 1));
  EXPECT_EQ(rec.count(0, true), 0u);
  EXPECT_EQ(d.next_deadline_us(), 21 * ms);
  advance(21 * ms);
  ASSERT_EQ(rec.count(0, true), 1u);
  EXPECT_EQ(rec.inputs.back().frame_us, 1 * ms);
  EXPECT_EQ(rec.inputs.back().decided_us, 21 * ms);
  EXPECT_EQ(rec.inputs.back().cause, InputChange::Cause::Debounce);
  EXPECT_TRUE(d.inputs()[0].pressed);
  at(100 * ms, pedal(kAcceptReleased));
  ASSERT_EQ(rec.count(0, false), 1u);
  EXPECT_EQ(rec.inputs.back().decided_us, 100 * ms);
  EXPECT_EQ(rec.inputs.back().cause, InputChange::Cause::Frame);
}

TEST_F(Decoder, ContactBounceGivesExactlyOnePressAndOneRelease) {
  at(0, heartbeat());
  std::int64_t t = 10 * ms;
  for (int press = 0; press < 50; ++press) {
    for (int b = 0; b < 6; ++b) at(t += 2 * ms, pedal(kAcceptReleased | (b % 2 == 0 ? 1 : 0)));  // 12 ms of chatter
    at(t += 1 * ms, pedal(kAcceptReleased | 1));
    at(t += 40 * ms, pedal(kAcceptReleased | 1));
    for (int b = 0; b < 5; ++b) at(t += 2 * ms, pedal(kAcceptReleased | (b % 2 == 0 ? 0 : 1)));
    at(t += 1 * ms, pedal(kAcceptReleased));
    at(t += 40 * ms, heartbeat());
  }
  EXPECT_EQ(rec.count(0, true), 50u);
  // Release bounce with release_debounce_ms 0: the first release counts, the chatter after
  // it never holds 20 ms, so it never presses again.
  EXPECT_EQ(rec.count(0, false), 50u);
  EXPECT_EQ(rec.count(1, true), 0u);
}

TEST_F(Decoder, ActiveLowAndImmediateWithZeroDebounce) {
  at(0, heartbeat());
  at(1 * ms, pedal(0x00));  // bit 1 low = accept pressed
  ASSERT_EQ(rec.count(1, true), 1u);
  EXPECT_EQ(rec.inputs.back().decided_us, 1 * ms);
  at(2 * ms, pedal(0x02));
  EXPECT_EQ(rec.count(1, false), 1u);
}

TEST_F(Decoder, AnalogueHysteresis) {
  at(0, heartbeat());
  auto analog = [](int v) { return frame(0x191, {0, static_cast<std::uint8_t>(v & 0xFF), static_cast<std::uint8_t>(v >> 8)}); };
  at(1 * ms, analog(500));
  at(2 * ms, analog(799));
  EXPECT_EQ(rec.count(2, true), 0u);
  at(3 * ms, analog(800));
  ASSERT_EQ(rec.count(2, true), 1u);
  EXPECT_EQ(rec.inputs.back().value, 800.0);
  at(4 * ms, analog(300));  // between: still pressed
  at(5 * ms, analog(900));
  EXPECT_EQ(rec.count(2, false), 0u);
  at(6 * ms, analog(200));
  EXPECT_EQ(rec.count(2, false), 1u);
  EXPECT_EQ(rec.count(2, true), 1u);
}

TEST_F(Decoder, FramesFromAnUnprovenDeviceChangeNothing) {
  at(0, pedal(kAcceptReleased | 1));
  advance(100 * ms);
  EXPECT_TRUE(rec.inputs.empty());
  EXPECT_EQ(d.nodes()[0].state, NodeState::Unknown);
  at(110 * ms, heartbeat());
  ASSERT_EQ(rec.nodes.size(), 1u);
  EXPECT_EQ(rec.nodes[0].state, NodeState::Alive);
  at(120 * ms, pedal(kAcceptReleased | 1));
  advance(140 * ms);
  EXPECT_EQ(rec.count(0, true), 1u);
}

TEST_F(Decoder, HeartbeatLossReleasesHeldInputsWithinTheTimeout) {
  at(0, heartbeat());
  at(1 * ms, pedal(kAcceptReleased | 1));
  advance(30 * ms);
  ASSERT_TRUE(d.inputs()[0].pressed);
  at(100 * ms, heartbeat());
  // Heartbeats stop; the pedal stays held (nothing says otherwise).
  EXPECT_EQ(d.next_deadline_us(), 400 * ms + 1);
  advance(400 * ms);
  EXPECT_TRUE(d.inputs()[0].pressed);
  advance(400 * ms + 1);
  EXPECT_FALSE(d.inputs()[0].pressed);
  ASSERT_EQ(rec.count(0, false), 1u);
  EXPECT_EQ(rec.inputs.back().cause, InputChange::Cause::NodeLost);
  EXPECT_EQ(rec.nodes.back().state, NodeState::Lost);
  EXPECT_EQ(rec.nodes.back().silent_us, 300 * ms + 1);
  EXPECT_EQ(d.nodes()[0].losses, 1);
  // Input frames while lost press nothing; the return is reported; the level seen before
  // the loss is forgotten: only a fresh frame presses again.
  at(500 * ms, pedal(kAcceptReleased | 1));
  advance(600 * ms);
  EXPECT_FALSE(d.inputs()[0].pressed);
  at(700 * ms, heartbeat());
  EXPECT_EQ(rec.nodes.back().state, NodeState::Alive);
  EXPECT_EQ(rec.nodes.back().previous, NodeState::Lost);
  advance(800 * ms);
  EXPECT_FALSE(d.inputs()[0].pressed);
  at(810 * ms, pedal(kAcceptReleased | 1));
  advance(840 * ms);
  EXPECT_TRUE(d.inputs()[0].pressed);
  EXPECT_EQ(rec.count(0, true), 2u);
}

TEST_F(Decoder, PeriodicDeviceLossOnlyReleasesItsOwnInputs) {
  at(0, heartbeat());
  at(1 * ms, frame(0x185, {0x80}));
  at(1 * ms, pedal(kAcceptReleased | 1));
  advance(25 * ms);
  at(50 * ms, heartbeat());
  ASSERT_TRUE(d.inputs()[3].pressed);
  ASSERT_TRUE(d.inputs()[0].pressed);
  advance(102 * ms);  // grasper silent 101 ms > 100
  EXPECT_FALSE(d.inputs()[3].pressed);
  EXPECT_TRUE(d.inputs()[0].pressed);
  EXPECT_EQ(d.nodes()[1].state, NodeState::Lost);
  // A periodic device is back with its first frame, and that frame counts.
  at(200 * ms, frame(0x185, {0x80}));
  EXPECT_EQ(d.nodes()[1].state, NodeState::Alive);
  advance(211 * ms);
  EXPECT_TRUE(d.inputs()[3].pressed);
}

TEST_F(Decoder, CanopenStateChangesAreReported) {
  at(0, heartbeat(0x00));
  at(10 * ms, heartbeat(0x7F));
  at(20 * ms, heartbeat(0x05));
  at(30 * ms, heartbeat(0x05));
  ASSERT_EQ(rec.nodes.size(), 3u);
  EXPECT_EQ(rec.nodes[2].canopen_state, 0x05);
  EXPECT_EQ(canopen_state_name(0x05), "operational");
  EXPECT_EQ(canopen_state_name(0x7F), "pre-operational");
}

TEST_F(Decoder, BusOffReleasesEverythingAndRecovers) {
  at(0, heartbeat());
  at(1 * ms, pedal(kAcceptReleased | 1));
  advance(30 * ms);
  ASSERT_TRUE(d.inputs()[0].pressed);
  CanFrame off;
  off.error = true;
  off.id = err::kBusOff;
  off.dlc = 8;
  at(40 * ms, off);
  EXPECT_EQ(d.bus_state(), BusState::BusOff);
  EXPECT_FALSE(d.inputs()[0].pressed);
  EXPECT_EQ(rec.inputs.back().cause, InputChange::Cause::BusOff);
  EXPECT_EQ(d.counters().bus_off, 1);
  CanFrame restarted = off;
  restarted.id = err::kRestarted;
  at(50 * ms, restarted);
  EXPECT_EQ(d.bus_state(), BusState::Active);
  EXPECT_EQ(d.counters().restarts, 1);
  ASSERT_EQ(rec.bus.size(), 2u);
  // A second bus-off, recovered by frames flowing again (no restart report).
  at(60 * ms, off);
  at(70 * ms, heartbeat());
  EXPECT_EQ(d.bus_state(), BusState::Active);
  EXPECT_EQ(d.counters().bus_off, 2);
  EXPECT_EQ(d.counters().restarts, 2);
}

TEST_F(Decoder, ControllerErrorStates) {
  CanFrame e;
  e.error = true;
  e.id = err::kCrtl;
  e.dlc = 8;
  e.data[1] = err::kCrtlRxWarning;
  at(0, e);
  EXPECT_EQ(d.bus_state(), BusState::Warning);
  e.data[1] = err::kCrtlTxPassive;
  at(1, e);
  EXPECT_EQ(d.bus_state(), BusState::Passive);
  e.data[1] = err::kCrtlActive;
  at(2, e);
  EXPECT_EQ(d.bus_state(), BusState::Active);
  e.id = err::kProt | err::kBusError;
  at(3, e);
  EXPECT_EQ(d.bus_state(), BusState::Active);
  EXPECT_EQ(d.counters().error_frames, 4);
}

TEST_F(Decoder, UnrelatedShortRemoteAndExtendedFramesAreIgnored) {
  at(0, heartbeat());
  for (int i = 0; i < 1000; ++i) at(1 + i, frame(0x300 + static_cast<std::uint32_t>(i % 100), {0xFF}));
  CanFrame ext = pedal(0xFF);
  ext.extended = true;
  at(2000, ext);
  CanFrame rtr = pedal(0);
  rtr.remote = true;
  at(2001, rtr);
  at(2002, frame(0x191, {0, 0xFF}));  // analogue needs 3 bytes
  advance(100 * ms);
  EXPECT_TRUE(rec.inputs.empty());
  EXPECT_EQ(d.counters().unrelated, 1002);  // 1000 others, the extended and the remote frame
  EXPECT_EQ(d.counters().short_frames, 1);
}

TEST_F(Decoder, LinkLostReleasesAndLosesEveryDevice) {
  at(0, heartbeat());
  at(0, frame(0x185, {0x80}));
  at(1 * ms, pedal(kAcceptReleased | 1));
  advance(30 * ms);
  d.link_lost(31 * ms, rec);
  EXPECT_FALSE(d.inputs()[0].pressed);
  EXPECT_EQ(d.nodes()[0].state, NodeState::Lost);
  EXPECT_EQ(d.nodes()[1].state, NodeState::Lost);
}

}  // namespace
}  // namespace arnav::can
