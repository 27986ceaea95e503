#pragma once
// Device-side replies of the simulated Polaris. The wire encoders themselves are the NDI
// driver's (appliance/ndi: encode_reply, format_tx_body, encode_bx), so the simulator and
// the appliance cannot drift apart on the format; this file only adapts them to the
// simulator's byte buffers and adds the small fixed-width fields of PHSR/PHINF replies.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "appliance/ndi/tracking.hpp"

namespace arnav::hil {

using Bytes = std::vector<std::uint8_t>;

// Reply options of TX/BX understood by the simulator.
inline constexpr std::uint16_t kReplyTransforms = 0x0001;
inline constexpr std::uint16_t kReplyOutOfVolume = 0x0800;

// "<text><CRC hex>\r"
Bytes text_reply(std::string_view text);
Bytes okay_reply();
Bytes error_reply(std::uint8_t code);
Bytes reset_reply();
// TX (text) or BX (binary) reply of one frame.
Bytes tracking_reply(const ndi::TrackingReply& frame, bool binary);

// `digits` uppercase hex digits.
std::string hex_field(std::uint32_t value, int digits);

}  // namespace arnav::hil
