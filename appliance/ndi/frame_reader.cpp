#include "appliance/ndi/frame_reader.hpp"

#include <algorithm>
#include <array>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/reply.hpp"

namespace arnav::ndi {
namespace {

constexpr std::array<std::string_view, 4> kAsciiStarts = {"ERROR", "WARNING", "RESET", "OKAY"};
constexpr std::size_t kExtendedHeaderBytes = 6;
constexpr std::size_t kStreamFixedBytes = 6;  // start (2) + id length (2) + CRC (2)

bool printable(std::uint8_t b) { return (b >= 0x20 && b < 0x7F) || b == '\n'; }

std::uint16_t u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

// How well bytes[0..] matches an ASCII reply start that the device sends while BX is
// expected: 2 = full keyword, 1 = a prefix of one (need more bytes), 0 = no.
int ascii_start_match(std::span<const std::uint8_t> bytes) {
  for (auto kw : kAsciiStarts) {
    std::size_t n = std::min(kw.size(), bytes.size());
    if (std::equal(kw.begin(), kw.begin() + static_cast<std::ptrdiff_t>(n), bytes.begin()))
      return n == kw.size() ? 2 : 1;
  }
  return 0;
}

// 2 = bytes start with first,second; 1 = with first and nothing follows yet; 0 = no.
int pair_match(std::span<const std::uint8_t> bytes, std::size_t pos, std::uint8_t first, std::uint8_t second) {
  if (bytes[pos] != first) return 0;
  if (pos + 1 == bytes.size()) return 1;
  return bytes[pos + 1] == second ? 2 : 0;
}

}  // namespace

FrameReader::FrameReader() { buf_.reserve(8192); }

void FrameReader::feed(std::span<const std::uint8_t> bytes) {
  if (start_ > 0 && start_ == buf_.size()) {
    buf_.clear();
    start_ = 0;
  } else if (start_ > 4096) {
    buf_.erase(buf_.begin(), buf_.begin() + static_cast<std::ptrdiff_t>(start_));
    start_ = 0;
  }
  buf_.insert(buf_.end(), bytes.begin(), bytes.end());
}

void FrameReader::skip(std::size_t n) {
  if (n == 0) return;
  counters_.garbage_bytes += static_cast<std::int64_t>(n);
  counters_.resyncs += 1;
  start_ += n;
}

void FrameReader::consume(std::size_t n) { start_ += n; }

void FrameReader::clear() {
  counters_.garbage_bytes += static_cast<std::int64_t>(buffered());
  buf_.clear();
  start_ = 0;
}

std::size_t FrameReader::find_start(std::span<const std::uint8_t> avail, bool& partial) const {
  partial = false;
  for (std::size_t pos = 0; pos < avail.size(); ++pos) {
    int m = pair_match(avail, pos, kStreamStart0, kStreamStart1);
    if (expect_binary_) {
      m = std::max(m, pair_match(avail, pos, kBxStart0, kBxStart1));
      if (expect_extended_) m = std::max(m, pair_match(avail, pos, kExtendedStart0, kBxStart1));
      const int a = ascii_start_match(avail.subspan(pos));
      if (a == 2) return pos;
      if (a == 1 && pos + 8 > avail.size()) m = std::max(m, 1);  // keyword cut off at the end of the buffer
    } else if (printable(avail[pos])) {
      return pos;
    }
    if (m == 2) return pos;
    if (m == 1) {
      partial = true;
      return pos;
    }
  }
  return avail.size();
}

FrameReader::Step FrameReader::reply_at(std::span<const std::uint8_t> bytes, bool binary_allowed, bool extended_allowed,
                                        Frame& out, std::size_t& used) {
  used = 1;
  if (binary_allowed && bytes[0] == kBxStart0) {
    if (bytes.size() < kBxHeaderBytes) return Step::NeedMore;
    std::uint16_t length = 0;
    if (check_bx_header(bytes, length) != ParseError::None) {
      counters_.crc_errors += 1;  // header corrupt: its length cannot be trusted
      return Step::Corrupt;
    }
    const std::size_t total = kBxHeaderBytes + length + 2u;
    if (bytes.size() < total) return Step::NeedMore;
    out.kind = Frame::Kind::Binary;
    out.bytes = bytes.first(total);
    // Body CRC only; the full parse is the caller's.
    const std::uint8_t* body = bytes.data() + kBxHeaderBytes;
    out.crc_ok = crc16(std::span(body, length)) == u16(body + length);
    if (!out.crc_ok) counters_.crc_errors += 1;
    used = total;
    return Step::Done;
  }
  if (binary_allowed && extended_allowed && bytes[0] == kExtendedStart0) {
    if (bytes.size() < kExtendedHeaderBytes) return Step::NeedMore;
    const std::uint32_t length = u32(bytes.data() + 2);
    if (bytes[1] != kBxStart1 || length == 0 || length > kMaxExtendedReply) {
      counters_.crc_errors += 1;
      return Step::Corrupt;
    }
    const std::size_t total = kExtendedHeaderBytes + length;
    if (bytes.size() < total) return Step::NeedMore;
    out.kind = Frame::Kind::Extended;
    out.bytes = bytes.first(total);
    out.crc_ok = true;  // nothing to check: callers never take poses from these
    used = total;
    return Step::Done;
  }
  // ASCII reply up to CR.
  auto cr = std::find(bytes.begin(), bytes.end(), static_cast<std::uint8_t>('\r'));
  if (cr == bytes.end()) {
    if (bytes.size() <= kMaxAsciiReply) return Step::NeedMore;
    used = bytes.size();  // a run this long without CR is not a reply
    return Step::Corrupt;
  }
  const std::size_t len = static_cast<std::size_t>(cr - bytes.begin());
  out.kind = Frame::Kind::Ascii;
  out.bytes = bytes.first(len);
  std::string_view body;
  out.crc_ok = check_ascii_reply(out.text(), body) == ParseError::None;
  if (!out.crc_ok) counters_.crc_errors += 1;
  used = len + 1;
  return Step::Done;
}

FrameReader::Step FrameReader::stream_at(std::span<const std::uint8_t> bytes, Frame& out, std::size_t& used) {
  used = 1;
  if (bytes.size() < 4) return Step::NeedMore;
  const std::size_t id_length = u16(bytes.data() + 2);
  if (id_length == 0 || id_length > kMaxStreamId) {
    counters_.crc_errors += 1;
    return Step::Corrupt;
  }
  const std::size_t header = kStreamFixedBytes + id_length;
  if (bytes.size() < header) return Step::NeedMore;
  if (crc16(bytes.first(4 + id_length)) != u16(bytes.data() + 4 + id_length)) {
    counters_.crc_errors += 1;  // header corrupt: neither the id nor what follows is trusted
    return Step::Corrupt;
  }
  const auto inner = bytes.subspan(header);
  if (inner.empty()) return Step::NeedMore;
  const bool binary = inner[0] == kBxStart0 || inner[0] == kExtendedStart0;
  if (!binary && !printable(inner[0])) {
    counters_.crc_errors += 1;  // the header checked but no reply follows it
    used = header;
    return Step::Corrupt;
  }
  std::size_t inner_used = 0;
  const Step s = reply_at(inner, true, true, out, inner_used);
  if (s == Step::NeedMore) return s;
  if (s == Step::Corrupt) {
    used = header;  // drop the packet header; what follows is resynchronised
    return s;
  }
  out.stream_id = bytes.subspan(4, id_length);
  used = header + inner_used;
  return Step::Done;
}

bool FrameReader::next(Frame& out) {
  for (;;) {
    std::span<const std::uint8_t> avail(buf_.data() + start_, buf_.size() - start_);
    if (avail.empty()) return false;
    bool partial = false;
    const std::size_t pos = find_start(avail, partial);
    skip(pos);
    if (partial || pos == avail.size()) return false;
    avail = avail.subspan(pos);
    out.stream_id = {};
    std::size_t used = 0;
    const Step s = avail[0] == kStreamStart0 ? stream_at(avail, out, used)
                                             : reply_at(avail, expect_binary_, expect_binary_ && expect_extended_, out, used);
    if (s == Step::NeedMore) return false;
    if (s == Step::Corrupt) {
      skip(used);
      continue;
    }
    consume(used);
    return true;
  }
}

}  // namespace arnav::ndi
