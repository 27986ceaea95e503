// libFuzzer target: arnav-ndi decode on arbitrary bytes (all reply kinds, JSON output).
#include <cstddef>
#include <cstdint>

#include "appliance/tools/decode.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  for (const auto& j : arnav::tools::decode_replies(std::span(data, size))) (void)j.dump();
  return 0;
}
