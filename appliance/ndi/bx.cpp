#include "appliance/ndi/bx.hpp"

#include <cstring>

#include "appliance/ndi/crc16.hpp"

namespace arnav::ndi {
namespace {

std::uint16_t u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
float f32(const std::uint8_t* p) {
  std::uint32_t bits = u32(p);
  float f;
  std::memcpy(&f, &bits, sizeof f);
  return f;
}
void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFF));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xFF));
}
void put_f32(std::vector<std::uint8_t>& out, double v) {
  float f = static_cast<float>(v);
  std::uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  put_u32(out, bits);
}

}  // namespace

ParseError check_bx_header(std::span<const std::uint8_t> header, std::uint16_t& body_length) {
  if (header.size() < kBxHeaderBytes) return ParseError::TooShort;
  if (header[0] != kBxStart0 || header[1] != kBxStart1) return ParseError::BadHeader;
  if (crc16(header.first(4)) != u16(header.data() + 4)) return ParseError::BadHeader;
  body_length = u16(header.data() + 2);
  if (body_length > kBxMaxBody || body_length < 3) return ParseError::BadHeader;
  return ParseError::None;
}

ParseError parse_bx(std::span<const std::uint8_t> frame, TrackingReply& out, BxCrc crc) {
  out.count = 0;
  out.has_frame = out.has_device_time = false;
  std::uint16_t length = 0;
  if (crc == BxCrc::Check) {
    if (auto e = check_bx_header(frame, length); e != ParseError::None) return e;
  } else {
    if (frame.size() < kBxHeaderBytes) return ParseError::TooShort;
    if (frame[0] != kBxStart0 || frame[1] != kBxStart1) return ParseError::BadHeader;
    length = u16(frame.data() + 2);
    if (length > kBxMaxBody || length < 3) return ParseError::BadHeader;
  }
  if (frame.size() != kBxHeaderBytes + length + 2u) return ParseError::LengthMismatch;
  const std::uint8_t* body = frame.data() + kBxHeaderBytes;
  if (crc == BxCrc::Check && crc16(std::span(body, length)) != u16(body + length)) return ParseError::BadCrc;

  const std::uint8_t* p = body;
  const std::uint8_t* end = body + length;  // system status is the last 2 body bytes
  const std::size_t count = *p++;
  if (count > kMaxHandles) return ParseError::TooManyHandles;
  for (std::size_t i = 0; i < count; ++i) {
    if (end - p < 2) return ParseError::LengthMismatch;
    HandleRecord& r = out.handles[i];
    r.handle = p[0];
    const std::uint8_t status = p[1];
    p += 2;
    r.has_status = false;
    r.port_status = 0;
    r.frame_number = 0;
    if (status == kBxDisabled) {
      r.state = HandleState::Disabled;
      continue;
    }
    if (status == kBxValid) {
      if (end - p < 32) return ParseError::LengthMismatch;
      r.state = HandleState::Valid;
      for (int k = 0; k < 4; ++k) r.q_NdiTool_wxyz[k] = static_cast<double>(f32(p + 4 * k));
      for (int k = 0; k < 3; ++k) r.p_NdiTool_mm[k] = static_cast<double>(f32(p + 16 + 4 * k));
      r.rms_error_mm = static_cast<double>(f32(p + 28));
      p += 32;
    } else if (status == kBxMissing) {
      r.state = HandleState::Missing;
    } else {
      return ParseError::BadStatus;
    }
    if (end - p < 8) return ParseError::LengthMismatch;
    r.has_status = true;
    r.port_status = u32(p);
    r.frame_number = u32(p + 4);
    p += 8;
  }
  if (end - p != 2) return end - p < 2 ? ParseError::LengthMismatch : ParseError::TrailingBytes;
  out.system_status = u16(p);
  out.count = count;
  return ParseError::None;
}

void encode_bx(const TrackingReply& reply, std::vector<std::uint8_t>& out) {
  std::vector<std::uint8_t> body;
  body.push_back(static_cast<std::uint8_t>(reply.count));
  for (std::size_t i = 0; i < reply.count; ++i) {
    const HandleRecord& r = reply.handles[i];
    body.push_back(r.handle);
    switch (r.state) {
      case HandleState::Valid:
        body.push_back(kBxValid);
        for (double q : r.q_NdiTool_wxyz) put_f32(body, q);
        for (double t : r.p_NdiTool_mm) put_f32(body, t);
        put_f32(body, r.rms_error_mm);
        break;
      case HandleState::Missing: body.push_back(kBxMissing); break;
      case HandleState::Disabled:
      case HandleState::Unoccupied: body.push_back(kBxDisabled); break;
    }
    if (r.state == HandleState::Valid || r.state == HandleState::Missing) {
      put_u32(body, r.port_status);
      put_u32(body, r.frame_number);
    }
  }
  put_u16(body, reply.system_status);
  const std::size_t start = out.size();
  out.push_back(kBxStart0);
  out.push_back(kBxStart1);
  put_u16(out, static_cast<std::uint16_t>(body.size()));
  put_u16(out, crc16(std::span<const std::uint8_t>(out.data() + start, 4)));
  out.insert(out.end(), body.begin(), body.end());
  put_u16(out, crc16(body));
}

}  // namespace arnav::ndi
