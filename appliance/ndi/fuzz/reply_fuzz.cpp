// libFuzzer target: every parser of device bytes. The input is fed to the streaming
// frame reader in both modes and in two chunkings, and every frame it yields goes
// through the parser for its kind; the ASCII parsers also see the raw input as a body.
#include <cstddef>
#include <cstdint>
#include <string_view>
#include <vector>

#include "appliance/ndi/bx.hpp"
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

void run_reader(const std::uint8_t* data, std::size_t size, bool binary, std::size_t chunk) {
  FrameReader reader;
  reader.set_expect_binary(binary);
  Frame f;
  TrackingReply t;
  for (std::size_t pos = 0; pos < size; pos += chunk) {
    reader.feed(std::span(data + pos, std::min(chunk, size - pos)));
    while (reader.next(f)) {
      if (f.kind == Frame::Kind::Binary) {
        const ParseError e = parse_bx(f.bytes, t);
        // A frame the reader passed as CRC-good must never be reported as a CRC failure.
        if (f.crc_ok && e == ParseError::BadCrc) __builtin_trap();
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
  run_reader(data, size, false, size == 0 ? 1 : size);
  TrackingReply t;
  (void)parse_bx(std::span(data, size), t);
  parse_all_ascii(std::string_view(reinterpret_cast<const char*>(data), size));
  return 0;
}
