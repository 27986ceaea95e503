#pragma once
// slcan (the Lawicel serial-line CAN protocol of common USB-CAN adapters): command
// encoders and a streaming reader for what the adapter sends back.
//
// Adapter -> host: CR (0x0D) = OK, BEL (0x07) = error, "tIIIL<data>" / "TIIIIIIIIL<data>"
// standard / extended data frames, "rIIIL" / "RIIIIIIIIL" remote frames, "Fxx" status
// flags, "Vhhss" version, "Nxxxx" serial number, "z" / "Z" transmit acknowledged, each
// line ending in CR. The reader takes bytes in any chunking and resynchronises the way the
// NDI reader does: a line with a byte that is not printable ASCII, a line longer than any
// valid one, or a line whose length disagrees with its DLC is dropped and counted; a frame
// start letter (t T r R never occur in hex) inside a bad line restarts parsing there, so a
// lost CR costs no frame and a lost character costs exactly one.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "appliance/can/can_frame.hpp"

namespace arnav::can::slcan {

// "S0".."S8" bit rates; nullopt for a rate slcan has no code for.
std::optional<int> bitrate_code(int bitrate);
inline constexpr std::array<int, 9> kBitrates = {10000, 20000, 50000, 100000, 125000, 250000, 500000, 800000, 1000000};

std::string bitrate_command(int code);  // "S6\r"
inline constexpr std::string_view kOpen = "O\r";
inline constexpr std::string_view kClose = "C\r";
inline constexpr std::string_view kStatus = "F\r";
inline constexpr std::string_view kVersion = "V\r";
// "t1232AABB\r" etc. Error frames cannot be sent over slcan: returns "".
std::string encode_frame(const CanFrame& f);

// Status flags of the "F" reply (Lawicel bit meanings).
namespace status {
inline constexpr std::uint8_t kRxFifoFull = 0x01;
inline constexpr std::uint8_t kTxFifoFull = 0x02;
inline constexpr std::uint8_t kErrorWarning = 0x04;
inline constexpr std::uint8_t kDataOverrun = 0x08;
inline constexpr std::uint8_t kErrorPassive = 0x20;
inline constexpr std::uint8_t kArbitrationLost = 0x40;
inline constexpr std::uint8_t kBusError = 0x80;
}  // namespace status

struct Message {
  enum class Kind : std::uint8_t { Frame, Ok, Error, Status, Version, Serial, TxAck };
  Kind kind = Kind::Ok;
  CanFrame frame;              // Kind::Frame
  std::uint8_t flags = 0;      // Kind::Status
  std::array<char, 4> text{};  // Kind::Version / Serial: the four characters
  std::optional<std::uint16_t> timestamp_ms;  // frames, when timestamps are enabled
};

struct ReaderCounters {
  std::int64_t frames = 0;
  std::int64_t malformed = 0;      // lines dropped (bad length, bad hex, unknown letter)
  std::int64_t garbage_bytes = 0;  // bytes dropped while resynchronising
  std::int64_t resyncs = 0;        // times bytes were dropped
  std::int64_t errors = 0;         // BEL replies
};

class Reader {
 public:
  // Longest valid line: "T" + 8 id + dlc + 16 data + 4 timestamp.
  static constexpr std::size_t kMaxLine = 30;

  Reader();
  // Adapters in timestamp mode (Z1) append 4 hex digits (ms) to each frame. Off by default:
  // with it on, a frame that lost 4 characters can no longer be told from one with a stamp.
  void set_timestamps(bool on) { timestamps_ = on; }

  void feed(std::span<const std::uint8_t> bytes);
  void feed(std::string_view text) { feed(std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size())); }
  // Next complete message, or false when more bytes are needed.
  bool next(Message& out);
  void clear();  // drops buffered bytes (counted as garbage)
  std::size_t buffered() const { return line_len_ + (buf_.size() - start_) + pending_.size() - pending_next_; }
  const ReaderCounters& counters() const { return counters_; }

 private:
  void drop(std::size_t n);
  // terminated: the last segment is complete (a CR or a frame start letter follows it).
  void parse_line(std::string_view line, bool terminated, bool has_cr);
  bool parse_one(std::string_view seg, Message& m) const;

  std::vector<std::uint8_t> buf_;
  std::size_t start_ = 0;
  std::array<char, kMaxLine + 1> line_{};
  std::size_t line_len_ = 0;
  std::vector<Message> pending_;  // messages found in the last line (a lost CR can give two)
  std::size_t pending_next_ = 0;
  bool timestamps_ = false;
  ReaderCounters counters_;
};

}  // namespace arnav::can::slcan
