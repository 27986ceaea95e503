#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <set>

#include "appliance/ndi/crc16.hpp"
#include "hil_tests/polaris_sim/replay_device.hpp"

namespace arnav::hil {
namespace {

std::string capture() { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/ndi_captures/polaris_classic_stream.txt"; }

std::string say(ReplayDevice& d, const std::string& command, int* baud_after = nullptr) {
  auto r = d.receive(std::span(reinterpret_cast<const std::uint8_t*>(command.data()), command.size()), 1.0);
  EXPECT_EQ(r.size(), 1u);
  if (r.empty()) return {};
  if (baud_after) *baud_after = r[0].baud_after;
  return std::string(r[0].bytes.begin(), r[0].bytes.end());
}

TEST(Replay, ReadsTheRealIgstkCapture) {
  const Recording rec = load_replay(capture());
  ASSERT_GT(rec.exchanges.size(), 100u);
  const auto& first = rec.exchanges[0];
  EXPECT_EQ(std::string(first.command.begin(), first.command.end()), "INIT:E3A5\r");
  EXPECT_EQ(std::string(first.reply.begin(), first.reply.end()), "OKAYA896\r");
  // Every recorded reply ends with a CRC that checks (real data, so a good parser check).
  int checked = 0;
  for (const auto& ex : rec.exchanges) {
    if (ex.reply.size() < 6 || ex.reply.back() != '\r') continue;
    const std::string r(ex.reply.begin(), ex.reply.end() - 1);
    EXPECT_EQ(std::stoul(r.substr(r.size() - 4), nullptr, 16), ndi::crc16(r.substr(0, r.size() - 4))) << "line " << ex.line;
    ++checked;
  }
  EXPECT_GT(checked, 100);
}

TEST(Replay, ActsOutTheSession) {
  ReplayDevice d(load_replay(capture()));
  d.reset(0.0);
  EXPECT_EQ(say(d, "INIT:E3A5\r"), "OKAYA896\r");
  EXPECT_NE(say(d, "VER:065EE\r").find("Polaris Control Firmware"), std::string::npos);
  int baud = 0;
  EXPECT_EQ(say(d, "COMM:500000048\r", &baud), "OKAYA896\r");
  EXPECT_EQ(baud, 115200);
  // The tracking loop can be polled for longer than it was recorded.
  std::set<std::string> distinct;
  for (int i = 0; i < 2000; ++i) {
    const std::string r = say(d, "GX 0001\r");
    ASSERT_FALSE(r.empty());
    ASSERT_EQ(r.back(), '\r');
    distinct.insert(r);
  }
  EXPECT_GT(distinct.size(), 100u);  // the recorded replies, in turn, not one repeated
  EXPECT_EQ(d.unmatched(), 0u);
  EXPECT_EQ(say(d, "BX:0001C26D\r").substr(0, 7), "ERROR01");  // never recorded
  EXPECT_EQ(d.unmatched(), 1u);
}

TEST(Replay, TranscriptsPairCommandsWithReplies) {
  const std::string dir = std::string(std::getenv("ARNAV_BINARY_DIR")) + "/replay_test";
  std::filesystem::create_directories(dir);
  {
    std::ofstream out(dir + "/session.txt");
    out << ndi::kTranscriptHeader << "\n"
        << "0 reply RESETBE6F\\r\n"
        << "10 cmd INIT:E3A5\\r\n"
        << "20 reply OK\n"
        << "21 reply AYA896\\r\n"
        << "30 break 250\n"
        << "40 cmd BEEP:1\\r\n";
  }
  ReplayDevice d(load_replay(dir + "/session.txt"));
  EXPECT_EQ(say(d, "INIT:E3A5\r"), "OKAYA896\r");  // pieces joined
  EXPECT_EQ(say(d, "BEEP:1\r"), "");               // recorded without a reply
  {
    std::ofstream out(dir + "/bad.txt");
    out << ndi::kTranscriptHeader << "\n5 cmd INIT\\q\n";
  }
  try {
    load_replay(dir + "/bad.txt");
    ADD_FAILURE() << "a malformed transcript was accepted";
  } catch (const ScenarioError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.txt:2"), std::string::npos) << e.what();
  }
  {
    std::ofstream out(dir + "/empty.txt");
    out << ndi::kTranscriptHeader << "\n0 note nothing\n";
  }
  EXPECT_THROW(load_replay(dir + "/empty.txt"), ScenarioError);
}

}  // namespace
}  // namespace arnav::hil
