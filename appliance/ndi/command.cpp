#include "appliance/ndi/command.hpp"

#include <cstdio>

#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/hex.hpp"

namespace arnav::ndi {

std::string hex2(unsigned value) {
  char buf[3];
  std::snprintf(buf, sizeof buf, "%02X", value & 0xFFu);
  return std::string(buf, 2);
}

std::string encode_command(std::string_view name, std::string_view params) {
  std::string out;
  out.reserve(name.size() + params.size() + 6);
  out.append(name).push_back(':');
  out.append(params);
  char crc[5];
  std::snprintf(crc, sizeof crc, "%04X", crc16(out));
  out.append(crc, 4).push_back('\r');
  return out;
}

std::optional<DecodedCommand> decode_command(std::string_view line) {
  std::size_t i = 0;
  while (i < line.size() && ((line[i] >= 'A' && line[i] <= 'Z') || (line[i] >= '0' && line[i] <= '9'))) ++i;
  if (i == 0) return std::nullopt;
  DecodedCommand c;
  c.name = line.substr(0, i);
  if (i == line.size()) return c;  // bare name, no separator
  if (line[i] == ' ') {
    c.params = line.substr(i + 1);
    return c;
  }
  if (line[i] != ':') return std::nullopt;
  std::string_view rest = line.substr(i + 1);
  if (rest.size() < 4) {
    c.has_crc = true;
    c.crc_ok = false;
    c.params = rest;
    return c;
  }
  c.has_crc = true;
  c.params = rest.substr(0, rest.size() - 4);
  auto crc = parse_hex<std::uint16_t>(rest.substr(rest.size() - 4));
  c.crc_ok = crc && *crc == crc16(line.substr(0, line.size() - 4));
  return c;
}

std::optional<char> baud_code(int baud) {
  switch (baud) {
    case 9600: return '0';
    case 14400: return '1';
    case 19200: return '2';
    case 38400: return '3';
    case 57600: return '4';
    case 115200: return '5';
    case 921600: return '6';
    case 1228739: return '7';
    case 230400: return 'A';
    default: return std::nullopt;
  }
}

std::optional<int> baud_from_code(char code) {
  switch (code) {
    case '0': return 9600;
    case '1': return 14400;
    case '2': return 19200;
    case '3': return 38400;
    case '4': return 57600;
    case '5': return 115200;
    case '6': return 921600;
    case '7': return 1228739;
    case 'A': return 230400;
    default: return std::nullopt;
  }
}

std::optional<std::string> comm_params(int baud) {
  auto code = baud_code(baud);
  if (!code) return std::nullopt;
  return std::string(1, *code) + "0000";
}

std::string pvwr_params(std::uint8_t handle, std::uint16_t address, std::span<const std::uint8_t> chunk) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  std::string out = hex2(handle);
  char addr[5];
  std::snprintf(addr, sizeof addr, "%04X", address);
  out.append(addr, 4);
  for (std::size_t i = 0; i < 64; ++i) {
    std::uint8_t b = i < chunk.size() ? chunk[i] : 0;
    out.push_back(kDigits[b >> 4]);
    out.push_back(kDigits[b & 0xF]);
  }
  return out;
}

}  // namespace arnav::ndi
