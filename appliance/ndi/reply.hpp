#pragma once
// ASCII replies (device -> host): CRC check, classification, and the data replies the
// driver uses (VER, PHRQ, PHSR, PHINF, TX). Encoders are here too: the bench simulator
// and the tests build replies with them.
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "appliance/ndi/parse_error.hpp"
#include "appliance/ndi/tracking.hpp"

namespace arnav::ndi {

// line: one reply without its CR. On success body is everything before the 4 CRC digits.
ParseError check_ascii_reply(std::string_view line, std::string_view& body);

enum class AsciiKind : std::uint8_t { Okay, Reset, Error, Warning, Data };
std::string_view to_string(AsciiKind k);

struct AsciiReply {
  AsciiKind kind = AsciiKind::Data;
  std::string_view body;        // CRC removed
  std::uint8_t error_code = 0;  // Error; Warning when the firmware appends a code
  bool has_code = false;
};
// CRC check plus classification (OKAY, RESET, ERRORxx, WARNING[xx], anything else Data).
ParseError parse_ascii_reply(std::string_view line, AsciiReply& out);

// VER:n reply: LF-separated text.
struct VersionInfo {
  std::vector<std::string> lines;
  std::string firmware;       // first line, e.g. "Polaris Control Firmware"
  std::string serial_number;  // text after "S/N:" when a line carries it
};
ParseError parse_ver(std::string_view body, VersionInfo& out);

// PHRQ reply: the new port handle (2 hex).
ParseError parse_phrq(std::string_view body, std::uint8_t& handle);

// PHSR reply: 2-hex count, then per handle 2-hex handle + 3-hex status.
struct PhsrEntry {
  std::uint8_t handle = 0;
  std::uint16_t status = 0;
};
ParseError parse_phsr(std::string_view body, std::vector<PhsrEntry>& out);

// PHINF option 0001 (basic): type(8) manufacturer(12) revision(3) serial(8) status(2).
struct PortHandleInfo {
  std::string tool_type;
  std::string manufacturer;
  std::string revision;
  std::string serial_number;
  std::uint8_t port_status = 0;
};
ParseError parse_phinf_basic(std::string_view body, PortHandleInfo& out);

// One 51-character transform: q0 qx qy qz (sign+5 digits, /1e4), tx ty tz (sign+6
// digits, /100 mm), error (sign+5 digits, /1e4 mm). Fills the pose fields of out.
inline constexpr std::size_t kTransformChars = 51;
ParseError parse_transform(std::string_view s, HandleRecord& out);

// TX reply body (CRC removed).
ParseError parse_tx(std::string_view body, TrackingReply& out);

// ---- encoders -----------------------------------------------------------------------
// body + 4 hex CRC + CR.
std::string encode_reply(std::string_view body);
std::string format_transform(const HandleRecord& r);
std::string format_tx_body(const TrackingReply& reply);

}  // namespace arnav::ndi
