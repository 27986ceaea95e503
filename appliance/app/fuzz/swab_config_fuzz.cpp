// libFuzzer: the swab: section of the appliance configuration must turn any text into a
// configuration (or none) or a ConfigError, nothing else.
#include <cstddef>
#include <cstdint>
#include <string>

#include "appliance/app/config.hpp"
#include "appliance/app/swab.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    (void)arnav::app::parse_swab_config(text, "fuzz.yaml", {"pointer", "patient"}, {"pedal_swab"});
  } catch (const arnav::app::ConfigError&) {
  }
  return 0;
}
