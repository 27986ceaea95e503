#pragma once
// candump log files (`candump -l`, read by canplayer): one frame per line,
// "(1700000000.123456) can0 123#DEADBEEF". Extended ids have 8 hex digits, remote frames
// end "#R" (optionally "#R<dlc>"), error frames set 0x20000000 in the id. CAN FD ("##")
// is refused: the appliance speaks classic CAN only.
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

#include "appliance/can/can_frame.hpp"

namespace arnav::can {

struct LogRecord {
  std::int64_t time_us = 0;  // the log's wall-clock time, microseconds since the epoch
  std::string interface;
  CanFrame frame;
};

enum class LogError : std::uint8_t { None, NoTimestamp, BadTimestamp, NoInterface, BadId, BadData, CanFd };
std::string_view to_string(LogError e);

// Parses one line (without the newline). Never throws.
LogError parse_log_line(std::string_view line, LogRecord& out);
// Parses the compact frame notation alone ("123#DEADBEEF"). Never throws.
LogError parse_frame_text(std::string_view text, CanFrame& out);
// "(1700000000.123456) can0 123#DEADBEEF"
std::string format_log_line(const LogRecord& r);

class LogFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Reads a log file line by line. Empty lines and lines starting with '#' are skipped; any
// other bad line throws LogFileError "<file>:<line>: <what>: '<line>'".
class LogReader {
 public:
  LogReader(std::istream& in, std::string source) : in_(in), source_(std::move(source)) {}
  std::optional<LogRecord> next();
  int line() const { return line_; }

 private:
  std::istream& in_;
  std::string source_;
  int line_ = 0;
};

}  // namespace arnav::can
