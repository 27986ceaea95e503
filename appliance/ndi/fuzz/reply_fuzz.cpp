// libFuzzer target: every parser of device bytes. The input is fed to the streaming
// frame reader (every reply kind: ASCII, BX/BX2 binary, extended C8 A5, stream packets
// D4 B5 as an Ethernet tracker sends them) in both modes and in two chunkings, and every
// frame it yields goes through the parsers for its kind; the ASCII parsers also see the
// raw input as a body.
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/frame_reader.hpp"
#include "appliance/ndi/reply.hpp"

using namespace arnav::ndi;

namespace {

void parse_all_ascii(std::string_view body) {
  TrackingReply t;
  (void)parse_tx(body, t);
  std::vector<PhsrEntry> phsr;
  (void)parse_phsr(body, phsr);
  PortHandleInfo info;
  (void)parse_phinf_basic(body, info);
  std::uint8_t handle = 0;
  (void)parse_phrq(body, handle);
  VersionInfo v;
  (void)parse_ver(body, v);
  HandleRecord h;
  (void)parse_transform(body, h);
  (void)decode_command(body);
}

void run_reader(const std::uint8_t* data, std::size_t size, bool binary, std::size_t chunk, bool extended = false) {
  FrameReader reader;
  reader.set_expect_binary(binary);
  reader.set_expect_extended(extended);
  Frame f;
  TrackingReply t;
  for (std::size_t pos = 0; pos < size; pos += chunk) {
    reader.feed(std::span(data + pos, std::min(chunk, size - pos)));
    while (reader.next(f)) {
      // A stream packet's id lies inside the reader's buffer and is bounded.
      if (f.streamed() && f.stream_id.size() > kMaxStreamId) __builtin_trap();
      if (f.kind == Frame::Kind::Binary) {
        const ParseError e = parse_bx(f.bytes, t);
        // A frame the reader passed as CRC-good must never be reported as a CRC failure.
        if (f.crc_ok && e == ParseError::BadCrc) __builtin_trap();
        const ParseError e2 = parse_bx2(f.bytes, t);
        if (f.crc_ok && e2 == ParseError::BadCrc) __builtin_trap();
        // A BX2 frame that parses gives at most kMaxHandles records, each with a frame.
        if (e2 == ParseError::None && (!t.has_frame || t.count > kMaxHandles)) __builtin_trap();
        if (f.crc_ok) (void)parse_bx2(f.bytes, t, true);
      } else if (f.kind == Frame::Kind::Extended) {
        if (f.bytes.size() > kMaxExtendedReply + 6) __builtin_trap();
      } else {
        AsciiReply a;
        if (parse_ascii_reply(f.text(), a) == ParseError::None) parse_all_ascii(a.body);
      }
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  run_reader(data, size, true, size == 0 ? 1 : size);
  run_reader(data, size, true, 7);
  run_reader(data, size, true, 5, true);
  run_reader(data, size, false, size == 0 ? 1 : size);
  TrackingReply t;
  (void)parse_bx(std::span(data, size), t);
  (void)parse_bx2(std::span(data, size), t);
  parse_all_ascii(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
