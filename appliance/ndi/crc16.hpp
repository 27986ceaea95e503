#pragma once
// CRC-16/ARC as used by the NDI Combined API (reflected poly 0xA001, init 0, no xor out).
// Commands: CRC over letters, colon and parameters (not the CR). Replies: over all bytes
// before the 4 hex CRC digits. BX binary frames: over the 4 header bytes and over the body.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace arnav::ndi {

std::uint16_t crc16(std::span<const std::uint8_t> bytes, std::uint16_t crc = 0);
std::uint16_t crc16(std::string_view text, std::uint16_t crc = 0);

}  // namespace arnav::ndi
