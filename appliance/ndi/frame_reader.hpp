#pragma once
// Streaming reply reader: bytes go in as they come off the wire (any chunking), whole
// replies come out. Binary BX frames are found by their C4 A5 header whose CRC must
// check before the length field is trusted; ASCII replies end at CR. Bytes before a
// recognisable reply start are skipped and counted (resync). A frame whose CRC fails is
// still returned (crc_ok = false) so the caller can count it and stop waiting, but its
// contents must never be used.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace arnav::ndi {

struct ReaderCounters {
  std::int64_t garbage_bytes = 0;  // bytes skipped while looking for a reply start
  std::int64_t resyncs = 0;        // times bytes were skipped
  std::int64_t crc_errors = 0;     // frames (or BX headers) whose CRC failed
};

struct Frame {
  enum class Kind : std::uint8_t { Binary, Ascii };
  Kind kind = Kind::Ascii;
  bool crc_ok = false;
  // Binary: the whole frame, header to body CRC. Ascii: the reply without its CR.
  // Valid until the next call to feed(), next() or clear().
  std::span<const std::uint8_t> bytes;

  std::string_view text() const { return {reinterpret_cast<const char*>(bytes.data()), bytes.size()}; }
};

class FrameReader {
 public:
  // Longest ASCII reply accepted; longer runs without CR are counted as garbage.
  static constexpr std::size_t kMaxAsciiReply = 4096;

  FrameReader();

  // When binary replies are expected (BX polling), ASCII is only accepted if it starts
  // like a reply the device sends instead (ERROR, WARNING, RESET, OKAY); anything else
  // before a BX header is garbage. Otherwise every printable run ending in CR is a reply.
  void set_expect_binary(bool expect) { expect_binary_ = expect; }
  bool expect_binary() const { return expect_binary_; }

  void feed(std::span<const std::uint8_t> bytes);
  // Next complete reply, or false when more bytes are needed.
  bool next(Frame& out);
  // Drops buffered bytes (counted as garbage), e.g. after a timeout or a baud change.
  void clear();
  std::size_t buffered() const { return buf_.size() - start_; }

  const ReaderCounters& counters() const { return counters_; }

 private:
  void skip(std::size_t n);
  void consume(std::size_t n);

  std::vector<std::uint8_t> buf_;
  std::size_t start_ = 0;
  bool expect_binary_ = false;
  ReaderCounters counters_;
};

}  // namespace arnav::ndi
