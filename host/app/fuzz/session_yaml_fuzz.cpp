// libFuzzer target: the navigation session file (docs/overlay.md) on arbitrary text.
// Files it names resolve against a folder that does not exist, so they fail to open
// (with the file:line error); every failure must be a SessionError, never a crash.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/app/session_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    arnav::host::parse_session(text, "fuzz.session.yaml", "/nonexistent-arnav-fuzz");
  } catch (const arnav::host::SessionError&) {
  }
  return 0;
}
