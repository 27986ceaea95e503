// libFuzzer: the board layout parser must either return a valid layout or throw
// CalibError; a parsed layout must survive a write/parse round trip.
#include <cstddef>
#include <cstdint>
#include <string>

#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/calib_error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const auto layout = arnav::calib::parse_board_layout(text, "fuzz");
    const auto again = arnav::calib::parse_board_layout(arnav::calib::format_board_layout(layout), "fuzz2");
    if (again.tags.size() != layout.tags.size()) __builtin_trap();
  } catch (const arnav::calib::CalibError&) {
  }
  return 0;
}
