#include <gtest/gtest.h>

#include <cstring>

#include "appliance/ndi/crc16.hpp"
#include "hil_tests/polaris_sim/reply_encoder.hpp"

namespace arnav::hil {
namespace {

std::string str(const Bytes& b) { return std::string(b.begin(), b.end()); }

TEST(ReplyEncoder, TextRepliesCarryTheCrcSeenOnRealDevices) {
  EXPECT_EQ(str(okay_reply()), "OKAYA896\r");
  EXPECT_EQ(str(reset_reply()), "RESETBE6F\r");
  EXPECT_EQ(str(text_reply("WARNING")), "WARNING7423\r");
  EXPECT_EQ(str(text_reply("01")), "01D4D5\r");
  const std::string err = str(error_reply(0x0C));
  EXPECT_EQ(err.substr(0, 7), "ERROR0C");
  EXPECT_EQ(err.substr(7, 4), hex_field(ndi::crc16("ERROR0C"), 4));
}

TEST(ReplyEncoder, TxFieldsMatchTheRealExample) {
  // Real fields from ndi-capi.md: q=(0.7066,0.7050,-0.0372,-0.0462), t=(-240.11,64.70,-1564.67),
  // error 0.1855 mm, port status 0x31, frame 445.
  HandleReport h;
  h.handle = 0x0A;
  h.kind = HandleReport::Kind::kValid;
  h.q_NdiTool = Eigen::Quaterniond(0.7066, 0.7050, -0.0372, -0.0462);
  h.p_NdiTool_mm = Eigen::Vector3d(-240.11, 64.70, -1564.67);
  h.rms_error_mm = 0.1855;
  h.port_status = 0x31;
  h.frame_number = 445;
  const std::string s = str(tx_reply({h}, 0));
  const std::string expect_body = "010A+07066+07050-00372-00462-024011+006470-156467+0185500000031000001BD\n0000";
  ASSERT_EQ(s.size(), expect_body.size() + 5);
  EXPECT_EQ(s.substr(0, expect_body.size()), expect_body);
  EXPECT_EQ(s.substr(expect_body.size(), 4), hex_field(ndi::crc16(expect_body), 4));
  EXPECT_EQ(s.back(), '\r');
  // 51-character transform field.
  EXPECT_EQ(std::string("+07066+07050-00372-00462-024011+006470-156467+01855").size(), 51u);
}

TEST(ReplyEncoder, TxMissingAndDisabled) {
  HandleReport m;
  m.handle = 0x0B;
  m.kind = HandleReport::Kind::kMissing;
  m.port_status = 0x71;
  m.frame_number = 0x1234;
  HandleReport d;
  d.handle = 0x0C;
  d.kind = HandleReport::Kind::kDisabled;
  const std::string s = str(tx_reply({m, d}, 0x0001));
  EXPECT_EQ(s.substr(0, s.size() - 5), "020BMISSING0000007100001234\n0CDISABLED\n0001");
}

TEST(ReplyEncoder, SignedFieldsRoundAndSaturate) {
  EXPECT_EQ(signed_field(1.0, 1e4, 5), "+10000");
  EXPECT_EQ(signed_field(-0.00004, 1e4, 5), "+00000");
  EXPECT_EQ(signed_field(-0.00006, 1e4, 5), "-00001");
  EXPECT_EQ(signed_field(123456.0, 100.0, 6), "+999999");
}

TEST(ReplyEncoder, BxFrameLayoutAndCrcs) {
  HandleReport v;
  v.handle = 0x0A;
  v.kind = HandleReport::Kind::kValid;
  v.q_NdiTool = Eigen::Quaterniond(1, 0, 0, 0);
  v.p_NdiTool_mm = Eigen::Vector3d(1.5, -2.25, -1500.0);
  v.rms_error_mm = 0.25;
  v.port_status = 0x31;
  v.frame_number = 77;
  HandleReport m;
  m.handle = 0x0B;
  m.kind = HandleReport::Kind::kMissing;
  m.port_status = 0x31;
  m.frame_number = 77;
  const Bytes b = bx_reply({v, m}, 0);
  ASSERT_GE(b.size(), 8u);
  EXPECT_EQ(b[0], 0xC4);
  EXPECT_EQ(b[1], 0xA5);
  const std::size_t len = b[2] | (b[3] << 8);
  EXPECT_EQ(len, 1u + (2 + 32 + 8) + (2 + 8) + 2);
  EXPECT_EQ(b.size(), len + 8);
  EXPECT_EQ(b[4] | (b[5] << 8), ndi::crc16(std::span<const std::uint8_t>(b.data(), 4)));
  EXPECT_EQ(b[6 + len] | (b[7 + len] << 8), ndi::crc16(std::span<const std::uint8_t>(b.data() + 6, len)));
  EXPECT_EQ(b[6], 2);     // handle count
  EXPECT_EQ(b[7], 0x0A);  // handle
  EXPECT_EQ(b[8], 0x01);  // valid
  float tz;
  std::memcpy(&tz, &b[9 + 6 * 4], 4);
  EXPECT_EQ(tz, -1500.0f);
  EXPECT_EQ(b[9 + 32 + 4], 77);  // frame number, little endian
  EXPECT_EQ(b[9 + 40], 0x0B);
  EXPECT_EQ(b[9 + 41], 0x02);  // missing
}

}  // namespace
}  // namespace arnav::hil
