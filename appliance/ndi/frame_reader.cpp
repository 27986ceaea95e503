#include "appliance/ndi/frame_reader.hpp"

#include <algorithm>
#include <array>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/reply.hpp"

namespace arnav::ndi {
namespace {

constexpr std::array<std::string_view, 4> kAsciiStarts = {"ERROR", "WARNING", "RESET", "OKAY"};

bool printable(std::uint8_t b) { return (b >= 0x20 && b < 0x7F) || b == '\n'; }

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

bool FrameReader::next(Frame& out) {
  for (;;) {
    std::span<const std::uint8_t> avail(buf_.data() + start_, buf_.size() - start_);
    if (avail.empty()) return false;

    if (expect_binary_) {
      // Find the first position that can start a reply: C4 A5 or an ASCII keyword.
      std::size_t pos = 0;
      bool partial = false;
      for (; pos < avail.size(); ++pos) {
        if (avail[pos] == kBxStart0 && (pos + 1 == avail.size() || avail[pos + 1] == kBxStart1)) {
          partial = pos + 1 == avail.size();
          break;
        }
        int m = ascii_start_match(avail.subspan(pos));
        if (m == 2) break;
        if (m == 1 && pos + 8 > avail.size()) {  // keyword cut off at the end of the buffer
          partial = true;
          break;
        }
      }
      skip(pos);
      if (partial || pos == avail.size()) return false;
      avail = avail.subspan(pos);
      if (avail[0] == kBxStart0) {
        if (avail.size() < kBxHeaderBytes) return false;
        std::uint16_t length = 0;
        if (check_bx_header(avail, length) != ParseError::None) {
          counters_.crc_errors += 1;  // header corrupt: its length cannot be trusted
          skip(1);
          continue;
        }
        const std::size_t total = kBxHeaderBytes + length + 2u;
        if (avail.size() < total) return false;
        out.kind = Frame::Kind::Binary;
        out.bytes = avail.first(total);
        // Body CRC only; the full parse is the caller's.
        const std::uint8_t* body = avail.data() + kBxHeaderBytes;
        const auto want = static_cast<std::uint16_t>(body[length] | (body[length + 1] << 8));
        out.crc_ok = crc16(std::span(body, length)) == want;
        if (!out.crc_ok) counters_.crc_errors += 1;
        consume(total);
        return true;
      }
    } else {
      // ASCII: skip bytes that can never be part of a reply.
      std::size_t pos = 0;
      while (pos < avail.size() && !printable(avail[pos])) ++pos;
      skip(pos);
      avail = avail.subspan(pos);
      if (avail.empty()) return false;
    }

    // ASCII reply up to CR.
    auto cr = std::find(avail.begin(), avail.end(), static_cast<std::uint8_t>('\r'));
    if (cr == avail.end()) {
      if (avail.size() > kMaxAsciiReply) {
        skip(avail.size());
        continue;
      }
      return false;
    }
    const std::size_t len = static_cast<std::size_t>(cr - avail.begin());
    out.kind = Frame::Kind::Ascii;
    out.bytes = avail.first(len);
    std::string_view body;
    out.crc_ok = check_ascii_reply(out.text(), body) == ParseError::None;
    if (!out.crc_ok) counters_.crc_errors += 1;
    consume(len + 1);
    return true;
  }
}

}  // namespace arnav::ndi
