#include <gtest/gtest.h>

#include <random>
#include <set>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/frame_reader.hpp"
#include "appliance/ndi/reply.hpp"
#include "appliance/ndi/test/capture.hpp"

namespace arnav::ndi {
namespace {

std::vector<std::uint8_t> bytes_of(std::string_view s) { return {s.begin(), s.end()}; }

TrackingReply reply_with_frame(std::uint32_t frame, std::size_t tools = 3) {
  TrackingReply t;
  t.count = tools;
  for (std::size_t i = 0; i < tools; ++i) {
    auto& h = t.handles[i];
    h.handle = static_cast<std::uint8_t>(i + 1);
    h.state = HandleState::Valid;
    h.p_NdiTool_mm = {1.0 * static_cast<double>(frame), 2.0, 3.0};
    h.has_status = true;
    h.port_status = 0x31;
    h.frame_number = frame;
  }
  return t;
}

std::vector<std::uint8_t> bx_bytes(std::uint32_t frame) {
  std::vector<std::uint8_t> out;
  encode_bx(reply_with_frame(frame), out);
  return out;
}

TEST(FrameReader, BinaryFramesFedOneByteAtATime) {
  FrameReader r;
  r.set_expect_binary(true);
  std::vector<std::uint8_t> stream;
  for (std::uint32_t f = 1; f <= 5; ++f) {
    auto b = bx_bytes(f);
    stream.insert(stream.end(), b.begin(), b.end());
  }
  std::vector<std::uint32_t> frames;
  Frame fr;
  for (std::uint8_t b : stream) {
    r.feed(std::span(&b, 1));
    while (r.next(fr)) {
      ASSERT_EQ(fr.kind, Frame::Kind::Binary);
      ASSERT_TRUE(fr.crc_ok);
      TrackingReply t;
      ASSERT_EQ(parse_bx(fr.bytes, t), ParseError::None);
      frames.push_back(t.frame_number());
    }
  }
  EXPECT_EQ(frames, (std::vector<std::uint32_t>{1, 2, 3, 4, 5}));
  EXPECT_EQ(r.counters().garbage_bytes, 0);
  EXPECT_EQ(r.counters().crc_errors, 0);
}

TEST(FrameReader, GarbageBeforeHeaderIsSkippedAndCounted) {
  FrameReader r;
  r.set_expect_binary(true);
  auto g = bytes_of("xx\xC4zz\x01");
  r.feed(g);
  auto b = bx_bytes(7);
  r.feed(b);
  Frame fr;
  ASSERT_TRUE(r.next(fr));
  EXPECT_TRUE(fr.crc_ok);
  EXPECT_EQ(r.counters().garbage_bytes, 6);
  EXPECT_GE(r.counters().resyncs, 1);
}

TEST(FrameReader, CorruptBodyIsFlaggedAndTheNextFrameIsFine) {
  FrameReader r;
  r.set_expect_binary(true);
  auto bad = bx_bytes(1);
  bad[20] ^= 0x40;
  r.feed(bad);
  r.feed(bx_bytes(2));
  Frame fr;
  ASSERT_TRUE(r.next(fr));
  EXPECT_FALSE(fr.crc_ok);
  ASSERT_TRUE(r.next(fr));
  EXPECT_TRUE(fr.crc_ok);
  EXPECT_EQ(r.counters().crc_errors, 1);
}

TEST(FrameReader, CorruptHeaderLengthIsNeverTrusted) {
  FrameReader r;
  r.set_expect_binary(true);
  auto bad = bx_bytes(1);
  bad[2] = 0xFF;  // length field: header CRC now fails
  r.feed(bad);
  r.feed(bx_bytes(2));
  Frame fr;
  ASSERT_TRUE(r.next(fr));
  ASSERT_TRUE(fr.crc_ok);
  TrackingReply t;
  ASSERT_EQ(parse_bx(fr.bytes, t), ParseError::None);
  EXPECT_EQ(t.frame_number(), 2u);
  EXPECT_EQ(r.counters().garbage_bytes, static_cast<std::int64_t>(bad.size()));
  EXPECT_FALSE(r.next(fr));
}

TEST(FrameReader, AsciiErrorWhileExpectingBinary) {
  FrameReader r;
  r.set_expect_binary(true);
  r.feed(bytes_of("\x01\x02" + encode_reply("ERROR0C")));
  Frame fr;
  ASSERT_TRUE(r.next(fr));
  EXPECT_EQ(fr.kind, Frame::Kind::Ascii);
  EXPECT_TRUE(fr.crc_ok);
  AsciiReply a;
  ASSERT_EQ(parse_ascii_reply(fr.text(), a), ParseError::None);
  EXPECT_EQ(a.error_code, 0x0C);
  EXPECT_EQ(r.counters().garbage_bytes, 2);
}

TEST(FrameReader, CaptureRepliesInRandomChunks) {
  std::vector<std::uint8_t> stream;
  std::vector<std::string> expected;
  for (const auto& rec : test::load_capture()) {
    if (rec.kind != TranscriptRecord::Kind::Reply) continue;
    stream.insert(stream.end(), rec.bytes.begin(), rec.bytes.end());
    expected.push_back(rec.bytes.substr(0, rec.bytes.size() - 1));
  }
  std::mt19937 rng(42);
  FrameReader r;
  std::size_t pos = 0, got = 0;
  Frame fr;
  while (pos < stream.size()) {
    std::size_t n = std::min<std::size_t>(stream.size() - pos, 1 + rng() % 97);
    r.feed(std::span(stream).subspan(pos, n));
    pos += n;
    while (r.next(fr)) {
      ASSERT_LT(got, expected.size());
      EXPECT_TRUE(fr.crc_ok);
      EXPECT_EQ(fr.text(), expected[got]);
      ++got;
    }
  }
  EXPECT_EQ(got, expected.size());
}

// Property: whatever garbage, corruption and chunking, a frame that the reader passes
// as CRC-good decodes to exactly one of the frames that was sent intact.
TEST(FrameReader, NeverAPoseFromACorruptFrame) {
  std::mt19937 rng(1234);
  FrameReader r;
  r.set_expect_binary(true);
  std::vector<std::uint8_t> stream;
  std::set<std::uint32_t> intact;
  for (std::uint32_t f = 1; f <= 2000; ++f) {
    auto b = bx_bytes(f);
    const unsigned fault = rng() % 10;
    if (fault == 0) b[rng() % b.size()] ^= static_cast<std::uint8_t>(1 + rng() % 255);  // corrupt
    else if (fault == 1) b.resize(rng() % b.size());                                  // cut short
    else intact.insert(f);
    if (rng() % 8 == 0) {
      const std::size_t g = rng() % 40;
      for (std::size_t i = 0; i < g; ++i) stream.push_back(static_cast<std::uint8_t>(rng()));
    }
    stream.insert(stream.end(), b.begin(), b.end());
  }
  std::size_t pos = 0, good = 0;
  Frame fr;
  TrackingReply t;
  while (pos < stream.size()) {
    std::size_t n = std::min<std::size_t>(stream.size() - pos, 1 + rng() % 300);
    r.feed(std::span(stream).subspan(pos, n));
    pos += n;
    while (r.next(fr)) {
      if (fr.kind != Frame::Kind::Binary || !fr.crc_ok) continue;
      ASSERT_EQ(parse_bx(fr.bytes, t), ParseError::None);
      const std::uint32_t f = t.frame_number();
      ASSERT_TRUE(intact.count(f)) << "pose from a frame that was corrupted: " << f;
      ASSERT_DOUBLE_EQ(t.handles[0].p_NdiTool_mm[0], static_cast<double>(f));
      ++good;
    }
  }
  // Most intact frames survive (a cut frame can swallow the start of its successor).
  EXPECT_GT(good, intact.size() * 8 / 10);
  EXPECT_GT(r.counters().crc_errors + r.counters().resyncs, 100);
}

}  // namespace
}  // namespace arnav::ndi
