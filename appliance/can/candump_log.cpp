#include "appliance/can/candump_log.hpp"

#include <cstdio>
#include <istream>

namespace arnav::can {
namespace {

constexpr std::uint32_t kErrFlag = 0x20000000;

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

const char kHex[] = "0123456789ABCDEF";

void put_hex(std::string& s, std::uint32_t v, int digits) {
  for (int i = digits - 1; i >= 0; --i) s += kHex[(v >> (4 * i)) & 0xF];
}

}  // namespace

std::string_view to_string(LogError e) {
  switch (e) {
    case LogError::None: return "ok";
    case LogError::NoTimestamp: return "expected '(seconds.micros)' at the start of the line";
    case LogError::BadTimestamp: return "bad timestamp (expected '(1700000000.123456)')";
    case LogError::NoInterface: return "expected an interface name after the timestamp";
    case LogError::BadId: return "bad CAN id (3 hex digits standard <= 7FF, 8 hex digits extended <= 1FFFFFFF)";
    case LogError::BadData: return "bad data (up to 8 bytes as hex pairs, or R for a remote frame)";
    case LogError::CanFd: return "CAN FD frame ('##'): only classic CAN is supported";
  }
  return "?";
}

std::string to_candump(const CanFrame& f) {
  std::string s;
  s.reserve(32);
  if (f.error) put_hex(s, kErrFlag | (f.id & kMaxExtendedId), 8);
  else if (f.extended) put_hex(s, f.id & kMaxExtendedId, 8);
  else put_hex(s, f.id & kMaxStandardId, 3);
  s += '#';
  if (f.remote) {
    s += 'R';
    if (f.dlc > 0) s += static_cast<char>('0' + f.dlc);
    return s;
  }
  for (int i = 0; i < f.dlc && i < 8; ++i) put_hex(s, f.data[static_cast<std::size_t>(i)], 2);
  return s;
}

LogError parse_frame_text(std::string_view text, CanFrame& out) {
  out = CanFrame{};
  const auto hash = text.find('#');
  if (hash == std::string_view::npos) return LogError::BadId;
  const std::string_view id_text = text.substr(0, hash);
  std::string_view rest = text.substr(hash + 1);
  if (!rest.empty() && rest[0] == '#') return LogError::CanFd;
  if (id_text.size() != 3 && id_text.size() != 8) return LogError::BadId;
  std::uint32_t id = 0;
  for (char c : id_text) {
    const int v = hex_value(c);
    if (v < 0) return LogError::BadId;
    id = (id << 4) | static_cast<std::uint32_t>(v);
  }
  if (id_text.size() == 3) {
    if (id > kMaxStandardId) return LogError::BadId;
  } else if (id & kErrFlag) {
    if (id & 0xC0000000u) return LogError::BadId;
    out.error = true;
    id &= ~kErrFlag;
  } else {
    if (id > kMaxExtendedId) return LogError::BadId;
    out.extended = true;
  }
  out.id = id;
  if (!rest.empty() && (rest[0] == 'R' || rest[0] == 'r')) {
    if (out.error) return LogError::BadData;
    out.remote = true;
    if (rest.size() == 2 && rest[1] >= '0' && rest[1] <= '8') out.dlc = static_cast<std::uint8_t>(rest[1] - '0');
    else if (rest.size() != 1) return LogError::BadData;
    return LogError::None;
  }
  std::size_t n = 0;
  for (std::size_t i = 0; i < rest.size();) {
    if (rest[i] == '.') {  // candump -ta style separators
      ++i;
      continue;
    }
    if (i + 1 >= rest.size() || n >= 8) return LogError::BadData;
    const int hi = hex_value(rest[i]), lo = hex_value(rest[i + 1]);
    if (hi < 0 || lo < 0) return LogError::BadData;
    out.data[n++] = static_cast<std::uint8_t>(hi * 16 + lo);
    i += 2;
  }
  out.dlc = static_cast<std::uint8_t>(n);
  return LogError::None;
}

LogError parse_log_line(std::string_view line, LogRecord& out) {
  out = LogRecord{};
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) line.remove_suffix(1);
  if (line.empty() || line[0] != '(') return LogError::NoTimestamp;
  const auto close = line.find(')');
  if (close == std::string_view::npos) return LogError::BadTimestamp;
  const std::string_view ts = line.substr(1, close - 1);
  const auto dot = ts.find('.');
  if (dot == std::string_view::npos || dot == 0 || dot > 12 || ts.size() - dot - 1 != 6) return LogError::BadTimestamp;
  std::int64_t sec = 0, usec = 0;
  for (std::size_t i = 0; i < ts.size(); ++i) {
    if (i == dot) continue;
    if (ts[i] < '0' || ts[i] > '9') return LogError::BadTimestamp;
    (i < dot ? sec : usec) = (i < dot ? sec : usec) * 10 + (ts[i] - '0');
  }
  out.time_us = sec * 1'000'000 + usec;
  std::string_view rest = line.substr(close + 1);
  if (rest.empty() || rest[0] != ' ') return LogError::NoInterface;
  while (!rest.empty() && rest[0] == ' ') rest.remove_prefix(1);
  const auto space = rest.find(' ');
  if (space == 0 || space == std::string_view::npos) return LogError::NoInterface;
  out.interface = std::string(rest.substr(0, space));
  rest = rest.substr(space + 1);
  while (!rest.empty() && rest[0] == ' ') rest.remove_prefix(1);
  // Newer candump logs may append a direction/flag field ("T" / "R"): ignore it.
  const auto tail = rest.find(' ');
  if (tail != std::string_view::npos) {
    const std::string_view extra = rest.substr(tail + 1);
    if (extra != "R" && extra != "T") return LogError::BadData;
    rest = rest.substr(0, tail);
  }
  return parse_frame_text(rest, out.frame);
}

std::string format_log_line(const LogRecord& r) {
  char ts[40];
  const std::int64_t sec = r.time_us / 1'000'000, usec = r.time_us % 1'000'000;
  std::snprintf(ts, sizeof ts, "(%lld.%06lld) ", static_cast<long long>(sec), static_cast<long long>(usec));
  return ts + r.interface + " " + to_candump(r.frame);
}

std::optional<LogRecord> LogReader::next() {
  std::string text;
  while (std::getline(in_, text)) {
    ++line_;
    std::string_view v(text);
    while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
    while (!v.empty() && (v.back() == '\r' || v.back() == ' ' || v.back() == '\t')) v.remove_suffix(1);
    if (v.empty() || v[0] == '#') continue;
    LogRecord r;
    const LogError e = parse_log_line(v, r);
    if (e != LogError::None) {
      std::string shown(v.substr(0, 80));
      for (char& c : shown)
        if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7F) c = '?';
      throw LogFileError(source_ + ":" + std::to_string(line_) + ": " + std::string(to_string(e)) + ": '" + shown + "'");
    }
    return r;
  }
  return std::nullopt;
}

}  // namespace arnav::can
