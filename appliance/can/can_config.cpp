#include "appliance/can/can_config.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <set>
#include <sstream>

#include "appliance/can/slcan.hpp"
#include "protocol/yaml/yaml_reader.hpp"

namespace arnav::can {
namespace {

using Reader = yaml::YamlReader<CanConfigError>;

// Integers in decimal or 0x hex (CAN ids are written in hex).
std::uint32_t id_value(const Reader& r, const YAML::Node& n, const std::string& key, std::uint32_t max) {
  const std::string s = r.get<std::string>(n, key, "an integer (decimal or 0x hex)");
  std::size_t used = 0;
  unsigned long long v = 0;
  try {
    v = std::stoull(s, &used, 0);
  } catch (const std::exception&) {
    r.fail(n, key, "expected an integer (decimal or 0x hex), got '" + s + "'");
  }
  if (used != s.size() || s.empty() || s[0] == '-') r.fail(n, key, "expected an integer (decimal or 0x hex), got '" + s + "'");
  if (v > max) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "0x%X", max);
    r.fail(n, key, "'" + s + "' is above " + buf);
  }
  return static_cast<std::uint32_t>(v);
}

void check_name(const Reader& r, const YAML::Node& n, const std::string& key, const std::string& name) {
  if (name.empty()) r.fail(n, key, "empty");
  for (char ch : name)
    if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-'))
      r.fail(n, key, "'" + name + "' may only hold letters, digits, '_' and '-'");
}

}  // namespace

std::vector<std::pair<std::uint32_t, bool>> CanConfig::ids() const {
  std::vector<std::pair<std::uint32_t, bool>> out;
  auto add = [&](std::uint32_t id, bool ext) {
    if (std::find(out.begin(), out.end(), std::make_pair(id, ext)) == out.end()) out.emplace_back(id, ext);
  };
  for (const auto& n : nodes) add(n.id, n.extended);
  for (const auto& i : inputs) add(i.id, i.extended);
  return out;
}

CanConfig parse_can_section(const YAML::Node& can, const std::string& source) {
  Reader r(source);
  r.only(can, "can", {"interface", "bitrate", "serial_baud", "status_poll_ms", "priority", "nodes", "inputs"});
  CanConfig c;
  c.source = source;
  if (!can["interface"]) r.fail(can, "can.interface", "missing: a SocketCAN interface (can0, vcan0) or slcan:/dev/ttyUSB0");
  c.interface = r.get<std::string>(can["interface"], "can.interface", "a string");
  c.interface_line = can["interface"].Mark().line + 1;
  if (c.interface.rfind("slcan:", 0) == 0) {
    c.slcan = true;
    c.port = c.interface.substr(6);
    if (c.port.empty()) r.fail(can["interface"], "can.interface", "'slcan:' needs a serial port, e.g. slcan:/dev/ttyUSB0");
  } else {
    if (c.interface.empty() || c.interface.size() >= 16)
      r.fail(can["interface"], "can.interface", "'" + c.interface + "' is not a network interface name (1-15 characters)");
    for (char ch : c.interface)
      if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-' || ch == '.'))
        r.fail(can["interface"], "can.interface", "'" + c.interface + "' is not a network interface name (letters, digits, _ - .)");
  }
  if (can["bitrate"]) {
    c.bitrate = r.get<int>(can["bitrate"], "can.bitrate", "an integer");
    if (!slcan::bitrate_code(c.bitrate))
      r.fail(can["bitrate"], "can.bitrate", std::to_string(c.bitrate) + " is not a CAN rate slcan can set (10000, 20000, 50000, 100000, 125000, 250000, 500000, 800000, 1000000)");
  }
  c.serial_baud = r.integer(can, "can", "serial_baud", c.serial_baud, 9600, 4000000);
  c.status_poll_ms = r.integer(can, "can", "status_poll_ms", c.status_poll_ms, 10, 60000);
  c.priority = r.integer(can, "can", "priority", c.priority, 0, 99);
  if (!c.slcan && can["serial_baud"]) r.fail(can["serial_baud"], "can.serial_baud", "only for an slcan adapter (interface: slcan:PORT)");

  const YAML::Node nodes = can["nodes"];
  if (!nodes) r.fail(can, "can.nodes", "missing: list the devices on the bus, each with a heartbeat or periodic_id and timeout_ms");
  if (!nodes.IsSequence() || nodes.size() == 0) r.fail(nodes, "can.nodes", "expected a non-empty list of {name, heartbeat | periodic_id, timeout_ms}");
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const std::string k = "can.nodes[" + std::to_string(i) + "]";
    const YAML::Node n = nodes[i];
    r.only(n, k, {"name", "heartbeat", "periodic_id", "extended", "timeout_ms"});
    NodeConfig node;
    if (!n["name"]) r.fail(n, k + ".name", "missing");
    node.name = r.get<std::string>(n["name"], k + ".name", "a string");
    check_name(r, n["name"], k + ".name", node.name);
    for (const auto& other : c.nodes)
      if (other.name == node.name) r.fail(n["name"], k + ".name", "duplicate node name '" + node.name + "'");
    if (n["heartbeat"] && n["periodic_id"]) r.fail(n, k, "give either 'heartbeat' (CANopen node id) or 'periodic_id', not both");
    node.extended = r.boolean(n, k, "extended", false);
    if (n["heartbeat"]) {
      node.liveness = NodeConfig::Liveness::Heartbeat;
      const std::uint32_t nid = id_value(r, n["heartbeat"], k + ".heartbeat", 127);
      if (nid == 0) r.fail(n["heartbeat"], k + ".heartbeat", "a CANopen node id is 1-127");
      if (node.extended) r.fail(n["extended"], k + ".extended", "CANopen heartbeats use standard ids");
      node.node_id = static_cast<std::uint8_t>(nid);
      node.id = 0x700 + nid;
    } else if (n["periodic_id"]) {
      node.liveness = NodeConfig::Liveness::Periodic;
      node.id = id_value(r, n["periodic_id"], k + ".periodic_id", node.extended ? kMaxExtendedId : kMaxStandardId);
    } else {
      r.fail(n, k, "how is this device known to be alive? give 'heartbeat: NODE_ID' (CANopen, id 0x700+N) or 'periodic_id: ID'");
    }
    if (!n["timeout_ms"]) r.fail(n, k + ".timeout_ms", "missing: after how long without a frame is the device lost (its inputs are released)");
    node.timeout_ms = r.integer(n, k, "timeout_ms", 0, 5, 60000);
    c.nodes.push_back(node);
  }

  const YAML::Node inputs = can["inputs"];
  if (!inputs) r.fail(can, "can.inputs", "missing: list the inputs, each with name, node, id and bit or range");
  if (!inputs.IsSequence() || inputs.size() == 0) r.fail(inputs, "can.inputs", "expected a non-empty list of inputs");
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const std::string k = "can.inputs[" + std::to_string(i) + "]";
    const YAML::Node n = inputs[i];
    r.only(n, k, {"name", "node", "id", "extended", "byte", "bit", "active", "range", "size", "big_endian", "debounce_ms", "release_debounce_ms"});
    InputConfig in;
    if (!n["name"]) r.fail(n, k + ".name", "missing");
    in.name = r.get<std::string>(n["name"], k + ".name", "a string");
    check_name(r, n["name"], k + ".name", in.name);
    for (const auto& other : c.inputs)
      if (other.name == in.name) r.fail(n["name"], k + ".name", "duplicate input name '" + in.name + "'");
    if (!n["node"]) r.fail(n, k + ".node", "missing: which device (under can.nodes) sends it; its loss releases the input");
    const std::string node = r.get<std::string>(n["node"], k + ".node", "a string");
    bool found = false;
    for (std::size_t j = 0; j < c.nodes.size(); ++j)
      if (c.nodes[j].name == node) {
        in.node = j;
        found = true;
      }
    if (!found) r.fail(n["node"], k + ".node", "'" + node + "' is not one of can.nodes");
    in.extended = r.boolean(n, k, "extended", false);
    if (!n["id"]) r.fail(n, k + ".id", "missing: the CAN id of the frame that carries the input");
    in.id = id_value(r, n["id"], k + ".id", in.extended ? kMaxExtendedId : kMaxStandardId);
    in.byte = r.integer(n, k, "byte", 0, 0, 7);
    if (n["bit"] && n["range"]) r.fail(n, k, "give either 'bit' (a switch) or 'range' (an analogue value), not both");
    if (n["range"]) {
      in.analog = true;
      const auto range = r.numbers(n["range"], k + ".range");
      if (range.size() != 2) r.fail(n["range"], k + ".range", "expected [released_at_or_below, pressed_at_or_above]");
      in.release_at = range[0];
      in.press_at = range[1];
      in.size = r.integer(n, k, "size", 1, 1, 2);
      in.big_endian = r.boolean(n, k, "big_endian", false);
      const double full = in.size == 1 ? 255.0 : 65535.0;
      if (!(in.release_at >= 0.0 && in.release_at < in.press_at && in.press_at <= full))
        r.fail(n["range"], k + ".range", "need 0 <= released < pressed <= " + Reader::fmt(full));
      if (in.byte + in.size > 8) r.fail(n["size"], k + ".size", "byte + size runs past the 8 data bytes");
      if (n["active"]) r.fail(n["active"], k + ".active", "an analogue input is pressed above its range; 'active' is for a bit");
    } else if (n["bit"]) {
      in.bit = r.integer(n, k, "bit", 0, 0, 7);
      if (n["size"] || n["big_endian"]) r.fail(n, k, "'size' and 'big_endian' are for an analogue 'range'");
      const std::string active = r.text(n, k, "active", "high");
      if (active != "high" && active != "low") r.fail(n["active"], k + ".active", "must be 'high' or 'low', got '" + active + "'");
      in.active_high = active == "high";
    } else {
      r.fail(n, k, "give 'bit: 0-7' (a switch) or 'range: [released, pressed]' (an analogue value)");
    }
    in.debounce_ms = r.integer(n, k, "debounce_ms", in.debounce_ms, 0, 10000);
    in.release_debounce_ms = r.integer(n, k, "release_debounce_ms", in.release_debounce_ms, 0, 10000);
    c.inputs.push_back(in);
  }
  return c;
}

std::optional<CanConfig> parse_can_config(const std::string& text, const std::string& source) {
  Reader r(source);
  const YAML::Node root = r.load_root(text);
  if (!root["can"]) return std::nullopt;
  return parse_can_section(root["can"], source);
}

std::optional<CanConfig> load_can_config(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw CanConfigError(path.string() + ": cannot read the configuration file");
  std::stringstream ss;
  ss << in.rdbuf();
  return parse_can_config(ss.str(), path.string());
}

}  // namespace arnav::can
