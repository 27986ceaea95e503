#include <gtest/gtest.h>

#include <set>

#include "appliance/ndi/crc16.hpp"
#include "hil_tests/polaris_sim/replay_device.hpp"

namespace arnav::hil {
namespace {

std::string capture() { return std::string(std::getenv("ARNAV_SHARED_DIR")) + "/data/ndi_captures/polaris_classic_stream.txt"; }

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

TEST(Replay, MalformedLogsNameTheLine) {
  const auto error_of = [](const std::string& text) {
    try {
      parse_igstk_log(text, "log.txt");
    } catch (const ScenarioError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of("1 : (INFO) 1. command[3] INIT\n").find("log.txt:1: length says 3"), std::string::npos);
  EXPECT_NE(error_of("\n1 : (INFO) 1. command[2] \\q1\n").find("log.txt:2: bad escape"), std::string::npos);
  EXPECT_NE(error_of("1 : (INFO) 1. sent[2] ab\n").find("log.txt:1"), std::string::npos);
  EXPECT_NE(error_of("hello\n").find("no 'command[len]'"), std::string::npos);
}

}  // namespace
}  // namespace arnav::hil
