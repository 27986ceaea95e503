// candump log lines and files: the formats candump -l writes, and errors with file:line.
#include <gtest/gtest.h>

#include <sstream>

#include "appliance/can/candump_log.hpp"

namespace arnav::can {
namespace {

TEST(Candump, ParsesStandardExtendedRemoteErrorLines) {
  LogRecord r;
  ASSERT_EQ(parse_log_line("(1700000000.123456) can0 123#DEADBEEF", r), LogError::None);
  EXPECT_EQ(r.time_us, 1700000000123456);
  EXPECT_EQ(r.interface, "can0");
  EXPECT_EQ(r.frame.id, 0x123u);
  EXPECT_FALSE(r.frame.extended);
  EXPECT_EQ(r.frame.dlc, 4);
  EXPECT_EQ(r.frame.data[3], 0xEF);

  ASSERT_EQ(parse_log_line("(0.000001) vcan0 1ABCDEF0#", r), LogError::None);
  EXPECT_TRUE(r.frame.extended);
  EXPECT_EQ(r.frame.id, 0x1ABCDEF0u);
  EXPECT_EQ(r.frame.dlc, 0);

  ASSERT_EQ(parse_log_line("(1.5) can0 123#R", r), LogError::BadTimestamp);  // needs 6 digits
  ASSERT_EQ(parse_log_line("(1.500000) can0 123#R", r), LogError::None);
  EXPECT_TRUE(r.frame.remote);
  ASSERT_EQ(parse_log_line("(1.500000) can0 123#R3", r), LogError::None);
  EXPECT_EQ(r.frame.dlc, 3);

  ASSERT_EQ(parse_log_line("(1.500000) can0 20000040#0000000000000000", r), LogError::None);
  EXPECT_TRUE(r.frame.error);
  EXPECT_EQ(r.frame.id, 0x40u);
  EXPECT_EQ(r.frame.dlc, 8);

  ASSERT_EQ(parse_log_line("(1.500000) can0 123#11.22.33", r), LogError::None);
  EXPECT_EQ(r.frame.dlc, 3);
  ASSERT_EQ(parse_log_line("(1.500000) can0 123#1122 R", r), LogError::None);
}

TEST(Candump, RejectsBadLines) {
  LogRecord r;
  EXPECT_EQ(parse_log_line("1.500000 can0 123#11", r), LogError::NoTimestamp);
  EXPECT_EQ(parse_log_line("(1.5x0000) can0 123#11", r), LogError::BadTimestamp);
  EXPECT_EQ(parse_log_line("(1.500000) 123#11", r), LogError::NoInterface);
  EXPECT_EQ(parse_log_line("(1.500000) can0 800#11", r), LogError::BadId);
  EXPECT_EQ(parse_log_line("(1.500000) can0 12#11", r), LogError::BadId);
  EXPECT_EQ(parse_log_line("(1.500000) can0 4FFFFFFF#11", r), LogError::BadId);
  EXPECT_EQ(parse_log_line("(1.500000) can0 123#112", r), LogError::BadData);
  EXPECT_EQ(parse_log_line("(1.500000) can0 123#112233445566778899", r), LogError::BadData);
  EXPECT_EQ(parse_log_line("(1.500000) can0 123##1112233", r), LogError::CanFd);
}

TEST(Candump, FormatRoundTrips) {
  for (const char* line : {"(1700000000.123456) can0 123#DEADBEEF", "(1700000000.000001) vcan0 1ABCDEF0#00",
                           "(1.000000) can1 7FF#R", "(1.000000) can1 7FF#R8", "(2.000000) can0 20000004#0004000000000000",
                           "(3.000000) slcan0 000#"}) {
    LogRecord r;
    ASSERT_EQ(parse_log_line(line, r), LogError::None) << line;
    EXPECT_EQ(format_log_line(r), line);
  }
}

TEST(Candump, FileReaderSkipsCommentsAndNamesTheBadLine) {
  std::istringstream in("# a capture\n\n(1.000000) can0 123#01\r\n(1.000100) can0 124#02\n(1.000200) can0 zz#02\n");
  LogReader reader(in, "pedal.log");
  ASSERT_TRUE(reader.next());
  const auto second = reader.next();
  ASSERT_TRUE(second);
  EXPECT_EQ(second->frame.id, 0x124u);
  try {
    (void)reader.next();
    FAIL() << "no error";
  } catch (const LogFileError& e) {
    EXPECT_NE(std::string(e.what()).find("pedal.log:5: bad CAN id"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arnav::can
