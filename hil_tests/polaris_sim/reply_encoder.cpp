#include "hil_tests/polaris_sim/reply_encoder.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "appliance/ndi/crc16.hpp"

namespace arnav::hil {

std::string hex_field(std::uint32_t value, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%0*X", digits, value);
  return std::string(buf).substr(0, static_cast<std::size_t>(digits));
}

std::string signed_field(double value, double scale, int digits) {
  // Saturate instead of overflowing the field: the device reports values that fit.
  const double limit = std::pow(10.0, digits) - 1.0;
  const double scaled = std::clamp(std::round(value * scale), -limit, limit);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%c%0*lld", scaled < 0 ? '-' : '+', digits,
                static_cast<long long>(std::llabs(static_cast<long long>(scaled))));
  return buf;
}

Bytes text_reply(std::string_view text) {
  std::string s(text);
  s += hex_field(ndi::crc16(text), 4);
  s += '\r';
  return Bytes(s.begin(), s.end());
}

Bytes okay_reply() { return text_reply("OKAY"); }
Bytes error_reply(std::uint8_t code) { return text_reply("ERROR" + hex_field(code, 2)); }
Bytes reset_reply() { return text_reply("RESET"); }

Bytes tx_reply(const std::vector<HandleReport>& handles, std::uint16_t system_status) {
  std::string s = hex_field(static_cast<std::uint32_t>(handles.size()), 2);
  for (const HandleReport& h : handles) {
    s += hex_field(h.handle, 2);
    switch (h.kind) {
      case HandleReport::Kind::kDisabled:
        s += "DISABLED";
        break;
      case HandleReport::Kind::kMissing:
        s += "MISSING" + hex_field(h.port_status, 8) + hex_field(h.frame_number, 8);
        break;
      case HandleReport::Kind::kValid:
        s += signed_field(h.q_NdiTool.w(), 1e4, 5) + signed_field(h.q_NdiTool.x(), 1e4, 5) +
             signed_field(h.q_NdiTool.y(), 1e4, 5) + signed_field(h.q_NdiTool.z(), 1e4, 5);
        for (int i = 0; i < 3; ++i) s += signed_field(h.p_NdiTool_mm[i], 100.0, 6);
        s += signed_field(h.rms_error_mm, 1e4, 5);
        s += hex_field(h.port_status, 8) + hex_field(h.frame_number, 8);
        break;
    }
    s += '\n';
  }
  s += hex_field(system_status, 4);
  return text_reply(s);
}

namespace {
void put_u16(Bytes& b, std::uint16_t v) {
  b.push_back(static_cast<std::uint8_t>(v & 0xFF));
  b.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put_u32(Bytes& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xFF));
}
void put_f32(Bytes& b, double v) {
  const float f = static_cast<float>(v);
  std::uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  put_u32(b, u);
}
}  // namespace

Bytes bx_reply(const std::vector<HandleReport>& handles, std::uint16_t system_status) {
  Bytes body;
  body.push_back(static_cast<std::uint8_t>(handles.size()));
  for (const HandleReport& h : handles) {
    body.push_back(h.handle);
    switch (h.kind) {
      case HandleReport::Kind::kDisabled:
        body.push_back(0x04);
        break;
      case HandleReport::Kind::kMissing:
        body.push_back(0x02);
        put_u32(body, h.port_status);
        put_u32(body, h.frame_number);
        break;
      case HandleReport::Kind::kValid:
        body.push_back(0x01);
        put_f32(body, h.q_NdiTool.w());
        put_f32(body, h.q_NdiTool.x());
        put_f32(body, h.q_NdiTool.y());
        put_f32(body, h.q_NdiTool.z());
        for (int i = 0; i < 3; ++i) put_f32(body, h.p_NdiTool_mm[i]);
        put_f32(body, h.rms_error_mm);
        put_u32(body, h.port_status);
        put_u32(body, h.frame_number);
        break;
    }
  }
  put_u16(body, system_status);
  if (body.size() > 0xFFFF) throw std::length_error("BX reply body longer than 65535 bytes");
  Bytes frame = {0xC4, 0xA5};
  put_u16(frame, static_cast<std::uint16_t>(body.size()));
  put_u16(frame, ndi::crc16(std::span<const std::uint8_t>(frame.data(), 4)));
  frame.insert(frame.end(), body.begin(), body.end());
  put_u16(frame, ndi::crc16(std::span<const std::uint8_t>(body.data(), body.size())));
  return frame;
}

}  // namespace arnav::hil
