// arnav-appliance with a can: section and arnav-can, run as child processes: --check
// summaries, configuration errors (exit 2, file:line), arnav-can usage, log and bus errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "protocol/testing/child_process.hpp"

#include "appliance/can/test/test_config.hpp"

namespace {

using Result = arnav::testing::CommandResult;
using arnav::testing::data_dir;

Result run(const std::string& command) { return arnav::testing::run_command(command); }
std::string bin(const std::string& rel) { return arnav::testing::binary_path(rel); }
std::filesystem::path temp_file(const std::string& name, const std::string& content) {
  return arnav::testing::write_temp_file("arnav_can_cli", name, content);
}

TEST(ApplianceCan, CheckCanOnlyAndNdiPlusCan) {
  const auto only = temp_file("only.yaml", std::string("security: off\n") + arnav::can::test::kPedalConfig);
  Result r = run(bin("appliance/app/arnav-appliance") + " --check " + only.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("CAN vcan0: 4 input(s), 2 device(s), no NDI"), std::string::npos) << r.output;
  const auto both = temp_file("both.yaml", "security: off\nport: sim\ntools:\n  - name: p\n    rom: " + data_dir() + "/ndi_roms/8700340.rom\n" +
                                               arnav::can::test::kPedalConfig);
  r = run(bin("appliance/app/arnav-appliance") + " --check " + both.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("1 tool(s), port sim; CAN vcan0: 4 input(s)"), std::string::npos) << r.output;
  std::filesystem::remove(only);
  std::filesystem::remove(both);
}

TEST(ApplianceCan, BadCanSectionExits2WithFileLineKey) {
  std::string text = arnav::can::test::kPedalConfig;
  text.replace(text.find("bit: 7"), 6, "bit: 9");
  const auto cfg = temp_file("bad.yaml", text);
  const Result r = run(bin("appliance/app/arnav-appliance") + " " + cfg.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(cfg.string() + ":35: key 'can.inputs[3].bit': must be between 0 and 7"), std::string::npos) << r.output;
  std::filesystem::remove(cfg);
}

TEST(CanTool, UsageLogAndBusErrors) {
  const std::string tool = bin("appliance/can/arnav-can");
  EXPECT_EQ(run(tool).code, 2);
  EXPECT_EQ(run(tool + " listen").code, 2);
  EXPECT_EQ(run(tool + " --help").code, 0);
  const auto cfg = temp_file("cfg.yaml", arnav::can::test::kPedalConfig);
  const auto log = temp_file("bad.log", "(1.000000) can0 710#05\n(1.000100) can0 190#0\n");
  Result r = run(tool + " decode " + log.string() + " --config " + cfg.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(log.string() + ":2: bad data"), std::string::npos) << r.output;
  const auto good = temp_file("good.log", "(1.000000) can0 710#05\n(1.010000) can0 190#03\n(1.100000) can0 190#02\n");
  r = run(tool + " decode " + good.string() + " --config " + cfg.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("(1.030000) INPUT pedal_cut pressed (after 20 ms debounce)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("(1.100000) INPUT pedal_cut released"), std::string::npos) << r.output;
  r = run(tool + " decode /nonexistent.log --config " + cfg.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("/nonexistent.log: cannot read the log file"), std::string::npos) << r.output;
  // A bus that cannot be opened (no AF_CAN here, or no such interface) is exit 2 with why.
  r = run("env -u LD_PRELOAD " + tool + " listen arnavnope0 --count 1");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("arnavnope0:"), std::string::npos) << r.output;
  r = run(tool + " listen slcan:/dev/arnav-no-such-port --count 1");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no serial port '/dev/arnav-no-such-port'"), std::string::npos) << r.output;
  r = run(tool + " listen vcan0 --bitrate 33");
  EXPECT_EQ(r.code, 2) << r.output;
  std::filesystem::remove(cfg);
  std::filesystem::remove(log);
  std::filesystem::remove(good);
}

}  // namespace
