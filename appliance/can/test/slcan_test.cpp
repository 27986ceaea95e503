// slcan codec and streaming reader: every message kind, any chunking, and the resync
// rules (lost CR, lost character, garbage, BEL, over-long lines).
#include <gtest/gtest.h>

#include <random>

#include "appliance/can/slcan.hpp"

namespace arnav::can::slcan {
namespace {

std::vector<Message> read_all(Reader& r, std::string_view text, std::size_t chunk = 0) {
  std::vector<Message> out;
  if (chunk == 0) chunk = text.empty() ? 1 : text.size();
  Message m;
  for (std::size_t pos = 0; pos < text.size(); pos += chunk) {
    r.feed(text.substr(pos, std::min(chunk, text.size() - pos)));
    while (r.next(m)) out.push_back(m);
  }
  return out;
}

CanFrame data_frame(std::uint32_t id, bool ext, std::vector<std::uint8_t> bytes) {
  CanFrame f;
  f.id = id;
  f.extended = ext;
  f.dlc = static_cast<std::uint8_t>(bytes.size());
  for (std::size_t i = 0; i < bytes.size(); ++i) f.data[i] = bytes[i];
  return f;
}

TEST(Slcan, BitrateCodes) {
  EXPECT_EQ(bitrate_code(10000), 0);
  EXPECT_EQ(bitrate_code(500000), 6);
  EXPECT_EQ(bitrate_code(1000000), 8);
  EXPECT_FALSE(bitrate_code(83333));
  EXPECT_EQ(bitrate_command(6), "S6\r");
}

TEST(Slcan, EncodesEveryFrameKind) {
  EXPECT_EQ(encode_frame(data_frame(0x123, false, {0xDE, 0xAD, 0xBE, 0xEF})), "t1234DEADBEEF\r");
  EXPECT_EQ(encode_frame(data_frame(0x1ABCDEF0, true, {0x01})), "T1ABCDEF0101\r");
  EXPECT_EQ(encode_frame(data_frame(0x7FF, false, {})), "t7FF0\r");
  CanFrame r = data_frame(0x321, false, {});
  r.remote = true;
  r.dlc = 2;
  EXPECT_EQ(encode_frame(r), "r3212\r");
  r.extended = true;
  EXPECT_EQ(encode_frame(r), "R000003212\r");
  CanFrame e;
  e.error = true;
  EXPECT_EQ(encode_frame(e), "");
}

TEST(Slcan, RoundTripInAnyChunking) {
  std::mt19937 rng(7);
  std::vector<CanFrame> frames;
  std::string wire;
  for (int i = 0; i < 200; ++i) {
    CanFrame f;
    f.extended = rng() % 2;
    f.id = static_cast<std::uint32_t>(rng()) & (f.extended ? kMaxExtendedId : kMaxStandardId);
    f.remote = rng() % 5 == 0;
    f.dlc = static_cast<std::uint8_t>(rng() % 9);
    if (!f.remote)
      for (int b = 0; b < f.dlc; ++b) f.data[static_cast<std::size_t>(b)] = static_cast<std::uint8_t>(rng());
    frames.push_back(f);
    wire += encode_frame(f);
  }
  for (std::size_t chunk : {std::size_t{0}, std::size_t{1}, std::size_t{3}, std::size_t{17}}) {
    Reader reader;
    const auto got = read_all(reader, wire, chunk);
    ASSERT_EQ(got.size(), frames.size()) << "chunk " << chunk;
    for (std::size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].kind, Message::Kind::Frame);
      EXPECT_EQ(got[i].frame, frames[i]) << i;
    }
    EXPECT_EQ(reader.counters().garbage_bytes, 0);
    EXPECT_EQ(reader.counters().malformed, 0);
  }
}

TEST(Slcan, RepliesOkErrorStatusVersionSerialAck) {
  Reader r;
  const auto got = read_all(r, "\r\aF25\rV1013\rNA123\rz\rZ\r");
  ASSERT_EQ(got.size(), 7u);
  EXPECT_EQ(got[0].kind, Message::Kind::Ok);
  EXPECT_EQ(got[1].kind, Message::Kind::Error);
  EXPECT_EQ(got[2].kind, Message::Kind::Status);
  EXPECT_EQ(got[2].flags, 0x25);
  EXPECT_EQ(got[3].kind, Message::Kind::Version);
  EXPECT_EQ(std::string(got[3].text.data(), 4), "1013");
  EXPECT_EQ(got[4].kind, Message::Kind::Serial);
  EXPECT_EQ(got[5].kind, Message::Kind::TxAck);
  EXPECT_EQ(got[6].kind, Message::Kind::TxAck);
  EXPECT_EQ(r.counters().errors, 1);
}

TEST(Slcan, LostCrCostsNoFrame) {
  Reader r;
  const auto got = read_all(r, "t1232AABBt1232CCDD\r");
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].frame, data_frame(0x123, false, {0xAA, 0xBB}));
  EXPECT_EQ(got[1].frame, data_frame(0x123, false, {0xCC, 0xDD}));
  EXPECT_EQ(r.counters().malformed, 0);
}

TEST(Slcan, ManyLostCrsBeyondTheLineLimit) {
  Reader r;
  std::string wire;
  for (int i = 0; i < 10; ++i) wire += "t1001" + std::string(i % 2 ? "01" : "00");
  wire += "\r";
  const auto got = read_all(r, wire, 1);
  ASSERT_EQ(got.size(), 10u);
  for (int i = 0; i < 10; ++i) EXPECT_EQ(got[static_cast<std::size_t>(i)].frame.data[0], i % 2);
}

TEST(Slcan, LostCharacterCostsExactlyThatFrame) {
  // Drop each character of the middle frame in turn: the frames around it always survive,
  // and the damaged one never comes out wrong.
  const std::string before = "t1001AA\r", mid = "t2002BBCC\r", after = "t3001DD\r";
  for (std::size_t k = 0; k < mid.size(); ++k) {
    std::string damaged = mid;
    damaged.erase(k, 1);
    Reader r;
    const auto got = read_all(r, before + damaged + after);
    std::vector<CanFrame> frames;
    for (const auto& m : got)
      if (m.kind == Message::Kind::Frame) frames.push_back(m.frame);
    ASSERT_GE(frames.size(), 2u) << "drop at " << k;
    EXPECT_EQ(frames.front(), data_frame(0x100, false, {0xAA}));
    EXPECT_EQ(frames.back(), data_frame(0x300, false, {0xDD}));
    for (std::size_t i = 1; i + 1 < frames.size(); ++i) EXPECT_EQ(frames[i], data_frame(0x200, false, {0xBB, 0xCC})) << k;
    if (k < mid.size() - 1) {
      EXPECT_EQ(frames.size(), 2u) << "drop at " << k;
    }
  }
}

TEST(Slcan, GarbageAndBinaryNoiseAreSkippedAndCounted) {
  Reader r;
  std::string wire = "xx\x01\xFFt1001AA\r";
  wire += "t100";
  wire += '\x8F';  // a corrupted byte inside a frame: the frame is dropped
  wire += "1AA\rt1001BB\r";
  const auto got = read_all(r, wire);
  std::vector<CanFrame> frames;
  for (const auto& m : got)
    if (m.kind == Message::Kind::Frame) frames.push_back(m.frame);
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0].data[0], 0xAA);
  EXPECT_EQ(frames[1].data[0], 0xBB);
  EXPECT_GT(r.counters().garbage_bytes, 5);
  EXPECT_GT(r.counters().resyncs, 1);
}

TEST(Slcan, RejectsOutOfRangeFields) {
  Reader r;
  // 9 is no DLC, 800 is no standard id, 2FFFFFFF no extended id, odd data, lowercase ok.
  const auto got = read_all(r, "t1009\rt8001AA\rT2FFFFFFF0\rt1001A\rt1001ab\r");
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].frame.data[0], 0xAB);
  EXPECT_EQ(r.counters().malformed, 4);
}

TEST(Slcan, TimestampsOnlyWhenEnabled) {
  Reader plain;
  EXPECT_TRUE(read_all(plain, "t1001AA1234\r").empty());
  Reader stamped;
  stamped.set_timestamps(true);
  const auto got = read_all(stamped, "t1001AA1234\rt1001AA\r");
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].timestamp_ms, 0x1234);
  EXPECT_FALSE(got[1].timestamp_ms);
}

TEST(Slcan, BelInsideALineDropsTheLine) {
  Reader r;
  const auto got = read_all(r, "t10\at1001AA\r");
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].kind, Message::Kind::Error);
  EXPECT_EQ(got[1].kind, Message::Kind::Frame);
  EXPECT_EQ(r.counters().malformed, 1);
}

TEST(Slcan, ClearCountsBufferedBytes) {
  Reader r;
  r.feed(std::string_view("t1001A"));
  Message m;
  EXPECT_FALSE(r.next(m));
  EXPECT_EQ(r.buffered(), 6u);
  r.clear();
  EXPECT_EQ(r.buffered(), 0u);
  EXPECT_EQ(r.counters().garbage_bytes, 6);
}

}  // namespace
}  // namespace arnav::can::slcan
