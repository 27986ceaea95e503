#pragma once
// arnav-appliance configuration (YAML, documented in docs/appliance.md). Every problem is
// reported as "<file>:<line>: key '<key>': <what is wrong>" and the program exits 2.
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "appliance/realtime/realtime.hpp"
#include "appliance/ndi/session.hpp"
#include "protocol/seal/security_config.hpp"

namespace arnav::app {

class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct AppConfig {
  bool ndi_enabled = true;    // false: no 'port' and a 'camera:' section (camera-only, docs/camera.md)
  std::string port;           // serial port path, or "sim"; "tcp:HOST:PORT" with an ndi: section
  int port_line = 1;          // line of the port key (for errors found later)
  // ndi: {host, port, stream, connect_timeout_ms}: an Ethernet tracker (Polaris Vega, Lyra)
  std::string ndi_host;       // empty: serial (port:)
  int ndi_port = 8765;
  bool ndi_stream = true;     // STREAM BX2 when the device's API revision allows it
  int connect_timeout_ms = 3000;
  int baud = 115200;          // COMM target rate
  double rate_hz = 60.0;      // polling rate (the device frame rate)
  double device_rate_hz = 60.0;  // frame counter rate, for device_time_us
  std::string lcm_url = "udpm://239.255.76.67:7667?ttl=0";
  bool use_bx = true;         // reply_mode: bx | tx
  std::vector<std::string> tx_firmware;
  int bx_failures_before_tx = 5;
  int tracking_timeout_ms = 150;
  int setup_timeout_ms = 5000;
  int reset_wait_ms = 3000;   // wait for RESET after a break
  double health_rate_hz = 1.0;
  std::vector<ndi::ToolConfig> tools;
  std::string sim_command;    // port: sim -> program to run (default: arnav-polaris-sim)
  std::vector<std::string> sim_args;
  seal::SecuritySettings security;  // `security:` (docs/protocol.md, "Sealed bus"); resolved at start
  RealtimeConfig realtime;    // `realtime:` (CPU latency request, polling-thread priority)
  std::filesystem::path source;  // the file read

  ndi::SessionConfig session_config() const;
};

// Parses text; relative ROM paths are resolved against base_dir. Throws ConfigError.
AppConfig parse_config(const std::string& text, const std::string& source, const std::filesystem::path& base_dir);
AppConfig load_config(const std::filesystem::path& path);
// The configuration file's text; throws ConfigError naming the file when it cannot be read.
std::string read_config_text(const std::filesystem::path& path);

}  // namespace arnav::app
