// The per-frame receive path (FrameReader + parse_bx) must not allocate: counted with a
// test-support operator new (protocol/testing/allocation_counter).
#include <gtest/gtest.h>

#include "protocol/testing/allocation_counter.hpp"


#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/frame_reader.hpp"


namespace arnav::ndi {
namespace {

TEST(HotPath, ReaderAndBxParseDoNotAllocatePerFrame) {
  TrackingReply in;
  in.count = 6;
  for (std::size_t i = 0; i < 6; ++i) {
    in.handles[i].handle = static_cast<std::uint8_t>(i + 1);
    in.handles[i].state = HandleState::Valid;
    in.handles[i].has_status = true;
    in.handles[i].frame_number = 5;
  }
  std::vector<std::uint8_t> frame;
  encode_bx(in, frame);
  std::vector<std::uint8_t> garbage = {0x00, 0xFF, 'x'};
  FrameReader reader;
  reader.set_expect_binary(true);
  TrackingReply out;
  Frame f;
  // Warm up (the reader's buffer reaches its working size).
  for (int i = 0; i < 10; ++i) {
    reader.feed(frame);
    ASSERT_TRUE(reader.next(f));
  }
  const long before = arnav::testing::allocation_count();
  int good = 0;
  for (int i = 0; i < 2000; ++i) {
    if (i % 7 == 0) reader.feed(garbage);
    reader.feed(std::span(frame).first(20));  // chunked
    reader.feed(std::span(frame).subspan(20));
    while (reader.next(f))
      if (f.crc_ok && parse_bx(f.bytes, out, BxCrc::AlreadyChecked) == ParseError::None) ++good;
  }
  EXPECT_EQ(arnav::testing::allocation_count() - before, 0);
  EXPECT_EQ(good, 2000);
  EXPECT_GT(reader.counters().garbage_bytes, 0);
}

}  // namespace
}  // namespace arnav::ndi
