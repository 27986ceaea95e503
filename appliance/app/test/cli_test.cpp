// The executables' exit codes and messages for bad input (run as child processes).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "protocol/testing/child_process.hpp"

namespace {

using Result = arnav::testing::CommandResult;
using arnav::testing::data_dir;

Result run(const std::string& command) { return arnav::testing::run_command(command); }
std::string bin(const std::string& rel) { return arnav::testing::binary_path(rel); }
std::filesystem::path temp_file(const std::string& name, const std::string& content) {
  return arnav::testing::write_temp_file("arnav_cli_test", name, content);
}

TEST(ApplianceCli, ConfigErrorExits2WithKeyAndLine) {
  const auto cfg = temp_file("bad.yaml", "port: sim\nbaud: 12345\ntools:\n  - name: p\n    rom: " + data_dir() +
                                             "/ndi_roms/8700340.rom\n");
  const Result r = run(bin("appliance/app/arnav-appliance") + " " + cfg.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(cfg.string() + ":2: key 'baud'"), std::string::npos) << r.output;
  std::filesystem::remove(cfg);
}

TEST(ApplianceCli, UnknownPortListsPortsAndExits2) {
  const auto cfg = temp_file("port.yaml", "port: /dev/arnav-no-such-port\ntools:\n  - name: p\n    rom: " + data_dir() +
                                              "/ndi_roms/8700340.rom\n");
  const Result r = run(bin("appliance/app/arnav-appliance") + " " + cfg.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(":1: key 'port': no serial port '/dev/arnav-no-such-port'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Ports on this machine"), std::string::npos) << r.output;
  std::filesystem::remove(cfg);
}

TEST(ApplianceCli, MissingConfigAndHelp) {
  EXPECT_EQ(run(bin("appliance/app/arnav-appliance") + " /nonexistent.yaml").code, 2);
  EXPECT_EQ(run(bin("appliance/app/arnav-appliance")).code, 2);
  const Result help = run(bin("appliance/app/arnav-appliance") + " --help");
  EXPECT_EQ(help.code, 0);
  EXPECT_NE(help.output.find("--check"), std::string::npos);
}

TEST(NdiCli, DecodeRawCaptureBytes) {
  // Raw bytes of the first three replies of the real capture: RESET, OKAY, VER.
  std::string wire = "RESETBE6F\rOKAYA896\rPolaris Control Firmware\nNDI S/N: P1-00091\n31C2\r";
  const auto file = temp_file("replies.bin", wire);
  const Result r = run(bin("appliance/tools/arnav-ndi") + " decode " + file.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("\"kind\":\"reset\""), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"kind\":\"okay\""), std::string::npos);
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 3);
  std::filesystem::remove(file);
}

TEST(NdiCli, UsageErrorsExit2) {
  const Result r = run(bin("appliance/tools/arnav-ndi") + " probe /dev/arnav-no-such-port");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("Ports on this machine"), std::string::npos);
  const auto notrom = temp_file("notrom.rom", "hello");
  const Result t = run(bin("appliance/tools/arnav-ndi") + " track /dev/ttyS0 --tool " + notrom.string());
  EXPECT_EQ(t.code, 2) << t.output;
  EXPECT_NE(t.output.find(notrom.string()), std::string::npos) << t.output;
  std::filesystem::remove(notrom);
  EXPECT_EQ(run(bin("appliance/tools/arnav-ndi")).code, 2);
  EXPECT_EQ(run(bin("appliance/tools/arnav-ndi") + " --help").code, 0);
}

}  // namespace
