#pragma once
// The `can:` section of the appliance configuration (docs/can.md): which bus (a SocketCAN
// interface or an slcan adapter on a serial port), which devices are on it and how each
// proves it is alive (a CANopen heartbeat or any periodic frame, with a timeout), and how
// frames map to named inputs (a bit with an active level, or an analogue value with a
// press/release range), each with its debounce time. Errors name "<file>:<line>: key ...".
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace YAML {
class Node;
}

namespace arnav::can {

class CanConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct NodeConfig {
  enum class Liveness : std::uint8_t { Heartbeat, Periodic };
  std::string name;
  Liveness liveness = Liveness::Heartbeat;
  std::uint8_t node_id = 0;  // Heartbeat: CANopen node id 1-127, frames on 0x700 + id
  std::uint32_t id = 0;      // the id that proves liveness (0x700 + node_id for a heartbeat)
  bool extended = false;
  int timeout_ms = 300;
};

struct InputConfig {
  std::string name;
  std::size_t node = 0;  // index into CanConfig::nodes
  std::uint32_t id = 0;
  bool extended = false;
  int byte = 0;          // first data byte
  // Digital: one bit. Analogue: `size` bytes (little endian unless big_endian) compared
  // with release_at/press_at (hysteresis: pressed at >= press_at, released at <= release_at).
  bool analog = false;
  int bit = 0;
  bool active_high = true;
  int size = 1;
  bool big_endian = false;
  double release_at = 0.0, press_at = 0.0;
  int debounce_ms = 20;          // a press must hold this long before it counts
  int release_debounce_ms = 0;   // a release counts at once by default (safe side)
};

struct CanConfig {
  std::string interface;  // "can0", "vcan0", ... or "slcan:/dev/ttyUSB0"
  bool slcan = false;
  std::string port;       // slcan: the serial port
  int bitrate = 500000;   // slcan: sent to the adapter (S0-S8); SocketCAN: set with `ip link`
  int serial_baud = 115200;
  int status_poll_ms = 500;  // slcan: how often the adapter's F flags are read
  // SCHED_FIFO priority of the CAN thread (1-99), 0: normal scheduling. On by default, as
  // the NDI polling thread: a pedal press must not wait behind other work.
  int priority = 50;
  std::vector<NodeConfig> nodes;
  std::vector<InputConfig> inputs;
  std::string source;     // file read
  int interface_line = 1;

  // Every id an input or a node listens to (SocketCAN receive filters).
  std::vector<std::pair<std::uint32_t, bool>> ids() const;
};

// Parses the `can:` node of a configuration read from `source` (for messages).
CanConfig parse_can_section(const YAML::Node& can, const std::string& source);
// The `can:` section of a whole configuration text, or nullopt when it has none.
std::optional<CanConfig> parse_can_config(const std::string& text, const std::string& source);
std::optional<CanConfig> load_can_config(const std::filesystem::path& path);

}  // namespace arnav::can
