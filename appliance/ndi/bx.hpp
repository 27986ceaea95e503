#pragma once
// BX binary tracking reply. Layout (little endian):
//   header: C4 A5, u16 body length, u16 CRC of the 4 bytes before it
//   body:   u8 count; per handle: u8 handle, u8 status (01 valid, 02 missing, 04 disabled);
//           valid: 8 x float32 q0 qx qy qz tx ty tz error; valid/missing: u32 port status,
//           u32 frame number; then u16 system status
//   u16 CRC of the body
#include <cstdint>
#include <span>
#include <vector>

#include "appliance/ndi/parse_error.hpp"
#include "appliance/ndi/tracking.hpp"

namespace arnav::ndi {

inline constexpr std::uint8_t kBxStart0 = 0xC4;
inline constexpr std::uint8_t kBxStart1 = 0xA5;
inline constexpr std::size_t kBxHeaderBytes = 6;
// Largest body the driver accepts (32 valid handles need 1 + 32*42 + 2 bytes).
inline constexpr std::size_t kBxMaxBody = 2048;

inline constexpr std::uint8_t kBxValid = 0x01;
inline constexpr std::uint8_t kBxMissing = 0x02;
inline constexpr std::uint8_t kBxDisabled = 0x04;

// Checks start bytes and header CRC of the first 6 bytes; sets body_length.
ParseError check_bx_header(std::span<const std::uint8_t> header, std::uint16_t& body_length);

enum class BxCrc : std::uint8_t {
  Check,           // verify header and body CRC
  AlreadyChecked,  // the FrameReader verified both (Frame::crc_ok): skip the second pass
};

// Parses one whole frame (header + body + body CRC). Allocation-free. With
// AlreadyChecked the start bytes and lengths are still validated, only the CRCs are not.
ParseError parse_bx(std::span<const std::uint8_t> frame, TrackingReply& out, BxCrc crc = BxCrc::Check);

// Appends the frame for reply to out (simulator, tests, benchmark).
void encode_bx(const TrackingReply& reply, std::vector<std::uint8_t>& out);

}  // namespace arnav::ndi
