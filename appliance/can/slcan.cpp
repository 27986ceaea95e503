#include "appliance/can/slcan.hpp"

namespace arnav::can::slcan {
namespace {

int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

bool parse_hex(std::string_view s, std::uint32_t& out) {
  out = 0;
  for (char c : s) {
    const int v = hex_value(c);
    if (v < 0) return false;
    out = (out << 4) | static_cast<std::uint32_t>(v);
  }
  return true;
}

bool frame_start(char c) { return c == 't' || c == 'T' || c == 'r' || c == 'R'; }

const char kHex[] = "0123456789ABCDEF";

}  // namespace

std::optional<int> bitrate_code(int bitrate) {
  for (std::size_t i = 0; i < kBitrates.size(); ++i)
    if (kBitrates[i] == bitrate) return static_cast<int>(i);
  return std::nullopt;
}

std::string bitrate_command(int code) { return std::string("S") + static_cast<char>('0' + code) + "\r"; }

std::string encode_frame(const CanFrame& f) {
  if (f.error) return {};
  std::string s;
  s.reserve(32);
  const int digits = f.extended ? 8 : 3;
  s += f.remote ? (f.extended ? 'R' : 'r') : (f.extended ? 'T' : 't');
  const std::uint32_t id = f.id & (f.extended ? kMaxExtendedId : kMaxStandardId);
  for (int i = digits - 1; i >= 0; --i) s += kHex[(id >> (4 * i)) & 0xF];
  const int dlc = f.dlc > 8 ? 8 : f.dlc;
  s += static_cast<char>('0' + dlc);
  if (!f.remote)
    for (int i = 0; i < dlc; ++i) {
      s += kHex[f.data[static_cast<std::size_t>(i)] >> 4];
      s += kHex[f.data[static_cast<std::size_t>(i)] & 0xF];
    }
  s += '\r';
  return s;
}

Reader::Reader() {
  buf_.reserve(4096);
  pending_.reserve(8);
}

void Reader::feed(std::span<const std::uint8_t> bytes) {
  if (start_ > 0 && start_ == buf_.size()) {
    buf_.clear();
    start_ = 0;
  } else if (start_ > 2048) {
    buf_.erase(buf_.begin(), buf_.begin() + static_cast<std::ptrdiff_t>(start_));
    start_ = 0;
  }
  buf_.insert(buf_.end(), bytes.begin(), bytes.end());
}

void Reader::drop(std::size_t n) {
  if (n == 0) return;
  counters_.garbage_bytes += static_cast<std::int64_t>(n);
  counters_.resyncs += 1;
}

void Reader::clear() {
  drop(buffered());
  buf_.clear();
  start_ = 0;
  line_len_ = 0;
  pending_.clear();
  pending_next_ = 0;
}

// One segment of a line: a whole message, nothing more, nothing less.
bool Reader::parse_one(std::string_view seg, Message& m) const {
  m = Message{};
  if (seg.empty()) {
    m.kind = Message::Kind::Ok;
    return true;
  }
  const char k = seg[0];
  if (frame_start(k)) {
    const bool ext = k == 'T' || k == 'R';
    const bool rtr = k == 'r' || k == 'R';
    const std::size_t id_digits = ext ? 8 : 3;
    if (seg.size() < 1 + id_digits + 1) return false;
    std::uint32_t id = 0;
    if (!parse_hex(seg.substr(1, id_digits), id)) return false;
    if (id > (ext ? kMaxExtendedId : kMaxStandardId)) return false;
    const char d = seg[1 + id_digits];
    if (d < '0' || d > '8') return false;
    const std::size_t dlc = static_cast<std::size_t>(d - '0');
    const std::size_t body = 1 + id_digits + 1 + (rtr ? 0 : 2 * dlc);
    if (seg.size() != body && !(timestamps_ && seg.size() == body + 4)) return false;
    m.kind = Message::Kind::Frame;
    m.frame.id = id;
    m.frame.extended = ext;
    m.frame.remote = rtr;
    m.frame.dlc = static_cast<std::uint8_t>(dlc);
    if (!rtr)
      for (std::size_t i = 0; i < dlc; ++i) {
        std::uint32_t b = 0;
        if (!parse_hex(seg.substr(1 + id_digits + 1 + 2 * i, 2), b)) return false;
        m.frame.data[i] = static_cast<std::uint8_t>(b);
      }
    if (seg.size() == body + 4) {
      std::uint32_t ts = 0;
      if (!parse_hex(seg.substr(body, 4), ts) || ts >= 60000) return false;
      m.timestamp_ms = static_cast<std::uint16_t>(ts);
    }
    return true;
  }
  if (k == 'F' && seg.size() == 3) {
    std::uint32_t flags = 0;
    if (!parse_hex(seg.substr(1, 2), flags)) return false;
    m.kind = Message::Kind::Status;
    m.flags = static_cast<std::uint8_t>(flags);
    return true;
  }
  if ((k == 'V' || k == 'v' || k == 'N') && seg.size() == 5) {
    for (std::size_t i = 0; i < 4; ++i) {
      const char c = seg[1 + i];
      if (!((c >= '0' && c <= '9') || (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z'))) return false;
      m.text[i] = c;
    }
    m.kind = k == 'N' ? Message::Kind::Serial : Message::Kind::Version;
    return true;
  }
  if ((k == 'z' || k == 'Z') && seg.size() == 1) {
    m.kind = Message::Kind::TxAck;
    return true;
  }
  return false;
}

// Splits a finished line at frame start letters: every segment that parses is a message
// (the ones before the last lost their CR); the rest is counted and dropped.
void Reader::parse_line(std::string_view line, bool terminated, bool has_cr) {
  std::size_t pos = 0;
  while (pos <= line.size()) {
    std::size_t end = pos + 1;
    while (end < line.size() && !frame_start(line[end])) ++end;
    if (pos == line.size()) end = pos;
    const std::string_view seg = line.substr(pos, std::min(end, line.size()) - pos);
    const bool last = end >= line.size();
    Message m;
    if ((terminated || !last) && parse_one(seg, m)) {
      if (m.kind == Message::Kind::Frame) counters_.frames += 1;
      if (!last) counters_.resyncs += 1;  // a frame whose CR was lost
      // An empty segment is only an OK reply when it is the whole line.
      if (!(seg.empty() && !line.empty())) pending_.push_back(m);
    } else if (!seg.empty()) {
      counters_.malformed += 1;
      drop(seg.size() + ((has_cr && last) ? 1 : 0));
    }
    if (last) break;
    pos = end;
  }
}

bool Reader::next(Message& out) {
  for (;;) {
    if (pending_next_ < pending_.size()) {
      out = pending_[pending_next_++];
      if (pending_next_ == pending_.size()) {
        pending_.clear();
        pending_next_ = 0;
      }
      return true;
    }
    if (start_ >= buf_.size()) return false;
    const auto b = static_cast<char>(buf_[start_++]);
    if (b == '\r') {
      parse_line(std::string_view(line_.data(), line_len_), true, true);
      line_len_ = 0;
    } else if (b == '\a') {
      if (line_len_ > 0) {  // a line cut short by an error reply
        counters_.malformed += 1;
        drop(line_len_);
        line_len_ = 0;
      }
      counters_.errors += 1;
      Message m;
      m.kind = Message::Kind::Error;
      pending_.push_back(m);
    } else if (static_cast<unsigned char>(b) < 0x20 || static_cast<unsigned char>(b) >= 0x7F) {
      // A corrupted byte: the line it sits in cannot be trusted, but frames before a
      // frame start letter in it can (their CR was lost, not their bytes).
      if (line_len_ > 0) parse_line(std::string_view(line_.data(), line_len_), false, false);
      drop(1);
      line_len_ = 0;
    } else {
      if (line_len_ == kMaxLine) {
        // Too long for one message: salvage whole frames, keep from the last start letter.
        std::size_t keep = line_len_;
        while (keep > 0 && !frame_start(line_[keep - 1])) --keep;
        if (keep > 1) {
          parse_line(std::string_view(line_.data(), keep - 1), true, false);  // a start letter follows
          const std::size_t n = line_len_ - (keep - 1);
          std::copy(line_.begin() + static_cast<std::ptrdiff_t>(keep - 1), line_.begin() + static_cast<std::ptrdiff_t>(line_len_), line_.begin());
          line_len_ = n;
        }
        if (line_len_ == kMaxLine) {
          counters_.malformed += 1;
          drop(line_len_);
          line_len_ = 0;
        }
      }
      line_[line_len_++] = b;
    }
  }
}

}  // namespace arnav::can::slcan
