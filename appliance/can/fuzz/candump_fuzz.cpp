// libFuzzer target: candump log lines and files. A line that parses formats back to a
// line that parses to the same record.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "appliance/can/candump_log.hpp"

using namespace arnav::can;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  LogRecord r;
  if (parse_log_line(text, r) == LogError::None && r.time_us < 100'000'000'000'000'000) {
    LogRecord again;
    if (parse_log_line(format_log_line(r), again) != LogError::None) __builtin_trap();
    if (!(again.frame == r.frame) || again.time_us != r.time_us || again.interface != r.interface) __builtin_trap();
  }
  CanFrame f;
  (void)parse_frame_text(text, f);
  std::istringstream in(text);
  LogReader reader(in, "fuzz.log");
  try {
    while (reader.next()) {
    }
  } catch (const LogFileError&) {
  }
  return 0;
}
