// The frame reader on TCP traffic: stream packets (D4 B5 ...) wrapping BX2 replies, ASCII
// command replies interleaved with them, extended C8 A5 replies, corruption and chunking.
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "appliance/ndi/bx2.hpp"
#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/frame_reader.hpp"
#include "appliance/ndi/reply.hpp"

namespace arnav::ndi {
namespace {

using Bytes = std::vector<std::uint8_t>;

Bytes bx2_bytes(std::uint32_t frame) {
  TrackingReply t;
  t.has_frame = t.has_device_time = true;
  t.frame = frame;
  t.device_time_ns = static_cast<std::int64_t>(frame) * 2'500'000;
  t.count = 2;
  for (std::size_t i = 0; i < 2; ++i) {
    t.handles[i].handle = static_cast<std::uint8_t>(0x0A + i);
    t.handles[i].state = HandleState::Valid;
    t.handles[i].p_NdiTool_mm = {static_cast<double>(frame), 1.0 + static_cast<double>(i), -1000.0};
  }
  Bytes out;
  encode_bx2(t, out);
  return out;
}

Bytes packet(const std::string& id, const Bytes& reply) {
  Bytes out;
  out.reserve(6 + id.size() + reply.size());
  for (std::uint8_t b : {kStreamStart0, kStreamStart1, static_cast<std::uint8_t>(id.size()), std::uint8_t{0}}) out.push_back(b);
  for (char c : id) out.push_back(static_cast<std::uint8_t>(c));
  const std::uint16_t crc = crc16(std::span(out));
  out.push_back(static_cast<std::uint8_t>(crc & 0xFF));
  out.push_back(static_cast<std::uint8_t>(crc >> 8));
  out.insert(out.end(), reply.begin(), reply.end());
  return out;
}

Bytes text(const std::string& s) {
  const std::string r = encode_reply(s);
  return {r.begin(), r.end()};
}

void append(Bytes& a, const Bytes& b) { a.insert(a.end(), b.begin(), b.end()); }

struct Seen {
  bool streamed;
  std::string id;
  Frame::Kind kind;
  bool crc_ok;
  std::uint32_t frame = 0;  // parsed BX2 frame number, when it parsed
  std::string text;
};

std::vector<Seen> read_all(const Bytes& wire, bool expect_binary, std::size_t chunk, FrameReader* keep = nullptr,
                           bool expect_extended = false) {
  FrameReader local;
  FrameReader& reader = keep ? *keep : local;
  reader.set_expect_binary(expect_binary);
  reader.set_expect_extended(expect_extended);
  std::vector<Seen> out;
  Frame f;
  for (std::size_t pos = 0; pos < wire.size(); pos += chunk) {
    reader.feed(std::span(wire.data() + pos, std::min(chunk, wire.size() - pos)));
    while (reader.next(f)) {
      Seen s{f.streamed(), std::string(f.stream()), f.kind, f.crc_ok, 0, {}};
      if (f.kind == Frame::Kind::Binary && f.crc_ok) {
        TrackingReply t;
        if (parse_bx2(f.bytes, t, true) == ParseError::None) s.frame = t.frame_number();
      }
      if (f.kind == Frame::Kind::Ascii) s.text = std::string(f.text());
      out.push_back(s);
    }
  }
  return out;
}

TEST(StreamFramer, PacketsFedOneByteAtATimeInBothModes) {
  Bytes wire;
  for (std::uint32_t n = 1; n <= 5; ++n) append(wire, packet("ARNAV", bx2_bytes(n)));
  for (bool binary : {true, false}) {
    const auto seen = read_all(wire, binary, 1);
    ASSERT_EQ(seen.size(), 5u) << binary;
    for (std::uint32_t n = 0; n < 5; ++n) {
      EXPECT_TRUE(seen[n].streamed);
      EXPECT_EQ(seen[n].id, "ARNAV");
      EXPECT_TRUE(seen[n].crc_ok);
      EXPECT_EQ(seen[n].frame, n + 1);
    }
  }
}

TEST(StreamFramer, CommandRepliesInterleavedWithPacketsKeepTheirOrder) {
  // USTREAM's race: packets already sent arrive before its OKAY; an ERROR inside a packet
  // belongs to the stream, the bare OKAY to the command.
  Bytes wire;
  append(wire, packet("ARNAV", bx2_bytes(10)));
  append(wire, packet("ARNAV", text("ERROR0C")));
  append(wire, packet("OTHER", bx2_bytes(11)));
  append(wire, text("OKAY"));
  append(wire, packet("ARNAV", bx2_bytes(12)));
  for (bool binary : {true, false}) {
    const auto seen = read_all(wire, binary, 3);
    ASSERT_EQ(seen.size(), 5u);
    EXPECT_EQ(seen[0].frame, 10u);
    EXPECT_TRUE(seen[1].streamed);
    EXPECT_EQ(seen[1].text.substr(0, 7), "ERROR0C");
    EXPECT_EQ(seen[2].id, "OTHER");
    EXPECT_FALSE(seen[3].streamed);
    EXPECT_EQ(seen[3].text.substr(0, 4), "OKAY");
    EXPECT_TRUE(seen[3].crc_ok);
    EXPECT_EQ(seen[4].frame, 12u);
  }
}

TEST(StreamFramer, CorruptPacketHeaderIsSkippedAndTheNextPacketIsFine) {
  for (std::size_t at : {2u, 3u, 5u, 9u, 10u}) {  // id length, id, header CRC
    Bytes bad = packet("ARNAV", bx2_bytes(1));
    bad[at] ^= 0x41;
    Bytes wire = bad;
    append(wire, packet("ARNAV", bx2_bytes(2)));
    FrameReader reader;
    const auto seen = read_all(wire, true, 4, &reader);
    ASSERT_FALSE(seen.empty()) << at;
    // Nothing from the damaged packet passes as a good stream frame of ours.
    for (const auto& s : seen) {
      if (s.streamed && s.crc_ok && s.id == "ARNAV") {
        EXPECT_EQ(s.frame, 2u) << at;
      }
    }
    EXPECT_EQ(seen.back().frame, 2u) << at;
    EXPECT_GE(reader.counters().crc_errors, 1) << at;
  }
}

TEST(StreamFramer, CorruptInnerReplyIsFlaggedNotUsed) {
  Bytes inner = bx2_bytes(3);
  inner[20] ^= 0x10;  // body byte: the body CRC fails
  Bytes wire = packet("ARNAV", inner);
  append(wire, packet("ARNAV", bx2_bytes(4)));
  const auto seen = read_all(wire, true, 7);
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_TRUE(seen[0].streamed);
  EXPECT_FALSE(seen[0].crc_ok);
  EXPECT_EQ(seen[1].frame, 4u);
}

TEST(StreamFramer, ExtendedRepliesAreFramedByTheirLengthAndBoundedInSize) {
  Bytes ext = {kExtendedStart0, 0xA5, 5, 0, 0, 0, 'h', 'e', 'l', 'l', 'o'};
  Bytes wire = ext;
  append(wire, packet("ARNAV", bx2_bytes(8)));
  auto seen = read_all(wire, true, 2, nullptr, true);
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[0].kind, Frame::Kind::Extended);
  EXPECT_EQ(seen[1].frame, 8u);
  // Inside a stream packet too (its header CRC vouches for the start).
  seen = read_all(packet("IMG", ext), true, 3);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(seen[0].kind, Frame::Kind::Extended);
  EXPECT_EQ(seen[0].id, "IMG");
  // A length beyond kMaxExtendedReply is not waited for: the next packet still comes out.
  Bytes huge = {kExtendedStart0, 0xA5, 0xFF, 0xFF, 0xFF, 0x7F};
  append(huge, packet("ARNAV", bx2_bytes(9)));
  seen = read_all(huge, true, 5, nullptr, true);
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back().frame, 9u);
  // Unasked for, a bare C8 A5 with a plausible length (line noise) does not hold up the
  // stream behind it.
  Bytes noise = {kExtendedStart0, 0xA5, 0x00, 0x00, 0x01, 0x00};
  append(noise, packet("ARNAV", bx2_bytes(10)));
  seen = read_all(noise, true, 4);
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(seen[0].frame, 10u);
}

TEST(StreamFramer, RandomFaultStreamNeverYieldsAFrameThatWasNotSent) {
  // 1500 packets with garbage, dropped bytes, flipped bits and any chunking: every frame
  // that passes its CRCs must be byte-identical to a packet sent intact.
  std::mt19937 rng(11);
  std::map<std::uint32_t, Bytes> sent;
  Bytes wire;
  for (std::uint32_t n = 1; n <= 1500; ++n) {
    Bytes p = packet("ARNAV", bx2_bytes(n));
    sent[n] = bx2_bytes(n);
    switch (rng() % 8) {
      case 0: p[rng() % p.size()] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
      case 1: p.erase(p.begin() + static_cast<std::ptrdiff_t>(rng() % p.size())); break;
      case 2:
        for (int g = 0; g < 5; ++g) wire.push_back(static_cast<std::uint8_t>(rng()));
        break;
      case 3: append(wire, text("OKAY")); break;
      default: break;
    }
    append(wire, p);
  }
  FrameReader reader;
  reader.set_expect_binary(true);
  Frame f;
  std::size_t good = 0;
  for (std::size_t pos = 0; pos < wire.size();) {
    const std::size_t n = std::min<std::size_t>(1 + rng() % 300, wire.size() - pos);
    reader.feed(std::span(wire.data() + pos, n));
    pos += n;
    while (reader.next(f)) {
      if (!f.crc_ok || f.kind != Frame::Kind::Binary) continue;
      TrackingReply t;
      if (parse_bx2(f.bytes, t, true) != ParseError::None) continue;
      const auto it = sent.find(t.frame_number());
      ASSERT_NE(it, sent.end());
      EXPECT_TRUE(std::equal(f.bytes.begin(), f.bytes.end(), it->second.begin(), it->second.end()));
      ++good;
    }
  }
  EXPECT_GT(good, 1000u);
}

}  // namespace
}  // namespace arnav::ndi
