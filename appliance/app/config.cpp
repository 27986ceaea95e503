#include "appliance/app/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cctype>
#include <fstream>
#include <set>
#include <sstream>

#include "appliance/ndi/command.hpp"
#include "appliance/ndi/rom.hpp"
#include "protocol/yaml/yaml_reader.hpp"

namespace arnav::app {
namespace {

using Reader = yaml::YamlReader<ConfigError>;

const std::set<std::string> kKeys = {"camera", "frames", "port", "ndi", "baud", "rate_hz", "device_rate_hz", "lcm_url", "reply_mode",
                                     "tx_firmware", "bx_failures_before_tx", "tracking_timeout_ms",
                                     "setup_timeout_ms", "reset_wait_ms", "health_rate_hz", "tools", "sim_command", "sim_args", "realtime", "can", "swab", "security"};

// ndi: {host: P9-B0103.local, port: 8765, stream: true, connect_timeout_ms: 3000}
void parse_ndi_section(const Reader& r, const YAML::Node& n, AppConfig& c) {
  if (!n.IsMap()) r.fail(n, "ndi", "expected a mapping such as {host: 192.168.1.50, port: 8765}");
  r.only(n, "ndi", {"host", "port", "stream", "connect_timeout_ms"});
  if (!n["host"]) r.fail(n, "ndi.host", "missing: the tracker's IP address or name (e.g. P9-B0103.local)");
  c.ndi_host = r.get<std::string>(n["host"], "ndi.host", "a string");
  if (c.ndi_host.empty()) r.fail(n["host"], "ndi.host", "empty");
  if (n["port"]) {
    c.ndi_port = r.get<int>(n["port"], "ndi.port", "an integer");
    if (c.ndi_port < 1 || c.ndi_port > 65535) r.fail(n["port"], "ndi.port", "must be a TCP port, 1 to 65535 (NDI's default is 8765)");
  }
  if (n["stream"]) c.ndi_stream = r.get<bool>(n["stream"], "ndi.stream", "true or false");
  if (n["connect_timeout_ms"]) {
    c.connect_timeout_ms = r.get<int>(n["connect_timeout_ms"], "ndi.connect_timeout_ms", "an integer");
    if (c.connect_timeout_ms < 10 || c.connect_timeout_ms > 60000) r.fail(n["connect_timeout_ms"], "ndi.connect_timeout_ms", "must be between 10 and 60000");
  }
  c.port = "tcp:" + c.ndi_host + ":" + std::to_string(c.ndi_port);
  c.port_line = n.Mark().line + 1;
}

}  // namespace

ndi::SessionConfig AppConfig::session_config() const {
  ndi::SessionConfig c;
  c.tools = tools;
  c.target_baud = baud;
  c.use_bx = use_bx;
  c.tx_firmware = tx_firmware;
  c.bx_failures_before_tx = bx_failures_before_tx;
  c.tracking_timeout = std::chrono::milliseconds(tracking_timeout_ms);
  c.setup_timeout = std::chrono::milliseconds(setup_timeout_ms);
  c.reset_wait = std::chrono::milliseconds(reset_wait_ms);
  c.stream = ndi_stream;
  return c;
}

AppConfig parse_config(const std::string& text, const std::string& source, const std::filesystem::path& base_dir) {
  Reader r(source);
  const YAML::Node root = r.load_root(text);
  r.only(root, "", kKeys);
  AppConfig c;
  c.source = source;
  try {
    c.security = seal::parse_security(root["security"], source, base_dir);
  } catch (const seal::SecurityError& e) {
    throw ConfigError(e.what());
  }
  // camera: and frames: are read by appliance/camera/camera_config (docs/camera.md),
  // can: by appliance/can/can_config (docs/can.md), swab: by appliance/app/swab (docs/register.md).
  if (!root["port"] && !root["ndi"] && (root["camera"] || root["can"]) && !root["tools"]) {  // camera and/or CAN, no NDI
    c.ndi_enabled = false;
    if (root["lcm_url"]) c.lcm_url = r.get<std::string>(root["lcm_url"], "lcm_url", "a string");
    if (root["health_rate_hz"]) {  // the CAN path's health rate
      c.health_rate_hz = r.get<double>(root["health_rate_hz"], "health_rate_hz", "a number");
      if (!(c.health_rate_hz > 0.0) || c.health_rate_hz > 10000.0) r.fail(root["health_rate_hz"], "health_rate_hz", "must be > 0 and <= 10000");
    }
    if (root["realtime"])
      r.fail(root["realtime"], "realtime", "applies to the NDI polling thread, and this configuration has no NDI 'port' (camera or CAN only)");
    return c;
  }
  if (root["port"] && root["ndi"])
    r.fail(root["ndi"], "ndi", "give either 'port' (serial tracker) or 'ndi: {host: ...}' (Ethernet tracker), not both");
  if (const YAML::Node n = root["ndi"]) {
    parse_ndi_section(r, n, c);
  } else {
    if (!root["port"]) r.fail(root, "port", "missing: give a serial port path (e.g. /dev/ttyUSB0) or 'sim', or an 'ndi: {host: ...}' section");
    c.port = r.get<std::string>(root["port"], "port", "a string");
    c.port_line = root["port"].Mark().line + 1;
    if (c.port.empty()) r.fail(root["port"], "port", "empty");
  }
  if (root["baud"]) {
    c.baud = r.get<int>(root["baud"], "baud", "an integer");
    if (!ndi::baud_code(c.baud))
      r.fail(root["baud"], "baud",
             std::to_string(c.baud) + " is not an NDI rate (9600, 14400, 19200, 38400, 57600, 115200, 230400, 921600, 1228739)");
  }
  auto positive = [&](const char* key, double& value) {
    if (!root[key]) return;
    value = r.get<double>(root[key], key, "a number");
    if (!(value > 0.0) || value > 10000.0) r.fail(root[key], key, "must be > 0 and <= 10000");
  };
  positive("rate_hz", c.rate_hz);
  c.device_rate_hz = c.rate_hz;
  positive("device_rate_hz", c.device_rate_hz);
  positive("health_rate_hz", c.health_rate_hz);
  if (root["lcm_url"]) c.lcm_url = r.get<std::string>(root["lcm_url"], "lcm_url", "a string");
  if (root["reply_mode"]) {
    const auto mode = r.get<std::string>(root["reply_mode"], "reply_mode", "a string");
    if (mode != "bx" && mode != "tx") r.fail(root["reply_mode"], "reply_mode", "must be 'bx' or 'tx', got '" + mode + "'");
    c.use_bx = mode == "bx";
  }
  if (root["tx_firmware"]) c.tx_firmware = r.strings(root["tx_firmware"], "tx_firmware");
  auto int_in = [&](const char* key, int& value, int lo, int hi) {
    if (!root[key]) return;
    value = r.get<int>(root[key], key, "an integer");
    if (value < lo || value > hi)
      r.fail(root[key], key, "must be between " + std::to_string(lo) + " and " + std::to_string(hi));
  };
  int_in("bx_failures_before_tx", c.bx_failures_before_tx, 1, 1000);
  int_in("tracking_timeout_ms", c.tracking_timeout_ms, 5, 10000);
  int_in("setup_timeout_ms", c.setup_timeout_ms, 50, 60000);
  int_in("reset_wait_ms", c.reset_wait_ms, 0, 60000);
  if (root["sim_command"]) c.sim_command = r.get<std::string>(root["sim_command"], "sim_command", "a string");
  if (root["sim_args"]) c.sim_args = r.strings(root["sim_args"], "sim_args");
  if (const YAML::Node rt = root["realtime"]) {
    r.only(rt, "realtime", {"cpu_latency_us", "priority"});
    if (rt["cpu_latency_us"]) {
      c.realtime.cpu_latency_us = r.get<int>(rt["cpu_latency_us"], "realtime.cpu_latency_us", "an integer");
      if (c.realtime.cpu_latency_us < -1 || c.realtime.cpu_latency_us > 100000)
        r.fail(rt["cpu_latency_us"], "realtime.cpu_latency_us", "must be between 0 and 100000 us, or -1 to leave the CPU idle policy alone");
    }
    if (rt["priority"]) {
      c.realtime.priority = r.get<int>(rt["priority"], "realtime.priority", "an integer");
      if (c.realtime.priority < 0 || c.realtime.priority > 99)
        r.fail(rt["priority"], "realtime.priority", "must be between 1 and 99 (SCHED_FIFO), or 0 for normal scheduling");
    }
  }

  const YAML::Node tools = root["tools"];
  if (!tools) r.fail(root, "tools", "missing: list the tools, each with 'name' and 'rom'");
  if (!tools.IsSequence() || tools.size() == 0) r.fail(tools, "tools", "expected a non-empty list of {name, rom}");
  std::set<std::string> names;
  for (std::size_t i = 0; i < tools.size(); ++i) {
    const std::string k = "tools[" + std::to_string(i) + "]";
    const YAML::Node t = tools[i];
    if (!t.IsMap()) r.fail(t, k, "expected a mapping with 'name' and 'rom'");
    for (const auto& kv : t)
      if (kv.first.Scalar() != "name" && kv.first.Scalar() != "rom")
        r.fail(kv.first, k + "." + kv.first.Scalar(), "unknown key (a tool has 'name' and 'rom')");
    if (!t["name"]) r.fail(t, k + ".name", "missing");
    if (!t["rom"]) r.fail(t, k + ".rom", "missing");
    ndi::ToolConfig tool;
    tool.name = r.get<std::string>(t["name"], k + ".name", "a string");
    for (char ch : tool.name)
      if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-'))
        r.fail(t["name"], k + ".name", "'" + tool.name + "' may only hold letters, digits, '_' and '-' (it names an LCM channel)");
    if (tool.name.empty()) r.fail(t["name"], k + ".name", "empty");
    if (!names.insert(tool.name).second) r.fail(t["name"], k + ".name", "duplicate tool name '" + tool.name + "'");
    std::filesystem::path rom = r.get<std::string>(t["rom"], k + ".rom", "a path");
    if (rom.is_relative()) rom = base_dir / rom;
    tool.rom_path = rom;
    try {
      (void)ndi::load_rom(rom);  // refuse a bad file now, before any serial traffic
    } catch (const ndi::RomError& e) {
      r.fail(t["rom"], k + ".rom", e.what());
    }
    c.tools.push_back(std::move(tool));
  }
  if (c.tools.size() > 12) r.fail(tools, "tools", "at most 12 tools");
  return c;
}

std::string read_config_text(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path.string() + ": cannot read the configuration file");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

AppConfig load_config(const std::filesystem::path& path) {
  return parse_config(read_config_text(path), path.string(), path.parent_path());
}

}  // namespace arnav::app
