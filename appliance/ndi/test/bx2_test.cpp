#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/crc16.hpp"

namespace arnav::ndi {
namespace {

TrackingReply sample(std::uint32_t frame) {
  TrackingReply t;
  t.has_frame = true;
  t.frame = frame;
  t.has_device_time = true;
  t.device_time_ns = 1234'567'891'011;
  t.count = 3;
  for (std::size_t i = 0; i < 3; ++i) {
    auto& h = t.handles[i];
    h.handle = static_cast<std::uint8_t>(0x0A + i);
    h.state = HandleState::Valid;
    h.q_NdiTool_wxyz = {0.5, 0.5, -0.5, 0.5};
    h.p_NdiTool_mm = {10.25 * static_cast<double>(i + 1), -20.5, -1500.75};
    h.rms_error_mm = 0.125;
    h.port_status = kPortOccupied | kPortInitialised | kPortEnabled;
  }
  t.handles[1].state = HandleState::Missing;
  t.handles[2].port_status |= kPortOutOfVolume;
  return t;
}

void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v & 0xFF));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void put_f32(std::vector<std::uint8_t>& out, float f) {
  std::uint32_t bits;
  std::memcpy(&bits, &f, sizeof bits);
  put_u32(out, bits);
}
// Wraps a GBF body in a C4 A5 frame with correct CRCs.
std::vector<std::uint8_t> frame_of(const std::vector<std::uint8_t>& body) {
  std::vector<std::uint8_t> out = {kBxStart0, kBxStart1};
  put_u16(out, static_cast<std::uint16_t>(body.size()));
  put_u16(out, crc16(std::span(out.data(), 4)));
  out.insert(out.end(), body.begin(), body.end());
  put_u16(out, crc16(std::span(body)));
  return out;
}
void component_header(std::vector<std::uint8_t>& b, std::uint16_t type, std::uint32_t size, std::uint32_t items) {
  put_u16(b, type);
  put_u32(b, size);
  put_u16(b, 0);
  put_u32(b, items);
}
// A frame item with one 6D component of one valid handle.
void frame_item(std::vector<std::uint8_t>& b, std::uint32_t frame, std::uint8_t handle) {
  b.push_back(1);
  b.push_back(0);
  put_u16(b, 0);
  put_u32(b, frame);
  put_u32(b, 7);            // s
  put_u32(b, 500'000'000);  // ns
  put_u16(b, 1);
  put_u16(b, 1);
  component_header(b, kGbf6d, 12 + 4 + 32, 1);
  put_u16(b, handle);
  put_u16(b, 0);
  for (float v : {1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 2.0f, 3.0f, 0.1f}) put_f32(b, v);
}

TEST(Bx2, RoundTripCarriesFrameNumberDeviceTimeAndEveryRecord) {
  std::vector<std::uint8_t> bytes;
  encode_bx2(sample(4242), bytes);
  TrackingReply r;
  ASSERT_EQ(parse_bx2(bytes, r), ParseError::None);
  EXPECT_TRUE(r.has_frame);
  EXPECT_EQ(r.frame_number(), 4242u);
  EXPECT_TRUE(r.has_device_time);
  EXPECT_EQ(r.device_time_ns, 1234'567'891'011);
  ASSERT_EQ(r.count, 3u);
  EXPECT_EQ(r.handles[0].state, HandleState::Valid);
  EXPECT_NEAR(r.handles[0].p_NdiTool_mm[0], 10.25, 1e-4);
  EXPECT_NEAR(r.handles[0].p_NdiTool_mm[2], -1500.75, 1e-3);
  EXPECT_NEAR(r.handles[0].q_NdiTool_wxyz[2], -0.5, 1e-7);
  EXPECT_NEAR(r.handles[0].rms_error_mm, 0.125, 1e-7);
  EXPECT_EQ(r.handles[0].frame_number, 4242u);
  EXPECT_EQ(r.handles[1].state, HandleState::Missing);
  EXPECT_EQ(r.handles[2].state, HandleState::Valid);
  EXPECT_TRUE(r.handles[2].out_of_volume());
  EXPECT_FALSE(r.handles[0].out_of_volume());
  // The reader's pass already checked the CRCs: the second pass agrees.
  TrackingReply again;
  EXPECT_EQ(parse_bx2(bytes, again, true), ParseError::None);
  EXPECT_EQ(again.count, 3u);
}

TEST(Bx2, EverySingleByteCorruptionIsRejected) {
  std::vector<std::uint8_t> good;
  encode_bx2(sample(7), good);
  for (std::size_t i = 0; i < good.size(); ++i) {
    for (std::uint8_t flip : {0x01, 0x80, 0xFF}) {
      auto bad = good;
      bad[i] ^= flip;
      TrackingReply r;
      EXPECT_NE(parse_bx2(bad, r), ParseError::None) << "byte " << i;
      EXPECT_EQ(r.count, 0u);
      EXPECT_FALSE(r.has_frame);
    }
  }
}

TEST(Bx2, TruncatedAndOverlongFramesAreRejected) {
  std::vector<std::uint8_t> good;
  encode_bx2(sample(7), good);
  TrackingReply r;
  for (std::size_t n = 0; n < good.size(); ++n)
    EXPECT_NE(parse_bx2(std::span(good.data(), n), r), ParseError::None) << n;
  auto longer = good;
  longer.push_back(0);
  EXPECT_EQ(parse_bx2(longer, r), ParseError::LengthMismatch);
}

TEST(Bx2, UnknownComponentsAreSkippedAndEveryFrameItemIsRead) {
  // An alert component first, then a frame component with two items (e.g. passive and
  // active tools): the reply's frame is the first item's; records keep their own numbers.
  std::vector<std::uint8_t> b;
  put_u16(b, 1);
  put_u16(b, 2);
  component_header(b, kGbfSystemAlert, 12 + 4, 1);
  put_u32(b, 0x00010002);
  std::vector<std::uint8_t> items;
  frame_item(items, 100, 0x0A);
  frame_item(items, 101, 0x0B);
  component_header(b, kGbfFrame, static_cast<std::uint32_t>(12 + items.size()), 2);
  b.insert(b.end(), items.begin(), items.end());
  TrackingReply r;
  ASSERT_EQ(parse_bx2(frame_of(b), r), ParseError::None);
  EXPECT_EQ(r.frame_number(), 100u);
  EXPECT_EQ(r.device_time_ns, 7'500'000'000);
  ASSERT_EQ(r.count, 2u);
  EXPECT_EQ(r.handles[1].handle, 0x0B);
  EXPECT_EQ(r.handles[1].frame_number, 101u);
}

TEST(Bx2, StructurallyWrongBodiesWithGoodCrcsAreRejected) {
  TrackingReply r;
  {  // component size beyond the body
    std::vector<std::uint8_t> b;
    put_u16(b, 1);
    put_u16(b, 1);
    component_header(b, kGbfFrame, 500, 1);
    EXPECT_EQ(parse_bx2(frame_of(b), r), ParseError::LengthMismatch);
  }
  {  // a 6D component outside any frame: no frame number to give it
    std::vector<std::uint8_t> b;
    put_u16(b, 1);
    put_u16(b, 1);
    component_header(b, kGbf6d, 12 + 4, 1);
    put_u16(b, 0x0A);
    put_u16(b, kBx2Missing);
    EXPECT_EQ(parse_bx2(frame_of(b), r), ParseError::BadField);
  }
  {  // no frame component at all
    std::vector<std::uint8_t> b;
    put_u16(b, 1);
    put_u16(b, 0);
    put_u16(b, 0);  // a trailing byte pair
    EXPECT_EQ(parse_bx2(frame_of(b), r), ParseError::TrailingBytes);
  }
  {  // a NaN position is never a pose
    std::vector<std::uint8_t> items;
    frame_item(items, 5, 0x0A);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::memcpy(items.data() + items.size() - 8, &nan, 4);
    std::vector<std::uint8_t> b;
    put_u16(b, 1);
    put_u16(b, 1);
    component_header(b, kGbfFrame, static_cast<std::uint32_t>(12 + items.size()), 1);
    b.insert(b.end(), items.begin(), items.end());
    EXPECT_EQ(parse_bx2(frame_of(b), r), ParseError::BadField);
    EXPECT_EQ(r.count, 0u);
  }
}

TEST(Bx2, ABxReplyIsNotTakenForBx2) {
  TrackingReply t = sample(9);
  t.has_frame = t.has_device_time = false;
  for (std::size_t i = 0; i < t.count; ++i) t.handles[i].has_status = true;
  std::vector<std::uint8_t> bx;
  encode_bx(t, bx);
  TrackingReply r;
  EXPECT_NE(parse_bx2(bx, r), ParseError::None);
  EXPECT_EQ(r.count, 0u);
}

}  // namespace
}  // namespace arnav::ndi
