#include "appliance/ndi/crc16.hpp"

#include <array>

namespace arnav::ndi {
namespace {

// Slicing-by-8: table k gives the CRC contribution of a byte followed by k zero bytes,
// so eight bytes are folded per step instead of one (the byte-wise loop is bound by the
// latency of its dependency chain; BX bodies are ~270 bytes per frame).
using Tables = std::array<std::array<std::uint16_t, 256>, 8>;

constexpr Tables make_tables() {
  Tables t{};
  for (unsigned i = 0; i < 256; ++i) {
    std::uint16_t c = static_cast<std::uint16_t>(i);
    for (int bit = 0; bit < 8; ++bit) c = (c & 1u) ? static_cast<std::uint16_t>((c >> 1) ^ 0xA001u) : static_cast<std::uint16_t>(c >> 1);
    t[0][i] = c;
  }
  for (std::size_t k = 1; k < 8; ++k)
    for (unsigned i = 0; i < 256; ++i)
      t[k][i] = static_cast<std::uint16_t>((t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xFFu]);
  return t;
}
constexpr Tables kTables = make_tables();

}  // namespace

std::uint16_t crc16(std::span<const std::uint8_t> bytes, std::uint16_t crc) {
  const std::uint8_t* p = bytes.data();
  std::size_t n = bytes.size();
  while (n >= 8) {
    crc = static_cast<std::uint16_t>(
        kTables[7][(p[0] ^ crc) & 0xFFu] ^ kTables[6][(p[1] ^ (crc >> 8)) & 0xFFu] ^ kTables[5][p[2]] ^
        kTables[4][p[3]] ^ kTables[3][p[4]] ^ kTables[2][p[5]] ^ kTables[1][p[6]] ^ kTables[0][p[7]]);
    p += 8;
    n -= 8;
  }
  while (n-- > 0) crc = static_cast<std::uint16_t>((crc >> 8) ^ kTables[0][(crc ^ *p++) & 0xFFu]);
  return crc;
}

std::uint16_t crc16(std::string_view text, std::uint16_t crc) {
  return crc16(std::span(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()), crc);
}

}  // namespace arnav::ndi
