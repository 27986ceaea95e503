// libFuzzer target: the transcript reader and the IGSTK log importer on arbitrary text.
// Either may throw TranscriptError (a clear message); nothing else is allowed.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "appliance/ndi/transcript.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    std::istringstream in(text);
    const auto records = arnav::ndi::read_transcript(in, "fuzz");
    // Whatever was read writes back and reads again to the same records.
    std::stringstream out;
    arnav::ndi::write_transcript(out, records);
    const auto again = arnav::ndi::read_transcript(out, "fuzz-again");
    if (again.size() != records.size()) __builtin_trap();
    for (std::size_t i = 0; i < records.size(); ++i)
      if (again[i].bytes != records[i].bytes || again[i].t_us != records[i].t_us || again[i].value != records[i].value)
        __builtin_trap();
  } catch (const arnav::ndi::TranscriptError&) {
  }
  try {
    std::istringstream in(text);
    (void)arnav::ndi::import_igstk_log(in, "fuzz");
  } catch (const arnav::ndi::TranscriptError&) {
  }
  return 0;
}
