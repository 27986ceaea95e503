#pragma once
// Command encoding (host -> device) and decoding (for the simulator and transcripts).
// Wire form: "CMD:params" + 4 uppercase hex CRC + CR; the CRC covers "CMD:params".
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace arnav::ndi {

// "CMD:params" + CRC + "\r".
std::string encode_command(std::string_view name, std::string_view params);

struct DecodedCommand {
  std::string_view name;    // "INIT", "BX", ...
  std::string_view params;  // after ':' (or ' ' in the space form), CRC removed
  bool has_crc = false;     // colon form carries a CRC; space form does not
  bool crc_ok = true;       // meaningful when has_crc
};
// Decodes one command line without its CR. nullopt when the line has no command name.
std::optional<DecodedCommand> decode_command(std::string_view line);

// COMM baud rate code letter ('0' 9600 .. '7' 1228739, 'A' 230400); nullopt if unsupported.
std::optional<char> baud_code(int baud);
std::optional<int> baud_from_code(char code);
// "COMM:" parameters for 8N1 without handshake at the given rate, e.g. "50000".
std::optional<std::string> comm_params(int baud);

// PVWR parameters for one 64-byte chunk: handle (2 hex) + address (4 hex) + 128 hex chars.
// Chunks shorter than 64 bytes are zero padded.
std::string pvwr_params(std::uint8_t handle, std::uint16_t address, std::span<const std::uint8_t> chunk);

std::string hex2(unsigned value);  // two uppercase hex digits

}  // namespace arnav::ndi
