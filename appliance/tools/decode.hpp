#pragma once
// `arnav-ndi decode`: splits raw reply bytes (as they came off the wire, replies
// concatenated) into replies and decodes each into a JSON object with every field.
// A reply's kind is inferred from its content (BX header, OKAY, RESET, ERRORxx,
// WARNING, then TX, PHSR, PHINF, PHRQ, VER shapes); anything else is "data" with its text.
#include <cstdint>
#include <span>
#include <vector>

#include <nlohmann/json.hpp>

namespace arnav::tools {

std::vector<nlohmann::json> decode_replies(std::span<const std::uint8_t> bytes);

}  // namespace arnav::tools
