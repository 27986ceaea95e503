#pragma once
// Streaming reply reader: bytes go in as they come off the wire (any chunking), whole
// replies come out. Every reply kind of the Combined API (docs/ndi-capi.md):
//  - ASCII replies, ending at CR (their CRC is checked here);
//  - binary replies C4 A5 (BX, BX2), whose header CRC must check before the length field
//    is trusted, then the body CRC;
//  - extended binary replies C8 A5 with a u32 length and no CRC (long replies such as
//    images; at most kMaxExtendedReply bytes; never a source of poses). With no CRC to
//    check, a C8 A5 in line noise would make the reader wait for up to 1 MiB, so they are
//    only recognised inside a stream packet (whose header CRC checked) or when a caller
//    that asked for one says so (set_expect_extended);
//  - stream packets D4 B5, u16 id length, id, u16 CRC of the bytes before it, then one
//    ordinary reply of any kind above: pushed by the device after STREAM (TCP devices);
//    the id comes out in Frame::stream_id.
// Bytes before a recognisable reply start are skipped and counted (resync). A frame whose
// CRC fails is still returned (crc_ok = false) so the caller can count it and stop
// waiting, but its contents must never be used.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace arnav::ndi {

struct ReaderCounters {
  std::int64_t garbage_bytes = 0;  // bytes skipped while looking for a reply start
  std::int64_t resyncs = 0;        // times bytes were skipped
  std::int64_t crc_errors = 0;     // frames (or BX / stream headers) whose CRC failed
};

inline constexpr std::uint8_t kStreamStart0 = 0xD4;
inline constexpr std::uint8_t kStreamStart1 = 0xB5;
inline constexpr std::uint8_t kExtendedStart0 = 0xC8;
inline constexpr std::size_t kMaxStreamId = 64;
inline constexpr std::size_t kMaxExtendedReply = 1u << 20;

struct Frame {
  enum class Kind : std::uint8_t { Binary, Ascii, Extended };
  Kind kind = Kind::Ascii;
  bool crc_ok = false;
  // Binary: the whole frame, header to body CRC. Extended: header and body. Ascii: the
  // reply without its CR. Valid until the next call to feed(), next() or clear().
  std::span<const std::uint8_t> bytes;
  // Non-empty for a reply that came in a stream packet: the stream's id.
  std::span<const std::uint8_t> stream_id;

  std::string_view text() const { return {reinterpret_cast<const char*>(bytes.data()), bytes.size()}; }
  std::string_view stream() const { return {reinterpret_cast<const char*>(stream_id.data()), stream_id.size()}; }
  bool streamed() const { return !stream_id.empty(); }
};

class FrameReader {
 public:
  // Longest ASCII reply accepted; longer runs without CR are counted as garbage.
  static constexpr std::size_t kMaxAsciiReply = 4096;

  FrameReader();

  // When binary replies are expected (BX polling, streaming), ASCII is only accepted if it
  // starts like a reply the device sends instead (ERROR, WARNING, RESET, OKAY); anything
  // else before a binary header is garbage. Otherwise every printable run ending in CR is
  // a reply, and binary replies are only recognised inside stream packets.
  void set_expect_binary(bool expect) { expect_binary_ = expect; }
  bool expect_binary() const { return expect_binary_; }
  // Whether a bare C8 A5 starts an extended reply (only while binary replies are expected).
  void set_expect_extended(bool expect) { expect_extended_ = expect; }

  void feed(std::span<const std::uint8_t> bytes);
  // Next complete reply, or false when more bytes are needed.
  bool next(Frame& out);
  // Drops buffered bytes (counted as garbage), e.g. after a timeout or a baud change.
  void clear();
  std::size_t buffered() const { return buf_.size() - start_; }

  const ReaderCounters& counters() const { return counters_; }

 private:
  enum class Step : std::uint8_t { NeedMore, Done, Corrupt };
  // A reply (not a stream packet) at the start of bytes; on Done sets out and used.
  Step reply_at(std::span<const std::uint8_t> bytes, bool binary_allowed, bool extended_allowed, Frame& out, std::size_t& used);
  Step stream_at(std::span<const std::uint8_t> bytes, Frame& out, std::size_t& used);
  std::size_t find_start(std::span<const std::uint8_t> avail, bool& partial) const;
  void skip(std::size_t n);
  void consume(std::size_t n);

  std::vector<std::uint8_t> buf_;
  std::size_t start_ = 0;
  bool expect_binary_ = false;
  bool expect_extended_ = false;
  ReaderCounters counters_;
};

}  // namespace arnav::ndi
