#include <gtest/gtest.h>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/reply.hpp"
#include "appliance/ndi/test/capture.hpp"
#include "appliance/tools/decode.hpp"

namespace arnav::tools {
namespace {

std::vector<std::uint8_t> bytes_of(const std::string& s) { return {s.begin(), s.end()}; }

TEST(Decode, EveryReplyOfTheRealCapture) {
  std::string wire;
  for (const auto& r : ndi::test::load_capture())
    if (r.kind == ndi::TranscriptRecord::Kind::Reply) wire += r.bytes;
  const auto out = decode_replies(bytes_of(wire));
  ASSERT_EQ(out.size(), 649u);
  for (const auto& j : out) EXPECT_TRUE(j.at("crc_ok").get<bool>()) << j.dump();
  EXPECT_EQ(out[0]["kind"], "reset");
  EXPECT_EQ(out[1]["kind"], "okay");
  EXPECT_EQ(out[2]["kind"], "ver");
  EXPECT_EQ(out[2]["serial_number"], "P1-00091");
  EXPECT_EQ(out[2]["offset"], 19);
}

TEST(Decode, BxErrorTxAndDamage) {
  ndi::TrackingReply t;
  t.count = 2;
  t.handles[0].handle = 0x0A;
  t.handles[0].state = ndi::HandleState::Valid;
  t.handles[0].p_NdiTool_mm = {1.5, 2.5, -1000.0};
  t.handles[0].has_status = true;
  t.handles[0].port_status = ndi::kPortOccupied | ndi::kPortOutOfVolume;
  t.handles[0].frame_number = 42;
  t.handles[1].handle = 0x0B;
  t.handles[1].state = ndi::HandleState::Disabled;
  std::vector<std::uint8_t> wire;
  ndi::encode_bx(t, wire);
  auto add = [&](const std::string& s) { wire.insert(wire.end(), s.begin(), s.end()); };
  add(ndi::encode_reply("ERROR0D"));
  add(ndi::encode_reply(ndi::format_tx_body(t)));
  std::vector<std::uint8_t> bad;
  ndi::encode_bx(t, bad);
  bad[10] ^= 1;
  wire.insert(wire.end(), bad.begin(), bad.end());
  add("OKAYA897\r");
  add("OKA");

  const auto out = decode_replies(wire);
  ASSERT_EQ(out.size(), 6u);
  EXPECT_EQ(out[0]["kind"], "bx");
  EXPECT_EQ(out[0]["handles"][0]["frame_number"], 42);
  EXPECT_EQ(out[0]["handles"][0]["port_status"]["out_of_volume"], true);
  EXPECT_DOUBLE_EQ(out[0]["handles"][0]["p_NdiTool_mm"][1].get<double>(), 2.5);
  EXPECT_EQ(out[0]["handles"][1]["state"], "disabled");
  EXPECT_EQ(out[1]["kind"], "error");
  EXPECT_EQ(out[1]["name"], "NO_TOOL_ON_HANDLE");
  EXPECT_EQ(out[2]["kind"], "tx");
  EXPECT_EQ(out[2]["handle_count"], 2);
  EXPECT_EQ(out[3]["kind"], "bx");
  EXPECT_EQ(out[3]["crc_ok"], false);
  EXPECT_FALSE(out[3].contains("handles"));
  EXPECT_EQ(out[4]["kind"], "corrupt");
  EXPECT_EQ(out[5]["kind"], "incomplete");
}

}  // namespace
}  // namespace arnav::tools
