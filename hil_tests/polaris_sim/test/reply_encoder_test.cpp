// The simulator's replies as bytes on the wire (built with appliance/ndi's encoders):
// checked against values seen on real devices.
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
  EXPECT_EQ(hex_field(0x31, 3), "031");
}

TEST(ReplyEncoder, TxMatchesTheRealExample) {
  // Real fields from ndi-capi.md: q=(0.7066,0.7050,-0.0372,-0.0462), t=(-240.11,64.70,-1564.67),
  // error 0.1855 mm, port status 0x31, frame 445.
  ndi::TrackingReply f;
  f.count = 1;
  auto& h = f.handles[0];
  h.handle = 0x0A;
  h.state = ndi::HandleState::Valid;
  h.q_NdiTool_wxyz = {0.7066, 0.7050, -0.0372, -0.0462};
  h.p_NdiTool_mm = {-240.11, 64.70, -1564.67};
  h.rms_error_mm = 0.1855;
  h.port_status = 0x31;
  h.frame_number = 445;
  const std::string s = str(tracking_reply(f, false));
  const std::string body = "010A+07066+07050-00372-00462-024011+006470-156467+0185500000031000001BD\n0000";
  EXPECT_EQ(s, body + hex_field(ndi::crc16(body), 4) + "\r");
}

TEST(ReplyEncoder, BxFrameLayoutAndCrcs) {
  ndi::TrackingReply f;
  f.count = 2;
  auto& v = f.handles[0];
  v.handle = 0x0A;
  v.state = ndi::HandleState::Valid;
  v.p_NdiTool_mm = {1.5, -2.25, -1500.0};
  v.rms_error_mm = 0.25;
  v.port_status = 0x31;
  v.frame_number = 77;
  auto& m = f.handles[1];
  m.handle = 0x0B;
  m.state = ndi::HandleState::Missing;
  m.port_status = 0x31;
  m.frame_number = 77;
  const Bytes b = tracking_reply(f, true);
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
