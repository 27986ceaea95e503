// libFuzzer target: the slcan reader in three chunkings, and the decoder fed with every
// frame it yields. Invariants: chunking never changes the frames read; a frame read back
// re-encodes to a line the reader accepts as the same frame.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "appliance/can/input_decoder.hpp"
#include "appliance/can/slcan.hpp"

using namespace arnav::can;

namespace {

struct NullSink : DecoderSink {
  void on_input(const InputChange&) override {}
  void on_node(const NodeChange&) override {}
  void on_bus(const BusChange&) override {}
};

const char* kConfig = R"(can:
  interface: slcan:/dev/ttyS0
  nodes: [{name: p, heartbeat: 1, timeout_ms: 5}, {name: q, periodic_id: 0x100, timeout_ms: 5}]
  inputs:
    - {name: a, node: p, id: 0x100, bit: 0, debounce_ms: 0}
    - {name: b, node: q, id: 0x100, byte: 1, size: 2, range: [10, 20], debounce_ms: 1}
)";

std::vector<CanFrame> run(const std::uint8_t* data, std::size_t size, std::size_t chunk, bool stamps) {
  slcan::Reader reader;
  reader.set_timestamps(stamps);
  std::vector<CanFrame> frames;
  slcan::Message m;
  for (std::size_t pos = 0; pos < size; pos += chunk) {
    reader.feed(std::span(data + pos, std::min(chunk, size - pos)));
    while (reader.next(m))
      if (m.kind == slcan::Message::Kind::Frame) frames.push_back(m.frame);
  }
  return frames;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto whole = run(data, size, size == 0 ? 1 : size, false);
  if (run(data, size, 1, false) != whole) __builtin_trap();
  if (run(data, size, 5, false) != whole) __builtin_trap();
  (void)run(data, size, 3, true);
  static InputDecoder decoder(*parse_can_config(kConfig, "fuzz"));
  NullSink sink;
  std::int64_t t = 0;
  for (const auto& f : whole) {
    const std::string line = slcan::encode_frame(f);
    slcan::Reader again;
    again.feed(std::string_view(line));
    slcan::Message m;
    if (!again.next(m) || m.kind != slcan::Message::Kind::Frame || !(m.frame == f)) __builtin_trap();
    decoder.on_frame(f, t += 1000, sink);
    decoder.tick(t, sink);
  }
  return 0;
}
