// The `can:` section: a full example, and every error names file:line and the key.
#include <gtest/gtest.h>

#include "appliance/can/can_config.hpp"
#include "appliance/can/test/test_config.hpp"

namespace arnav::can {
namespace {

TEST(CanConfig, ParsesTheExample) {
  const auto c = parse_can_config(test::kPedalConfig, "a.yaml");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->interface, "vcan0");
  EXPECT_FALSE(c->slcan);
  ASSERT_EQ(c->nodes.size(), 2u);
  EXPECT_EQ(c->nodes[0].id, 0x710u);
  EXPECT_EQ(c->nodes[0].liveness, NodeConfig::Liveness::Heartbeat);
  EXPECT_EQ(c->nodes[1].id, 0x185u);
  ASSERT_EQ(c->inputs.size(), 4u);
  EXPECT_EQ(c->inputs[1].active_high, false);
  EXPECT_TRUE(c->inputs[2].analog);
  EXPECT_EQ(c->inputs[2].size, 2);
  EXPECT_EQ(c->inputs[3].node, 1u);
  EXPECT_EQ(c->ids().size(), 4u);  // 0x710, 0x185, 0x190, 0x191
  EXPECT_EQ(c->priority, 50);
  EXPECT_EQ(c->status_poll_ms, 500);
}

TEST(CanConfig, NoSectionIsNotAnError) { EXPECT_FALSE(parse_can_config("port: sim\n", "a.yaml")); }

TEST(CanConfig, Slcan) {
  const auto c = parse_can_config(
      "can:\n  interface: slcan:/dev/ttyUSB0\n  bitrate: 250000\n  serial_baud: 921600\n"
      "  nodes: [{name: p, periodic_id: 0x100, timeout_ms: 50}]\n  inputs: [{name: x, node: p, id: 0x100, bit: 3}]\n",
      "a.yaml");
  ASSERT_TRUE(c);
  EXPECT_TRUE(c->slcan);
  EXPECT_EQ(c->port, "/dev/ttyUSB0");
  EXPECT_EQ(c->bitrate, 250000);
  EXPECT_EQ(c->serial_baud, 921600);
}

void expect_error(const std::string& text, const std::string& want) {
  try {
    (void)parse_can_config(text, "cfg.yaml");
    ADD_FAILURE() << "no error for:\n" << text;
  } catch (const CanConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(want), std::string::npos) << "got: " << e.what() << "\nwant: " << want;
  }
}

std::string with(const std::string& from, const std::string& to) {
  std::string s = test::kPedalConfig;
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return s.replace(pos, from.size(), to);
}

TEST(CanConfig, ErrorsNameFileLineAndKey) {
  expect_error(with("interface: vcan0", "interface: \"slcan:\""), "cfg.yaml:2: key 'can.interface': 'slcan:' needs a serial port");
  expect_error(with("interface: vcan0", "interface: a/b"), "cfg.yaml:2: key 'can.interface'");
  expect_error(with("interface: vcan0", "interface: vcan0\n  bitrate: 83333"), "cfg.yaml:3: key 'can.bitrate': 83333 is not a CAN rate");
  expect_error(with("interface: vcan0", "interface: vcan0\n  serial_baud: 115200"), "key 'can.serial_baud': only for an slcan adapter");
  expect_error(with("heartbeat: 0x10", "heartbeat: 0x80"), "cfg.yaml:5: key 'can.nodes[0].heartbeat': '0x80' is above 0x7F");
  expect_error(with("heartbeat: 0x10", "heartbeat: ten"), "key 'can.nodes[0].heartbeat': expected an integer");
  expect_error(with("      heartbeat: 0x10\n", ""), "key 'can.nodes[0]': how is this device known to be alive?");
  expect_error(with("      timeout_ms: 300\n", ""), "key 'can.nodes[0].timeout_ms': missing");
  expect_error(with("periodic_id: 0x185", "periodic_id: 0x800"), "cfg.yaml:8: key 'can.nodes[1].periodic_id': '0x800' is above 0x7FF");
  expect_error(with("name: grasper\n", "name: pedal\n"), "duplicate node name 'pedal'");
  expect_error(with("node: grasper", "node: gripper"), "key 'can.inputs[3].node': 'gripper' is not one of can.nodes");
  expect_error(with("      bit: 7\n", ""), "key 'can.inputs[3]': give 'bit: 0-7'");
  expect_error(with("bit: 7", "bit: 8"), "key 'can.inputs[3].bit': must be between 0 and 7");
  expect_error(with("active: low", "active: down"), "cfg.yaml:22: key 'can.inputs[1].active': must be 'high' or 'low'");
  expect_error(with("range: [200, 800]", "range: [800, 200]"), "key 'can.inputs[2].range': need 0 <= released < pressed");
  expect_error(with("range: [200, 800]", "range: [200, 80000]"), "need 0 <= released < pressed <= 65535");
  expect_error(with("      byte: 1\n      size: 2", "      byte: 7\n      size: 2"), "key 'can.inputs[2].size': byte + size runs past");
  expect_error(with("name: pedal_accept", "name: pedal_cut"), "duplicate input name 'pedal_cut'");
  expect_error(with("debounce_ms: 10", "debounce_ms: -1"), "key 'can.inputs[3].debounce_ms': must be between 0 and 10000");
  expect_error(with("debounce_ms: 10", "debounce: 10"), "key 'can.inputs[3].debounce': unknown key");
  expect_error(with("interface: vcan0", "interface: vcan0\n  priority: 100"), "cfg.yaml:3: key 'can.priority': must be between 0 and 99");
  expect_error("can:\n  interface: can0\n  nodes: []\n", "key 'can.nodes': expected a non-empty list");
  expect_error("can:\n  nodes: []\n", "cfg.yaml:2: key 'can.interface': missing");
  expect_error("can: [1\n", "YAML syntax error");
}

}  // namespace
}  // namespace arnav::can
