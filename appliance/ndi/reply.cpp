#include "appliance/ndi/reply.hpp"

#include <cmath>
#include <cstdio>

#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/hex.hpp"

namespace arnav::ndi {

std::string_view to_string(ParseError e) {
  switch (e) {
    case ParseError::None: return "ok";
    case ParseError::TooShort: return "too short";
    case ParseError::BadCrc: return "CRC mismatch";
    case ParseError::BadHeader: return "bad BX header";
    case ParseError::LengthMismatch: return "length mismatch";
    case ParseError::BadField: return "malformed field";
    case ParseError::BadStatus: return "unknown handle status";
    case ParseError::TooManyHandles: return "too many handles";
    case ParseError::TrailingBytes: return "trailing bytes";
    case ParseError::WrongKind: return "unexpected reply kind";
  }
  return "?";
}

std::string_view to_string(AsciiKind k) {
  switch (k) {
    case AsciiKind::Okay: return "OKAY";
    case AsciiKind::Reset: return "RESET";
    case AsciiKind::Error: return "ERROR";
    case AsciiKind::Warning: return "WARNING";
    case AsciiKind::Data: return "DATA";
  }
  return "?";
}

ParseError check_ascii_reply(std::string_view line, std::string_view& body) {
  if (line.size() < 4) return ParseError::TooShort;
  auto crc = parse_hex<std::uint16_t>(line.substr(line.size() - 4));
  if (!crc) return ParseError::BadCrc;
  body = line.substr(0, line.size() - 4);
  if (crc16(body) != *crc) return ParseError::BadCrc;
  return ParseError::None;
}

ParseError parse_ascii_reply(std::string_view line, AsciiReply& out) {
  out = AsciiReply{};
  if (auto e = check_ascii_reply(line, out.body); e != ParseError::None) return e;
  const std::string_view b = out.body;
  if (b == "OKAY") {
    out.kind = AsciiKind::Okay;
  } else if (b == "RESET") {
    out.kind = AsciiKind::Reset;
  } else if (b.size() == 7 && b.starts_with("ERROR")) {
    auto code = parse_hex<std::uint8_t>(b.substr(5));
    if (!code) return ParseError::BadField;
    out.kind = AsciiKind::Error;
    out.error_code = *code;
    out.has_code = true;
  } else if (b == "WARNING") {
    out.kind = AsciiKind::Warning;
  } else if (b.size() == 9 && b.starts_with("WARNING")) {
    auto code = parse_hex<std::uint8_t>(b.substr(7));
    if (!code) return ParseError::BadField;
    out.kind = AsciiKind::Warning;
    out.error_code = *code;
    out.has_code = true;
  } else {
    out.kind = AsciiKind::Data;
  }
  return ParseError::None;
}

ParseError parse_ver(std::string_view body, VersionInfo& out) {
  out = VersionInfo{};
  if (body.empty()) return ParseError::TooShort;
  std::size_t start = 0;
  while (start < body.size()) {
    std::size_t end = body.find('\n', start);
    if (end == std::string_view::npos) end = body.size();
    std::string_view line = body.substr(start, end - start);
    if (!line.empty()) out.lines.emplace_back(line);
    start = end + 1;
  }
  if (out.lines.empty()) return ParseError::TooShort;
  out.firmware = out.lines.front();
  for (const auto& line : out.lines) {
    auto pos = line.find("S/N:");
    if (pos == std::string::npos) continue;
    std::string_view sn = std::string_view(line).substr(pos + 4);
    while (!sn.empty() && sn.front() == ' ') sn.remove_prefix(1);
    out.serial_number = std::string(sn);
    break;
  }
  return ParseError::None;
}

ParseError parse_phrq(std::string_view body, std::uint8_t& handle) {
  if (body.size() != 2) return body.size() < 2 ? ParseError::TooShort : ParseError::TrailingBytes;
  auto h = parse_hex<std::uint8_t>(body);
  if (!h) return ParseError::BadField;
  handle = *h;
  return ParseError::None;
}

ParseError parse_phsr(std::string_view body, std::vector<PhsrEntry>& out) {
  out.clear();
  if (body.size() < 2) return ParseError::TooShort;
  auto count = parse_hex<std::uint8_t>(body.substr(0, 2));
  if (!count) return ParseError::BadField;
  if (*count > kMaxHandles) return ParseError::TooManyHandles;
  if (body.size() < 2 + 5u * *count) return ParseError::TooShort;
  if (body.size() > 2 + 5u * *count) return ParseError::TrailingBytes;
  for (unsigned i = 0; i < *count; ++i) {
    auto h = parse_hex<std::uint8_t>(body.substr(2 + 5 * i, 2));
    auto s = parse_hex<std::uint16_t>(body.substr(4 + 5 * i, 3));
    if (!h || !s) return ParseError::BadField;
    out.push_back({*h, *s});
  }
  return ParseError::None;
}

namespace {
std::string trimmed(std::string_view s) {
  while (!s.empty() && s.back() == ' ') s.remove_suffix(1);
  while (!s.empty() && s.front() == ' ') s.remove_prefix(1);
  return std::string(s);
}
}  // namespace

ParseError parse_phinf_basic(std::string_view body, PortHandleInfo& out) {
  if (body.size() < 33) return ParseError::TooShort;
  if (body.size() > 33) return ParseError::TrailingBytes;
  out.tool_type = std::string(body.substr(0, 8));
  out.manufacturer = trimmed(body.substr(8, 12));
  out.revision = trimmed(body.substr(20, 3));
  out.serial_number = trimmed(body.substr(23, 8));
  auto st = parse_hex<std::uint8_t>(body.substr(31, 2));
  if (!st) return ParseError::BadField;
  out.port_status = *st;
  return ParseError::None;
}

ParseError parse_transform(std::string_view s, HandleRecord& out) {
  if (s.size() < kTransformChars) return ParseError::TooShort;
  static constexpr std::size_t kOffsets[8] = {0, 6, 12, 18, 24, 31, 38, 45};
  static constexpr std::size_t kWidths[8] = {6, 6, 6, 6, 7, 7, 7, 6};
  long v[8];
  for (int i = 0; i < 8; ++i) {
    auto x = parse_signed_decimal(s.substr(kOffsets[i], kWidths[i]));
    if (!x) return ParseError::BadField;
    v[i] = *x;
  }
  for (int i = 0; i < 4; ++i) out.q_NdiTool_wxyz[i] = static_cast<double>(v[i]) / 1e4;
  for (int i = 0; i < 3; ++i) out.p_NdiTool_mm[i] = static_cast<double>(v[4 + i]) / 100.0;
  out.rms_error_mm = static_cast<double>(v[7]) / 1e4;
  return ParseError::None;
}

ParseError parse_tx(std::string_view body, TrackingReply& out) {
  out.count = 0;
  out.has_frame = out.has_device_time = false;
  if (body.size() < 2 + 4) return ParseError::TooShort;
  auto count = parse_hex<std::uint8_t>(body.substr(0, 2));
  if (!count) return ParseError::BadField;
  if (*count > kMaxHandles) return ParseError::TooManyHandles;
  std::size_t pos = 2;
  for (unsigned i = 0; i < *count; ++i) {
    HandleRecord& r = out.handles[i];
    r = HandleRecord{};
    if (body.size() < pos + 2) return ParseError::TooShort;
    auto h = parse_hex<std::uint8_t>(body.substr(pos, 2));
    if (!h) return ParseError::BadField;
    r.handle = *h;
    pos += 2;
    std::size_t lf = body.find('\n', pos);
    if (lf == std::string_view::npos) return ParseError::TooShort;
    std::string_view item = body.substr(pos, lf - pos);
    std::string_view tail;  // port status + frame number (16 hex), when present
    if (item.starts_with("MISSING")) {
      r.state = HandleState::Missing;
      tail = item.substr(7);
    } else if (item.starts_with("DISABLED")) {
      r.state = HandleState::Disabled;
      tail = item.substr(8);
    } else if (item.starts_with("UNOCCUPIED")) {
      r.state = HandleState::Unoccupied;
      tail = item.substr(10);
    } else {
      r.state = HandleState::Valid;
      if (auto e = parse_transform(item, r); e != ParseError::None) return e;
      tail = item.substr(kTransformChars);
    }
    if (tail.size() == 16) {
      auto ps = parse_hex<std::uint32_t>(tail.substr(0, 8));
      auto fn = parse_hex<std::uint32_t>(tail.substr(8, 8));
      if (!ps || !fn) return ParseError::BadField;
      r.has_status = true;
      r.port_status = *ps;
      r.frame_number = *fn;
    } else if (!tail.empty() || r.state == HandleState::Valid || r.state == HandleState::Missing) {
      return ParseError::BadField;  // valid and missing handles always carry status + frame
    }
    pos = lf + 1;
  }
  out.count = *count;
  if (body.size() < pos + 4) return ParseError::TooShort;
  if (body.size() > pos + 4) return ParseError::TrailingBytes;
  auto sys = parse_hex<std::uint16_t>(body.substr(pos, 4));
  if (!sys) return ParseError::BadField;
  out.system_status = *sys;
  return ParseError::None;
}

std::string encode_reply(std::string_view body) {
  std::string out(body);
  char crc[5];
  std::snprintf(crc, sizeof crc, "%04X", crc16(body));
  out.append(crc, 4).push_back('\r');
  return out;
}

namespace {
void append_signed(std::string& out, double value, double scale, int digits) {
  long v = std::lround(value * scale);
  long limit = 1;
  for (int i = 0; i < digits; ++i) limit *= 10;
  if (v >= limit) v = limit - 1;
  if (v <= -limit) v = -(limit - 1);
  char buf[16];
  std::snprintf(buf, sizeof buf, "%c%0*ld", v < 0 ? '-' : '+', digits, v < 0 ? -v : v);
  out.append(buf);
}
}  // namespace

std::string format_transform(const HandleRecord& r) {
  std::string out;
  out.reserve(kTransformChars);
  for (double q : r.q_NdiTool_wxyz) append_signed(out, q, 1e4, 5);
  for (double p : r.p_NdiTool_mm) append_signed(out, p, 100.0, 6);
  append_signed(out, r.rms_error_mm, 1e4, 5);
  return out;
}

std::string format_tx_body(const TrackingReply& reply) {
  std::string out = hex2(static_cast<unsigned>(reply.count));
  char buf[24];
  for (std::size_t i = 0; i < reply.count; ++i) {
    const HandleRecord& r = reply.handles[i];
    out += hex2(r.handle);
    switch (r.state) {
      case HandleState::Valid: out += format_transform(r); break;
      case HandleState::Missing: out += "MISSING"; break;
      case HandleState::Disabled: out += "DISABLED"; break;
      case HandleState::Unoccupied: out += "UNOCCUPIED"; break;
    }
    if (r.has_status || r.state == HandleState::Valid || r.state == HandleState::Missing) {
      std::snprintf(buf, sizeof buf, "%08X%08X", r.port_status, r.frame_number);
      out += buf;
    }
    out += '\n';
  }
  std::snprintf(buf, sizeof buf, "%04X", reply.system_status);
  out += buf;
  return out;
}

}  // namespace arnav::ndi
