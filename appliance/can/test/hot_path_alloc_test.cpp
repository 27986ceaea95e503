// The per-frame path (slcan reader + input decoder) must not allocate once warmed up:
// counted by the test-support operator new (protocol/testing/allocation_counter).
#include <gtest/gtest.h>

#include "protocol/testing/allocation_counter.hpp"


#include "appliance/can/input_decoder.hpp"
#include "appliance/can/slcan.hpp"
#include "appliance/can/test/test_config.hpp"


namespace arnav::can {
namespace {

struct Counter : DecoderSink {
  long inputs = 0, nodes = 0, bus = 0;
  void on_input(const InputChange&) override { ++inputs; }
  void on_node(const NodeChange&) override { ++nodes; }
  void on_bus(const BusChange&) override { ++bus; }
};

TEST(HotPath, SlcanReaderAndDecoderDoNotAllocatePerFrame) {
  InputDecoder decoder(*parse_can_config(test::kPedalConfig, "t.yaml"));
  slcan::Reader reader;
  Counter sink;
  // One second of traffic: heartbeat, grasper frames, pedal presses, bounce, garbage, a lost CR.
  const std::string wire =
      "t710105\rt185100\rt190100\rt190102\rt1913002003\rt1913000100\r\x01\x02zzt185180t185100\rt1901" "03\r";
  slcan::Message m;
  std::int64_t t = 0;
  auto run = [&](int rounds) {
    for (int k = 0; k < rounds; ++k) {
      for (std::size_t pos = 0; pos < wire.size(); pos += 5) {
        reader.feed(std::string_view(wire).substr(pos, 5));
        while (reader.next(m)) {
          t += 3000;
          decoder.tick(t, sink);
          if (m.kind == slcan::Message::Kind::Frame) decoder.on_frame(m.frame, t, sink);
        }
      }
      decoder.tick(t += 30000, sink);
    }
  };
  run(5);  // warm-up: buffers reach their size
  const long before = arnav::testing::allocation_count();
  run(200);
  EXPECT_EQ(arnav::testing::allocation_count() - before, 0);
  EXPECT_GT(sink.inputs, 200);
  EXPECT_GT(decoder.counters().frames, 1000);
}

}  // namespace
}  // namespace arnav::can
