#pragma once
// BX2 tracking reply (Combined API revision G.003+): the ordinary binary header (C4 A5,
// u16 body length, u16 header CRC), a General Binary Format (GBF) body, u16 body CRC.
// Little endian throughout. GBF as far as the driver reads it:
//   container: u16 version, u16 component count, components
//   component: u16 type, u32 size (bytes, this 12-byte header included), u16 item option,
//              u32 item count, items
//   type 0x0001 frame; item: u8 frame type, u8 sequence index, u16 frame status,
//              u32 frame number, u32 timestamp seconds, u32 timestamp nanoseconds,
//              then a nested container with the frame's data components
//   type 0x0002 6D; item: u16 port handle, u16 status (bits 0-7 transform status,
//              bit 8 missing), and unless missing 8 x float32 q0 qx qy qz tx ty tz error
// Other component types are skipped by their size. Facts gathered from public sources
// (docs/ndi-capi.md, "BX2 and streaming"); verify against a device.
#include <cstdint>
#include <span>
#include <vector>

#include "appliance/ndi/parse_error.hpp"
#include "appliance/ndi/tracking.hpp"

namespace arnav::ndi {

inline constexpr std::uint16_t kGbfFrame = 0x0001;
inline constexpr std::uint16_t kGbf6d = 0x0002;
inline constexpr std::uint16_t kGbfSystemAlert = 0x0012;
inline constexpr std::uint16_t kGbfVersion = 0x0001;

// 6D item status: bits 0-7 transform status, bit 8 transform missing.
inline constexpr std::uint16_t kBx2Missing = 0x0100;
inline constexpr std::uint8_t kBx2PartiallyOutOfVolume = 0x03;
inline constexpr std::uint8_t kBx2OutOfVolume = 0x09;

// Parses one whole BX2 frame (header + GBF body + body CRC) without allocating. The first
// frame item's number and timestamp become the reply's (has_frame, has_device_time); every
// 6D item becomes a handle record (Valid or Missing, with that frame number and port status
// bits derived from the transform status). With AlreadyChecked only the CRCs are skipped.
ParseError parse_bx2(std::span<const std::uint8_t> frame, TrackingReply& out, bool crc_already_checked = false);

// Appends the BX2 frame for reply (simulator, tests, fuzz seeds): one frame item carrying
// reply.frame and reply.device_time_ns, one 6D component with the Valid and Missing
// records (Disabled and Unoccupied records are not sent: BX2 reports enabled tools only).
void encode_bx2(const TrackingReply& reply, std::vector<std::uint8_t>& out);

}  // namespace arnav::ndi
