#include <gtest/gtest.h>

#include <sstream>

#include "appliance/ndi/test/capture.hpp"
#include "appliance/ndi/transcript.hpp"

namespace arnav::ndi {
namespace {

using Kind = TranscriptRecord::Kind;

std::string all_bytes() {
  std::string s;
  for (int i = 0; i < 256; ++i) s += static_cast<char>(i);
  return s + " ";  // trailing space must survive
}

TEST(Transcript, EscapeRoundTripsEveryByte) {
  const std::string s = all_bytes();
  auto back = unescape_bytes(escape_bytes(s));
  ASSERT_TRUE(back);
  EXPECT_EQ(*back, s);
  EXPECT_EQ(escape_bytes("OKAYA896\r"), "OKAYA896\\r");
  EXPECT_EQ(escape_bytes("TSTART "), "TSTART\\x20");
  EXPECT_FALSE(unescape_bytes("\\q"));
  EXPECT_FALSE(unescape_bytes("\\x4"));
  EXPECT_FALSE(unescape_bytes("abc\\"));
}

TEST(Transcript, WriteReadRoundTrip) {
  std::vector<TranscriptRecord> recs(6);
  recs[0] = {0, Kind::Break, "", 300, 0};
  recs[1] = {300000, Kind::Reply, "RESETBE6F\r", 0, 0};
  recs[2] = {300100, Kind::Command, "INIT:E3A5\r", 0, 0};
  recs[3] = {301000, Kind::Baud, "", 115200, 0};
  recs[4] = {302000, Kind::Reply, all_bytes(), 0, 0};
  recs[5] = {302000, Kind::Note, "bring-up done; tools: pointer ", 0, 0};
  std::stringstream ss;
  write_transcript(ss, recs);
  auto back = read_transcript(ss, "mem");
  ASSERT_EQ(back.size(), recs.size());
  for (std::size_t i = 0; i < recs.size(); ++i) {
    EXPECT_EQ(back[i].t_us, recs[i].t_us);
    EXPECT_EQ(back[i].kind, recs[i].kind);
    EXPECT_EQ(back[i].bytes, recs[i].bytes);
    EXPECT_EQ(back[i].value, recs[i].value);
    EXPECT_EQ(back[i].line, static_cast<int>(i) + 2);
  }
}

TEST(Transcript, CaptureImportsAndRoundTrips) {
  auto cap = test::load_capture();
  ASSERT_EQ(cap.size(), 1297u);
  EXPECT_EQ(cap[0].kind, Kind::Reply);
  EXPECT_EQ(cap[0].bytes, "RESETBE6F\r");
  EXPECT_EQ(cap[1].bytes, "INIT:E3A5\r");
  EXPECT_EQ(cap.back().bytes, "OKAYA896\r");
  EXPECT_GT(cap.back().t_us, 13'000'000);
  std::stringstream ss;
  write_transcript(ss, cap);
  auto back = read_transcript(ss);
  ASSERT_EQ(back.size(), cap.size());
  for (std::size_t i = 0; i < cap.size(); ++i) EXPECT_EQ(back[i].bytes, cap[i].bytes);
}

void expect_error(const std::string& text, const std::string& needle) {
  std::istringstream in(text);
  try {
    read_transcript(in, "t.txt");
    ADD_FAILURE() << "accepted: " << text;
  } catch (const TranscriptError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(Transcript, ErrorsNameTheLine) {
  const std::string h = std::string(kTranscriptHeader) + "\n";
  expect_error("", "t.txt:1: empty file");
  expect_error("hello\n", "t.txt:1: not an arnav-ndi transcript");
  expect_error(h + "# c\nabc cmd X\n", "t.txt:3: time 'abc'");
  expect_error(h + "10 cmd X\n5 cmd Y\n", "t.txt:3: time goes backwards");
  expect_error(h + "10 shout X\n", "t.txt:2: unknown record kind 'shout'");
  expect_error(h + "10 cmd A\\qB\n", "t.txt:2: malformed escape");
  expect_error(h + "10 baud fast\n", "t.txt:2: baud needs a positive integer");
  expect_error(h + "10 reply\n", "t.txt:2: empty reply record");
  expect_error(h + "10\n", "t.txt:2: expected");
}

TEST(Transcript, IgstkImportRejectsLengthMismatch) {
  std::istringstream in("1.0  :    (INFO) 1. receive[5] OKAYA896\\x0D\n");
  EXPECT_THROW(import_igstk_log(in, "log"), TranscriptError);
}

}  // namespace
}  // namespace arnav::ndi
