#pragma once
// Frames -> input presses and releases, device liveness and bus state (docs/can.md).
//
// Inputs: a press counts once the raw level has held for debounce_ms, a release once it
// has held for release_debounce_ms (0 by default: at once), so contact bounce gives exactly
// one press and one release. Liveness: a device is alive from its first heartbeat (or
// periodic frame) until timeout_ms passes without one; while it is not alive its inputs
// are held released and its frames change nothing, and on loss the raw level is forgotten,
// so after its return only fresh frames can press again. Bus-off releases every input at
// once. Times are monotonic microseconds; the caller calls tick() at next_deadline_us().
// No allocation after construction.
#include <cstdint>
#include <string_view>
#include <vector>

#include "appliance/can/can_config.hpp"
#include "appliance/can/can_frame.hpp"

namespace arnav::can {

enum class NodeState : std::uint8_t { Unknown, Alive, Lost };
enum class BusState : std::uint8_t { Active, Warning, Passive, BusOff };
std::string_view to_string(NodeState s);
std::string_view to_string(BusState s);
// CANopen NMT state of a heartbeat byte ("operational", "pre-operational", ...).
std::string_view canopen_state_name(std::uint8_t state);

struct InputChange {
  enum class Cause : std::uint8_t { Frame, Debounce, NodeLost, BusOff };
  std::size_t input = 0;
  bool pressed = false;
  double value = 0.0;            // digital: 1/0; analogue: the raw value
  std::int64_t frame_us = 0;     // receive time of the frame that set the level (0: none)
  std::int64_t decided_us = 0;   // when the change became certain (frame time or deadline)
  Cause cause = Cause::Frame;
};

struct NodeChange {
  std::size_t node = 0;
  NodeState state = NodeState::Unknown;
  NodeState previous = NodeState::Unknown;
  std::int64_t time_us = 0;
  std::int64_t silent_us = 0;       // Lost: time since the last liveness frame
  std::uint8_t canopen_state = 0xFF;  // Heartbeat: last NMT state byte (0xFF: none)
};

struct BusChange {
  BusState state = BusState::Active;
  BusState previous = BusState::Active;
  std::int64_t time_us = 0;
};

class DecoderSink {
 public:
  virtual ~DecoderSink() = default;
  virtual void on_input(const InputChange& c) = 0;
  virtual void on_node(const NodeChange& c) = 0;
  virtual void on_bus(const BusChange& c) = 0;
};

struct DecoderCounters {
  std::int64_t frames = 0;          // data/remote frames seen
  std::int64_t matched = 0;         // frames that carried an input or liveness
  std::int64_t unrelated = 0;       // frames no input or device uses
  std::int64_t short_frames = 0;    // input frames with too few data bytes (ignored)
  std::int64_t error_frames = 0;
  std::int64_t bus_off = 0;         // times the bus went off
  std::int64_t restarts = 0;        // controller restarts / recoveries from bus-off
  std::int64_t presses = 0;
  std::int64_t releases = 0;
  std::int64_t forced_releases = 0; // releases because of node loss or bus-off
};

struct InputStatus {
  bool pressed = false;
  double value = 0.0;
};

struct NodeStatus {
  NodeState state = NodeState::Unknown;
  std::int64_t last_seen_us = 0;
  std::uint8_t canopen_state = 0xFF;
  std::int64_t losses = 0;
};

class InputDecoder {
 public:
  explicit InputDecoder(CanConfig config);

  // A frame (data, remote or error) received at receive_us.
  void on_frame(const CanFrame& f, std::int64_t receive_us, DecoderSink& sink);
  // Deadlines (debounce, liveness timeouts) up to now.
  void tick(std::int64_t now_us, DecoderSink& sink);
  // The earliest time tick() has something to do, or INT64_MAX.
  std::int64_t next_deadline_us() const;
  // The transport is gone (port lost, interface down): everything released, devices lost.
  void link_lost(std::int64_t now_us, DecoderSink& sink);

  const CanConfig& config() const { return config_; }
  const DecoderCounters& counters() const { return counters_; }
  BusState bus_state() const { return bus_; }
  const std::vector<InputStatus>& inputs() const { return status_; }
  const std::vector<NodeStatus>& nodes() const { return nodes_; }

 private:
  struct Raw {
    bool level = false;       // raw pressed level (after active level / hysteresis)
    double value = 0.0;
    std::int64_t since_us = 0;
    std::int64_t frame_us = 0;  // frame that set the level
  };
  void evaluate(std::size_t i, std::int64_t now_us, DecoderSink& sink, InputChange::Cause cause);
  void release_all(std::int64_t now_us, DecoderSink& sink, InputChange::Cause cause, bool only_node, std::size_t node);
  void set_bus(BusState s, std::int64_t now_us, DecoderSink& sink);
  void node_seen(std::size_t n, std::int64_t now_us, DecoderSink& sink, std::uint8_t canopen_state);

  CanConfig config_;
  std::vector<InputStatus> status_;
  std::vector<Raw> raw_;
  std::vector<NodeStatus> nodes_;
  BusState bus_ = BusState::Active;
  DecoderCounters counters_;
};

}  // namespace arnav::can
