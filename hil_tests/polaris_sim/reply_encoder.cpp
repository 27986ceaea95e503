#include "hil_tests/polaris_sim/reply_encoder.hpp"

#include <cstdio>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/reply.hpp"

namespace arnav::hil {

std::string hex_field(std::uint32_t value, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%0*X", digits, value);
  return std::string(buf).substr(0, static_cast<std::size_t>(digits));
}

Bytes text_reply(std::string_view text) {
  const std::string s = ndi::encode_reply(text);
  return Bytes(s.begin(), s.end());
}

Bytes okay_reply() { return text_reply("OKAY"); }
Bytes error_reply(std::uint8_t code) { return text_reply("ERROR" + hex_field(code, 2)); }
Bytes reset_reply() { return text_reply("RESET"); }

Bytes tracking_reply(const ndi::TrackingReply& frame, bool binary) {
  if (!binary) return text_reply(ndi::format_tx_body(frame));
  Bytes out;
  ndi::encode_bx(frame, out);
  return out;
}

}  // namespace arnav::hil
