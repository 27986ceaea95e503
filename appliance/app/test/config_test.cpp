#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

#include "appliance/app/config.hpp"

namespace arnav::app {
namespace {

std::filesystem::path roms() {
  const char* data = std::getenv("ARNAV_DATA_DIR");
  if (!data) throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
  return std::filesystem::path(data) / "ndi_roms";
}

AppConfig parse(const std::string& text) { return parse_config(text, "cfg.yaml", roms()); }

void expect_error(const std::string& text, const std::string& needle) {
  try {
    parse(text);
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what() << "\n  wanted: " << needle;
  }
}

const std::string kTools = "tools:\n  - name: pointer\n    rom: 8700340.rom\n";

TEST(Config, FullExample) {
  AppConfig c = parse(
      "port: sim\n"
      "baud: 57600\n"
      "rate_hz: 60\n"
      "lcm_url: memq://\n"
      "reply_mode: tx\n"
      "tx_firmware: [\"Rev 007\"]\n"
      "sim_args: [\"--tools\", \"2\"]\n" +
      kTools + "  - {name: ref, rom: 8700339.rom}\n");
  EXPECT_EQ(c.port, "sim");
  EXPECT_EQ(c.baud, 57600);
  EXPECT_FALSE(c.use_bx);
  ASSERT_EQ(c.tools.size(), 2u);
  EXPECT_EQ(c.tools[1].name, "ref");
  EXPECT_EQ(c.tools[1].rom_path, roms() / "8700339.rom");
  EXPECT_EQ(c.sim_args.size(), 2u);
  EXPECT_DOUBLE_EQ(c.device_rate_hz, 60.0);
  auto s = c.session_config();
  EXPECT_EQ(s.target_baud, 57600);
  EXPECT_EQ(s.tx_firmware.at(0), "Rev 007");
}

TEST(Config, ErrorsNameKeyAndLine) {
  expect_error("port: sim\nbaud: 12345\n" + kTools, "cfg.yaml:2: key 'baud': 12345 is not an NDI rate");
  expect_error("port: sim\nbaud: fast\n" + kTools, "cfg.yaml:2: key 'baud': expected an integer, got 'fast'");
  expect_error("port: sim\nbuad: 9600\n" + kTools, "cfg.yaml:2: key 'buad': unknown key");
  expect_error(kTools, "key 'port': missing");
  expect_error("port: sim\n", "key 'tools': missing");
  expect_error("port: sim\nrate_hz: -3\n" + kTools, "cfg.yaml:2: key 'rate_hz': must be > 0");
  expect_error("port: sim\nreply_mode: binary\n" + kTools, "cfg.yaml:2: key 'reply_mode': must be 'bx' or 'tx'");
  expect_error("port: sim\ntools:\n  - name: a\n    rom: nope.rom\n", "cfg.yaml:4: key 'tools[0].rom':");
  expect_error("port: sim\ntools:\n  - name: a\n", "cfg.yaml:3: key 'tools[0].rom': missing");
  expect_error("port: sim\ntools:\n  - name: a b\n    rom: 8700340.rom\n", "cfg.yaml:3: key 'tools[0].name'");
  expect_error("port: sim\n" + kTools + "  - name: pointer\n    rom: 8700339.rom\n",
               "cfg.yaml:5: key 'tools[1].name': duplicate tool name 'pointer'");
  expect_error("port: sim\n" + kTools + "    colour: red\n", "cfg.yaml:5: key 'tools[0].colour': unknown key");
  expect_error("port: [sim\n", "cfg.yaml:2: YAML syntax error");
  expect_error("port: sim\nsim_args: --fast\n" + kTools, "cfg.yaml:2: key 'sim_args': expected a list of strings");
}

TEST(Config, NonNdiRomIsAConfigError) {
  auto bad = std::filesystem::temp_directory_path() / "arnav_config_test_notarom.rom";
  { std::ofstream(bad) << "plain text"; }
  expect_error("port: sim\ntools:\n  - name: a\n    rom: " + bad.string() + "\n",
               "cfg.yaml:4: key 'tools[0].rom': " + bad.string() + ": not an NDI tool definition");
  std::filesystem::remove(bad);
}

TEST(Config, EthernetTrackerSection) {
  AppConfig c = parse("ndi: {host: 192.168.1.50, port: 9000, stream: false, connect_timeout_ms: 500}\n" + kTools);
  EXPECT_EQ(c.ndi_host, "192.168.1.50");
  EXPECT_EQ(c.ndi_port, 9000);
  EXPECT_FALSE(c.ndi_stream);
  EXPECT_EQ(c.connect_timeout_ms, 500);
  EXPECT_EQ(c.port, "tcp:192.168.1.50:9000");
  EXPECT_FALSE(c.session_config().stream);
  c = parse("ndi:\n  host: P9-B0103.local\n" + kTools);
  EXPECT_EQ(c.ndi_port, 8765);
  EXPECT_TRUE(c.session_config().stream);
  expect_error("port: sim\nndi: {host: a}\n" + kTools, "cfg.yaml:2: key 'ndi': give either 'port'");
  expect_error("ndi: {port: 8765}\n" + kTools, "cfg.yaml:1: key 'ndi.host': missing");
  expect_error("ndi: {host: a, port: 70000}\n" + kTools, "cfg.yaml:1: key 'ndi.port': must be a TCP port");
  expect_error("ndi: {host: a, streem: true}\n" + kTools, "key 'ndi.streem': unknown key");
  expect_error("ndi: 192.168.1.50\n" + kTools, "cfg.yaml:1: key 'ndi': expected a mapping");
}

}  // namespace
}  // namespace arnav::app
