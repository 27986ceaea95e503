#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

#include "appliance/ndi/bx.hpp"
#include "appliance/ndi/command.hpp"
#include "appliance/ndi/crc16.hpp"
#include "appliance/ndi/error_codes.hpp"
#include "appliance/ndi/reply.hpp"
#include "appliance/ndi/test/capture.hpp"

namespace arnav::ndi {
namespace {

using Kind = TranscriptRecord::Kind;

std::string_view strip_cr(const std::string& s) {
  std::string_view v(s);
  if (!v.empty() && v.back() == '\r') v.remove_suffix(1);
  return v;
}

// ---- commands -----------------------------------------------------------------------
TEST(Command, EncodesLikeRealTraffic) {
  EXPECT_EQ(encode_command("INIT", ""), "INIT:E3A5\r");
  EXPECT_EQ(encode_command("VER", "0"), "VER:065EE\r");
  EXPECT_EQ(encode_command("COMM", *comm_params(115200)), "COMM:500000048\r");
  EXPECT_EQ(encode_command("TSTART", ""), "TSTART:5423\r");
  EXPECT_EQ(encode_command("BX", "0001"), "BX:0001C26D\r");
  EXPECT_EQ(encode_command("PHSR", "02"), "PHSR:02E17E\r");
}

TEST(Command, CaptureCommandsDecodeWithValidCrc) {
  int colon_form = 0;
  for (const auto& r : test::load_capture()) {
    if (r.kind != Kind::Command) continue;
    auto c = decode_command(strip_cr(r.bytes));
    ASSERT_TRUE(c) << r.bytes;
    if (c->has_crc) {
      ++colon_form;
      EXPECT_TRUE(c->crc_ok) << r.bytes;
    }
  }
  EXPECT_GE(colon_form, 6);  // INIT, VER, COMM, 4 x PSTAT
}

TEST(Command, DecodeSpaceFormAndBadCrc) {
  auto c = decode_command("PENA 2D");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->name, "PENA");
  EXPECT_EQ(c->params, "2D");
  EXPECT_FALSE(c->has_crc);
  auto bad = decode_command("INIT:E3A6");
  ASSERT_TRUE(bad);
  EXPECT_FALSE(bad->crc_ok);
  EXPECT_FALSE(decode_command(":::"));
}

TEST(Command, BaudCodes) {
  EXPECT_EQ(*baud_code(9600), '0');
  EXPECT_EQ(*baud_code(230400), 'A');
  EXPECT_EQ(*baud_from_code('6'), 921600);
  EXPECT_FALSE(baud_code(12345));
  EXPECT_EQ(*comm_params(9600), "00000");
}

TEST(Command, PvwrPadsTheLastChunk) {
  std::vector<std::uint8_t> chunk = {'N', 'D', 'I', 0, 0xAB};
  std::string p = pvwr_params(0x0A, 0x0040, chunk);
  ASSERT_EQ(p.size(), 2u + 4u + 128u);
  EXPECT_EQ(p.substr(0, 16), "0A00404E444900AB");
  EXPECT_EQ(p.substr(16), std::string(118, '0'));
}

// ---- ASCII replies from the real capture ---------------------------------------------
TEST(AsciiReply, EveryCaptureReplyHasAValidCrc) {
  int replies = 0;
  for (const auto& r : test::load_capture()) {
    if (r.kind != Kind::Reply) continue;
    ++replies;
    ASSERT_EQ(r.bytes.back(), '\r');
    AsciiReply a;
    EXPECT_EQ(parse_ascii_reply(strip_cr(r.bytes), a), ParseError::None) << r.bytes;
  }
  EXPECT_EQ(replies, 649);
}

TEST(AsciiReply, ClassifiesCaptureReplies) {
  auto cap = test::load_capture();
  AsciiReply a;
  ASSERT_EQ(parse_ascii_reply(strip_cr(cap.at(0).bytes), a), ParseError::None);
  EXPECT_EQ(a.kind, AsciiKind::Reset);
  ASSERT_EQ(parse_ascii_reply(strip_cr(cap.at(2).bytes), a), ParseError::None);
  EXPECT_EQ(a.kind, AsciiKind::Okay);
  // VER:0 reply, multi-line.
  ASSERT_EQ(parse_ascii_reply(strip_cr(cap.at(4).bytes), a), ParseError::None);
  EXPECT_EQ(a.kind, AsciiKind::Data);
  VersionInfo v;
  ASSERT_EQ(parse_ver(a.body, v), ParseError::None);
  EXPECT_EQ(v.firmware, "Polaris Control Firmware");
  EXPECT_EQ(v.serial_number, "P1-00091");
  EXPECT_EQ(v.lines.size(), 6u);
}

TEST(AsciiReply, ErrorsAndWarnings) {
  AsciiReply a;
  ASSERT_EQ(parse_ascii_reply(strip_cr(encode_reply("ERROR0C")), a), ParseError::None);
  EXPECT_EQ(a.kind, AsciiKind::Error);
  EXPECT_EQ(a.error_code, 0x0C);
  EXPECT_EQ(error_code_info(a.error_code).symbol, "INVALID_IN_MODE");
  ASSERT_EQ(parse_ascii_reply("WARNING7423", a), ParseError::None);
  EXPECT_EQ(a.kind, AsciiKind::Warning);
  EXPECT_FALSE(a.has_code);
  EXPECT_EQ(parse_ascii_reply(strip_cr(encode_reply("ERRORZZ")), a), ParseError::BadField);
  EXPECT_EQ(parse_ascii_reply("OKAYA897", a), ParseError::BadCrc);
  EXPECT_EQ(parse_ascii_reply("OK", a), ParseError::TooShort);
}

TEST(ErrorCodes, NamesForDocumentedCodes) {
  EXPECT_EQ(error_code_info(0x01).symbol, "INVALID_COMMAND");
  EXPECT_EQ(error_code_info(0x04).symbol, "BAD_COMMAND_CRC");
  EXPECT_EQ(error_code_info(0x06).symbol, "COMM_SETTINGS_FAILED");
  EXPECT_EQ(error_code_info(0x0D).symbol, "NO_TOOL_ON_HANDLE");
  EXPECT_EQ(error_code_info(0x41).symbol, "TOOL_DEFINITION_ERROR");
  EXPECT_EQ(error_code_info(0xF1).symbol, "TOO_MUCH_INFRARED");
  EXPECT_EQ(error_code_info(0x77).symbol, "UNKNOWN_ERROR");
}

TEST(Transform, CaptureTransformsAreUnitQuaternions) {
  int transforms = 0;
  for (const auto& r : test::load_capture()) {
    if (r.kind != Kind::Reply) continue;
    std::string_view body = strip_cr(r.bytes);
    std::size_t start = 0;
    while (start < body.size()) {
      std::size_t lf = body.find('\n', start);
      if (lf == std::string_view::npos) break;
      std::string_view line = body.substr(start, lf - start);
      start = lf + 1;
      if (line.size() != kTransformChars) continue;
      HandleRecord h;
      ASSERT_EQ(parse_transform(line, h), ParseError::None) << line;
      const double n = std::sqrt(h.q_NdiTool_wxyz[0] * h.q_NdiTool_wxyz[0] + h.q_NdiTool_wxyz[1] * h.q_NdiTool_wxyz[1] +
                                  h.q_NdiTool_wxyz[2] * h.q_NdiTool_wxyz[2] + h.q_NdiTool_wxyz[3] * h.q_NdiTool_wxyz[3]);
      EXPECT_NEAR(n, 1.0, 2e-4) << line;
      EXPECT_GT(h.rms_error_mm, 0.0);
      EXPECT_LT(h.rms_error_mm, 1.0);
      ++transforms;
    }
  }
  EXPECT_GT(transforms, 600);
}

TEST(Transform, FirstCaptureTransformValues) {
  HandleRecord h;
  ASSERT_EQ(parse_transform("-04849-05520-05899+03348-001994+008181-091438+00400", h), ParseError::None);
  EXPECT_DOUBLE_EQ(h.q_NdiTool_wxyz[0], -0.4849);
  EXPECT_DOUBLE_EQ(h.q_NdiTool_wxyz[3], 0.3348);
  EXPECT_DOUBLE_EQ(h.p_NdiTool_mm[0], -19.94);
  EXPECT_DOUBLE_EQ(h.p_NdiTool_mm[2], -914.38);
  EXPECT_DOUBLE_EQ(h.rms_error_mm, 0.04);
  EXPECT_EQ(format_transform(h), "-04849-05520-05899+03348-001994+008181-091438+00400");
  EXPECT_EQ(parse_transform("-04849-05520-05899+03348-001994+008181-091438+0040x", h), ParseError::BadField);
}

// ---- TX -----------------------------------------------------------------------------
TEST(Tx, DocumentedExampleFields) {
  // Field values quoted in ndi-capi.md from a real TX reply.
  std::string body = "0101+07066+07050-00372-00462-024011+006470-156467+0185500000031000001BD\n0000";
  TrackingReply t;
  ASSERT_EQ(parse_tx(body, t), ParseError::None);
  ASSERT_EQ(t.count, 1u);
  const auto& h = t.handles[0];
  EXPECT_EQ(h.handle, 1);
  EXPECT_EQ(h.state, HandleState::Valid);
  EXPECT_DOUBLE_EQ(h.q_NdiTool_wxyz[1], 0.7050);
  EXPECT_DOUBLE_EQ(h.p_NdiTool_mm[2], -1564.67);
  EXPECT_DOUBLE_EQ(h.rms_error_mm, 0.1855);
  EXPECT_EQ(h.port_status, 0x31u);
  EXPECT_EQ(h.frame_number, 445u);
  EXPECT_EQ(format_tx_body(t), body);
}

TrackingReply sample_reply(std::size_t n) {
  TrackingReply t;
  t.count = n;
  for (std::size_t i = 0; i < n; ++i) {
    auto& h = t.handles[i];
    h.handle = static_cast<std::uint8_t>(0x0A + i);
    h.state = i == 1 ? HandleState::Missing : i == 2 ? HandleState::Disabled : HandleState::Valid;
    h.q_NdiTool_wxyz = {0.5, 0.5, -0.5, 0.5};
    h.p_NdiTool_mm = {10.25 * static_cast<double>(i), -64.5, -1500.75};
    h.rms_error_mm = 0.125;
    h.has_status = h.state != HandleState::Disabled;
    h.port_status = h.has_status ? (kPortOccupied | kPortInitialised | kPortEnabled | (i == 3 ? kPortOutOfVolume : 0u)) : 0u;
    h.frame_number = h.has_status ? 1234567u : 0u;
  }
  t.system_status = kSysTooMuchInfrared;
  return t;
}

TEST(Tx, RoundTripWithMissingDisabledAndOutOfVolume) {
  TrackingReply in = sample_reply(6);
  TrackingReply out;
  ASSERT_EQ(parse_tx(format_tx_body(in), out), ParseError::None);
  ASSERT_EQ(out.count, 6u);
  EXPECT_EQ(out.handles[1].state, HandleState::Missing);
  EXPECT_EQ(out.handles[1].frame_number, 1234567u);
  EXPECT_EQ(out.handles[2].state, HandleState::Disabled);
  EXPECT_FALSE(out.handles[2].has_status);
  EXPECT_TRUE(out.handles[3].out_of_volume());
  EXPECT_DOUBLE_EQ(out.handles[5].p_NdiTool_mm[0], 51.25);
  EXPECT_EQ(out.system_status, kSysTooMuchInfrared);
  EXPECT_EQ(out.frame_number(), 1234567u);
}

TEST(Tx, RejectsMalformedBodies) {
  TrackingReply t;
  std::string good = format_tx_body(sample_reply(2));
  EXPECT_EQ(parse_tx(good.substr(0, good.size() - 1), t), ParseError::TooShort);
  EXPECT_EQ(parse_tx("0", t), ParseError::TooShort);
  EXPECT_EQ(parse_tx("FF" + good.substr(2), t), ParseError::TooManyHandles);
  EXPECT_EQ(parse_tx(good + "0", t), ParseError::TrailingBytes);
  std::string missing_status = "010AMISSING\n0000";
  EXPECT_EQ(parse_tx(missing_status, t), ParseError::BadField);
  EXPECT_EQ(parse_tx("010AUNOCCUPIED\n0000", t), ParseError::None);
  EXPECT_EQ(t.handles[0].state, HandleState::Unoccupied);
}

// ---- PHSR, PHRQ, PHINF ----------------------------------------------------------------
TEST(PortHandles, PhsrPhrqPhinf) {
  std::vector<PhsrEntry> e;
  ASSERT_EQ(parse_phsr("020A0010B031", e), ParseError::None);
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[1].handle, 0x0B);
  EXPECT_EQ(e[1].status, 0x031);
  ASSERT_EQ(parse_phsr("00", e), ParseError::None);
  EXPECT_TRUE(e.empty());
  EXPECT_EQ(parse_phsr("020A001", e), ParseError::TooShort);
  EXPECT_EQ(parse_phsr("010A00G", e), ParseError::BadField);
  std::uint8_t h = 0;
  ASSERT_EQ(parse_phrq("0A", h), ParseError::None);
  EXPECT_EQ(h, 0x0A);
  EXPECT_EQ(parse_phrq("0A1", h), ParseError::TrailingBytes);
  PortHandleInfo info;
  const std::string type = "08000000", maker = "NDI         ", rev = "000", serial = "08700340";
  ASSERT_EQ(maker.size(), 12u);
  ASSERT_EQ(parse_phinf_basic(type + maker + rev + serial + "3G", info), ParseError::BadField);
  ASSERT_EQ(parse_phinf_basic(type + maker + rev + serial + "310", info), ParseError::TrailingBytes);
  ASSERT_EQ(parse_phinf_basic(type + maker + rev + serial + "3", info), ParseError::TooShort);
  ASSERT_EQ(parse_phinf_basic(type + maker + rev + serial + "31", info), ParseError::None);
  EXPECT_EQ(info.tool_type, "08000000");
  EXPECT_EQ(info.serial_number, "08700340");
  EXPECT_EQ(info.manufacturer, "NDI");
  EXPECT_EQ(info.port_status, 0x31);
}

// ---- BX -----------------------------------------------------------------------------
void put_f(std::vector<std::uint8_t>& v, float f) {
  std::uint8_t b[4];
  std::memcpy(b, &f, 4);  // little-endian host (x86, arm)
  v.insert(v.end(), b, b + 4);
}

TEST(Bx, HandBuiltFrameFromTheSpec) {
  // One valid handle 0x0A and one disabled handle 0x0B, built byte by byte.
  std::vector<std::uint8_t> body = {2, 0x0A, 0x01};
  for (float f : {1.0f, 0.0f, 0.0f, 0.0f, 12.5f, -3.25f, -1500.0f, 0.2f}) put_f(body, f);
  body.insert(body.end(), {0x31, 0, 0, 0, 0x10, 0x27, 0, 0});  // port status 0x31, frame 10000
  body.insert(body.end(), {0x0B, 0x04});
  body.insert(body.end(), {0x00, 0x01});  // system status 0x0100
  std::vector<std::uint8_t> frame = {0xC4, 0xA5, static_cast<std::uint8_t>(body.size()), 0};
  std::uint16_t hcrc = crc16(std::span<const std::uint8_t>(frame.data(), 4));
  frame.push_back(hcrc & 0xFF);
  frame.push_back(hcrc >> 8);
  frame.insert(frame.end(), body.begin(), body.end());
  std::uint16_t bcrc = crc16(body);
  frame.push_back(bcrc & 0xFF);
  frame.push_back(bcrc >> 8);

  TrackingReply t;
  ASSERT_EQ(parse_bx(frame, t), ParseError::None);
  ASSERT_EQ(t.count, 2u);
  EXPECT_EQ(t.handles[0].state, HandleState::Valid);
  EXPECT_DOUBLE_EQ(t.handles[0].p_NdiTool_mm[1], -3.25);
  EXPECT_NEAR(t.handles[0].rms_error_mm, 0.2, 1e-7);
  EXPECT_EQ(t.handles[0].port_status, 0x31u);
  EXPECT_EQ(t.handles[0].frame_number, 10000u);
  EXPECT_EQ(t.handles[1].state, HandleState::Disabled);
  EXPECT_EQ(t.system_status, 0x0100);
  EXPECT_EQ(t.frame_number(), 10000u);

  // Our encoder produces the identical bytes.
  std::vector<std::uint8_t> encoded;
  encode_bx(t, encoded);
  EXPECT_EQ(encoded, frame);
}

TEST(Bx, RoundTripSixTools) {
  TrackingReply in = sample_reply(6), out;
  std::vector<std::uint8_t> frame;
  encode_bx(in, frame);
  ASSERT_EQ(parse_bx(frame, out), ParseError::None);
  ASSERT_EQ(out.count, 6u);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(out.handles[i].handle, in.handles[i].handle);
    EXPECT_EQ(out.handles[i].state, in.handles[i].state);
    EXPECT_EQ(out.handles[i].port_status, in.handles[i].port_status);
  }
  EXPECT_TRUE(out.handles[3].out_of_volume());
  EXPECT_DOUBLE_EQ(out.handles[4].p_NdiTool_mm[0], 41.0);
}

TEST(Bx, EverySingleByteCorruptionIsRejected) {
  std::vector<std::uint8_t> frame;
  encode_bx(sample_reply(6), frame);
  TrackingReply t;
  for (std::size_t i = 0; i < frame.size(); ++i) {
    for (std::uint8_t mask : {0x01, 0x10, 0x80, 0xFF}) {
      auto bad = frame;
      bad[i] ^= mask;
      EXPECT_NE(parse_bx(bad, t), ParseError::None) << "byte " << i;
      EXPECT_EQ(t.count, 0u);
    }
  }
}

TEST(Bx, TruncatedAndInconsistentFrames) {
  std::vector<std::uint8_t> frame;
  encode_bx(sample_reply(3), frame);
  TrackingReply t;
  EXPECT_EQ(parse_bx(std::span(frame).first(5), t), ParseError::TooShort);
  EXPECT_EQ(parse_bx(std::span(frame).first(frame.size() - 1), t), ParseError::LengthMismatch);
  // Body that claims 3 handles but holds the bytes for fewer (CRCs recomputed).
  TrackingReply lie = sample_reply(3);
  std::vector<std::uint8_t> f2;
  encode_bx(lie, f2);
  f2[6] = 5;  // count
  std::uint16_t len = static_cast<std::uint16_t>(f2[2] | (f2[3] << 8));
  std::uint16_t c = crc16(std::span<const std::uint8_t>(f2.data() + 6, len));
  f2[6 + len] = c & 0xFF;
  f2[7 + len] = c >> 8;
  EXPECT_NE(parse_bx(f2, t), ParseError::None);
  EXPECT_EQ(t.count, 0u);
  f2[6] = 3;
  f2[8] = 0x09;  // unknown status byte of the first handle
  c = crc16(std::span<const std::uint8_t>(f2.data() + 6, len));
  f2[6 + len] = c & 0xFF;
  f2[7 + len] = c >> 8;
  EXPECT_EQ(parse_bx(f2, t), ParseError::BadStatus);
}

TEST(Pose, XNdiToolFromQuaternionWFirst) {
  HandleRecord h;
  h.q_NdiTool_wxyz = {std::sqrt(0.5), std::sqrt(0.5), 0.0, 0.0};  // +90 deg about x
  h.p_NdiTool_mm = {1.0, 2.0, 3.0};
  Eigen::Isometry3d X = X_NdiTool(h);
  Eigen::Vector3d p = X * Eigen::Vector3d(0.0, 1.0, 0.0);
  EXPECT_NEAR(p.x(), 1.0, 1e-12);
  EXPECT_NEAR(p.y(), 2.0, 1e-12);
  EXPECT_NEAR(p.z(), 4.0, 1e-12);
}

}  // namespace
}  // namespace arnav::ndi
