#include "appliance/ndi/bx2.hpp"

#include <cmath>
#include <cstring>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/crc16.hpp"

namespace arnav::ndi {
namespace {

constexpr std::size_t kComponentHeaderBytes = 12;
constexpr std::size_t kFrameItemHeaderBytes = 16;
constexpr std::size_t k6dItemHeaderBytes = 4;
constexpr std::size_t k6dPoseBytes = 32;
constexpr std::uint16_t kMaxComponents = 64;
constexpr std::uint32_t kMaxFrameItems = 8;

// Bounds-checked little-endian reads over [pos, end).
class Cursor {
 public:
  Cursor(const std::uint8_t* data, std::size_t end) : data_(data), end_(end) {}
  bool has(std::size_t n) const { return end_ - pos_ >= n; }
  std::size_t pos() const { return pos_; }
  std::size_t end() const { return end_; }
  std::uint8_t u8() { return data_[pos_++]; }
  std::uint16_t u16() {
    const auto v = static_cast<std::uint16_t>(data_[pos_] | (data_[pos_ + 1] << 8));
    pos_ += 2;
    return v;
  }
  std::uint32_t u32() {
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = (v << 8) | data_[pos_ + static_cast<std::size_t>(i)];
    pos_ += 4;
    return v;
  }
  float f32() {
    const std::uint32_t bits = u32();
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
  }
  // A sub-range [pos, pos + n) to parse on its own; this cursor skips past it.
  Cursor take(std::size_t n) {
    Cursor sub(data_, pos_ + n);
    sub.pos_ = pos_;
    pos_ += n;
    return sub;
  }

 private:
  const std::uint8_t* data_;
  std::size_t end_;
  std::size_t pos_ = 0;
};

struct FrameInfo {
  std::uint32_t frame_number = 0;
};

std::uint32_t port_status_for(std::uint16_t status) {
  std::uint32_t bits = kPortOccupied | kPortInitialised | kPortEnabled;
  const auto code = static_cast<std::uint8_t>(status & 0xFF);
  if (code == kBx2OutOfVolume) bits |= kPortOutOfVolume;
  if (code == kBx2PartiallyOutOfVolume) bits |= kPortPartiallyInVolume;
  return bits;
}

ParseError parse_6d(Cursor c, std::uint32_t items, const FrameInfo& frame, TrackingReply& out) {
  for (std::uint32_t i = 0; i < items; ++i) {
    if (!c.has(k6dItemHeaderBytes)) return ParseError::LengthMismatch;
    const std::uint16_t handle = c.u16();
    const std::uint16_t status = c.u16();
    if (handle > 0xFF) return ParseError::BadField;
    if (out.count >= kMaxHandles) return ParseError::TooManyHandles;
    HandleRecord& r = out.handles[out.count];
    r = HandleRecord{};
    r.handle = static_cast<std::uint8_t>(handle);
    r.has_status = true;
    r.frame_number = frame.frame_number;
    r.port_status = port_status_for(status);
    if (status & kBx2Missing) {
      r.state = HandleState::Missing;
    } else {
      if (!c.has(k6dPoseBytes)) return ParseError::LengthMismatch;
      float v[8];
      for (float& x : v) {
        x = c.f32();
        if (!std::isfinite(x)) return ParseError::BadField;
      }
      r.state = HandleState::Valid;
      const auto d = [&](int k) { return static_cast<double>(v[k]); };
      r.q_NdiTool_wxyz = {d(0), d(1), d(2), d(3)};
      r.p_NdiTool_mm = {d(4), d(5), d(6)};
      r.rms_error_mm = d(7);
    }
    ++out.count;
  }
  return c.pos() == c.end() ? ParseError::None : ParseError::TrailingBytes;
}

ParseError parse_container(Cursor& c, const FrameInfo* frame, TrackingReply& out, int depth);

ParseError parse_frame_items(Cursor c, std::uint32_t items, TrackingReply& out, int depth) {
  if (items > kMaxFrameItems) return ParseError::BadField;
  for (std::uint32_t i = 0; i < items; ++i) {
    if (!c.has(kFrameItemHeaderBytes)) return ParseError::LengthMismatch;
    c.u8();  // frame type
    c.u8();  // sequence index
    c.u16();  // frame status
    FrameInfo frame;
    frame.frame_number = c.u32();
    const std::uint32_t seconds = c.u32();
    const std::uint32_t nanoseconds = c.u32();
    if (nanoseconds >= 1'000'000'000u) return ParseError::BadField;
    if (!out.has_frame) {
      out.has_frame = true;
      out.frame = frame.frame_number;
      out.has_device_time = true;
      out.device_time_ns = static_cast<std::int64_t>(seconds) * 1'000'000'000 + nanoseconds;
    }
    if (auto e = parse_container(c, &frame, out, depth + 1); e != ParseError::None) return e;
  }
  return c.pos() == c.end() ? ParseError::None : ParseError::TrailingBytes;
}

// One GBF container at c: version, count, components. A 6D component outside a frame
// item has no frame number and is refused (the driver never asks for such replies).
ParseError parse_container(Cursor& c, const FrameInfo* frame, TrackingReply& out, int depth) {
  if (depth > 2) return ParseError::BadField;  // frames do not nest further
  if (!c.has(4)) return ParseError::TooShort;
  c.u16();  // GBF version
  const std::uint16_t components = c.u16();
  if (components > kMaxComponents) return ParseError::BadField;
  for (std::uint16_t i = 0; i < components; ++i) {
    if (!c.has(kComponentHeaderBytes)) return ParseError::LengthMismatch;
    const std::uint16_t type = c.u16();
    const std::uint32_t size = c.u32();
    c.u16();  // item option
    const std::uint32_t items = c.u32();
    if (size < kComponentHeaderBytes || !c.has(size - kComponentHeaderBytes)) return ParseError::LengthMismatch;
    Cursor body = c.take(size - kComponentHeaderBytes);
    ParseError e = ParseError::None;
    if (type == kGbfFrame) e = parse_frame_items(body, items, out, depth);
    else if (type == kGbf6d) e = frame ? parse_6d(body, items, *frame, out) : ParseError::BadField;
    if (e != ParseError::None) return e;
  }
  return ParseError::None;
}

void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFF));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xFF));
}
void put_f32(std::vector<std::uint8_t>& out, double v) {
  const auto f = static_cast<float>(v);
  std::uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  put_u32(out, bits);
}
void patch_u32(std::vector<std::uint8_t>& out, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>((v >> (8 * i)) & 0xFF);
}

std::uint16_t status_for(const HandleRecord& r) {
  std::uint16_t s = 0;
  if (r.state != HandleState::Valid) s |= kBx2Missing;
  if (r.port_status & kPortOutOfVolume) s |= kBx2OutOfVolume;
  else if (r.port_status & kPortPartiallyInVolume) s |= kBx2PartiallyOutOfVolume;
  return s;
}

}  // namespace

ParseError parse_bx2(std::span<const std::uint8_t> frame, TrackingReply& out, bool crc_already_checked) {
  out.count = 0;
  out.system_status = 0;
  out.has_frame = out.has_device_time = false;
  out.frame = 0;
  out.device_time_ns = 0;
  std::uint16_t length = 0;
  if (crc_already_checked) {
    if (frame.size() < kBxHeaderBytes) return ParseError::TooShort;
    if (frame[0] != kBxStart0 || frame[1] != kBxStart1) return ParseError::BadHeader;
    length = static_cast<std::uint16_t>(frame[2] | (frame[3] << 8));
  } else if (auto e = check_bx_header(frame, length); e != ParseError::None) {
    return e;
  }
  if (frame.size() != kBxHeaderBytes + length + 2u) return ParseError::LengthMismatch;
  const std::uint8_t* body = frame.data() + kBxHeaderBytes;
  if (!crc_already_checked && crc16(std::span(body, length)) != static_cast<std::uint16_t>(body[length] | (body[length + 1] << 8)))
    return ParseError::BadCrc;
  Cursor c(body, length);
  ParseError e = parse_container(c, nullptr, out, 0);
  if (e == ParseError::None && c.pos() != c.end()) e = ParseError::TrailingBytes;
  if (e == ParseError::None && !out.has_frame) e = ParseError::WrongKind;  // a GBF reply without a frame
  if (e != ParseError::None) {
    out.count = 0;
    out.has_frame = out.has_device_time = false;
  }
  return e;
}

void encode_bx2(const TrackingReply& reply, std::vector<std::uint8_t>& out) {
  std::vector<std::uint8_t> body;
  put_u16(body, kGbfVersion);
  put_u16(body, 1);
  const std::size_t frame_component = body.size();
  put_u16(body, kGbfFrame);
  put_u32(body, 0);  // size, patched below
  put_u16(body, 0);
  put_u32(body, 1);
  body.push_back(0x01);  // frame type
  body.push_back(0x00);  // sequence index
  put_u16(body, 0);      // frame status
  put_u32(body, reply.frame);
  const std::int64_t t_ns = reply.device_time_ns < 0 ? 0 : reply.device_time_ns;
  put_u32(body, static_cast<std::uint32_t>(t_ns / 1'000'000'000));
  put_u32(body, static_cast<std::uint32_t>(t_ns % 1'000'000'000));
  put_u16(body, kGbfVersion);
  put_u16(body, 1);
  const std::size_t six_d = body.size();
  put_u16(body, kGbf6d);
  put_u32(body, 0);
  put_u16(body, 0);
  const std::size_t six_d_count = body.size();
  put_u32(body, 0);
  std::uint32_t n = 0;
  for (std::size_t i = 0; i < reply.count; ++i) {
    const HandleRecord& r = reply.handles[i];
    if (r.state == HandleState::Disabled || r.state == HandleState::Unoccupied) continue;
    ++n;
    put_u16(body, r.handle);
    put_u16(body, status_for(r));
    if (r.state != HandleState::Valid) continue;
    for (double q : r.q_NdiTool_wxyz) put_f32(body, q);
    for (double p : r.p_NdiTool_mm) put_f32(body, p);
    put_f32(body, r.rms_error_mm);
  }
  patch_u32(body, six_d + 2, static_cast<std::uint32_t>(body.size() - six_d));
  patch_u32(body, six_d_count, n);
  patch_u32(body, frame_component + 2, static_cast<std::uint32_t>(body.size() - frame_component));

  const std::size_t start = out.size();
  out.push_back(kBxStart0);
  out.push_back(kBxStart1);
  put_u16(out, static_cast<std::uint16_t>(body.size()));
  put_u16(out, crc16(std::span(out.data() + start, 4)));
  out.insert(out.end(), body.begin(), body.end());
  put_u16(out, crc16(std::span(body)));
}

}  // namespace arnav::ndi
