#include <gtest/gtest.h>

#include <vector>

#include "appliance/ndi/crc16.hpp"

namespace arnav::ndi {
namespace {

TEST(Crc16, CheckValue) { EXPECT_EQ(crc16("123456789"), 0xBB3D); }

// Pairs seen in real Polaris traffic (docs/ndi-capi.md).
TEST(Crc16, KnownCommandAndReplyPairs) {
  EXPECT_EQ(crc16("INIT:"), 0xE3A5);
  EXPECT_EQ(crc16("OKAY"), 0xA896);
  EXPECT_EQ(crc16("RESET"), 0xBE6F);
  EXPECT_EQ(crc16("VER:0"), 0x65EE);
  EXPECT_EQ(crc16("TSTART:"), 0x5423);
  EXPECT_EQ(crc16("TSTOP:"), 0x2C14);
  EXPECT_EQ(crc16("COMM:50000"), 0x0048);
  EXPECT_EQ(crc16("TX:0001"), 0x031A);
  EXPECT_EQ(crc16("BX:0001"), 0xC26D);
  EXPECT_EQ(crc16("PHSR:02"), 0xE17E);
  EXPECT_EQ(crc16("WARNING"), 0x7423);
  EXPECT_EQ(crc16("01"), 0xD4D5);
}

// The sliced implementation against a bit-by-bit reference, for every length 0..300
// (covers the 8-byte steps and every tail length) and several start values.
TEST(Crc16, SlicedEqualsBitwiseReference) {
  auto reference = [](const std::vector<std::uint8_t>& v, std::uint16_t crc) {
    for (std::uint8_t b : v) {
      crc ^= b;
      for (int i = 0; i < 8; ++i) crc = (crc & 1u) ? static_cast<std::uint16_t>((crc >> 1) ^ 0xA001u) : static_cast<std::uint16_t>(crc >> 1);
    }
    return crc;
  };
  std::vector<std::uint8_t> v;
  std::uint32_t x = 12345;
  for (int len = 0; len <= 300; ++len) {
    for (std::uint16_t start : {0x0000, 0xFFFF, 0x1234}) EXPECT_EQ(crc16(v, start), reference(v, start)) << "length " << len;
    x = x * 1103515245u + 12345u;
    v.push_back(static_cast<std::uint8_t>(x >> 16));
  }
}

TEST(Crc16, IncrementalEqualsWhole) {
  EXPECT_EQ(crc16("56789", crc16("1234")), crc16("123456789"));
}

}  // namespace
}  // namespace arnav::ndi
