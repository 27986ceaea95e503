#pragma once
// Names of the ERRORxx codes of the NDI Combined API (docs/ndi-capi.md).
#include <cstdint>
#include <string_view>

namespace arnav::ndi {

struct ErrorCodeInfo {
  std::string_view symbol;       // stable identifier, e.g. "INVALID_COMMAND"
  std::string_view description;  // human-readable
};

// Unknown codes give {"UNKNOWN_ERROR", "unknown error code"}.
ErrorCodeInfo error_code_info(std::uint8_t code);

}  // namespace arnav::ndi
