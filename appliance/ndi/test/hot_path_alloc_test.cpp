// The per-frame receive path (FrameReader + parse_bx) must not allocate: counted with a
// replacement global operator new in this test binary only.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/frame_reader.hpp"

namespace {
std::atomic<long> g_allocations{0};
}

void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

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
  const long before = g_allocations.load();
  int good = 0;
  for (int i = 0; i < 2000; ++i) {
    if (i % 7 == 0) reader.feed(garbage);
    reader.feed(std::span(frame).first(20));  // chunked
    reader.feed(std::span(frame).subspan(20));
    while (reader.next(f))
      if (f.crc_ok && parse_bx(f.bytes, out, BxCrc::AlreadyChecked) == ParseError::None) ++good;
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
  EXPECT_EQ(good, 2000);
  EXPECT_GT(reader.counters().garbage_bytes, 0);
}

}  // namespace
}  // namespace arnav::ndi
