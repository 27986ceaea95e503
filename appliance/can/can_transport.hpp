#pragma once
// Where CAN frames come from: a SocketCAN raw socket or an slcan adapter on a serial
// port, behind one small interface so the runtime, the tools and the tests do not care.
#include <chrono>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "appliance/can/can_frame.hpp"

namespace arnav::can {

// The bus cannot be opened. `kind` says whether trying again can help.
class CanUnavailable : public std::runtime_error {
 public:
  enum class Kind : std::uint8_t {
    NoAfCan,      // the kernel has no CAN socket family (EAFNOSUPPORT): retrying cannot help
    NoInterface,  // no such interface / serial port (yet): retry (USB adapter plugged later)
    Refused,      // permissions, bad rate, adapter answered BEL: fix the configuration
  };
  CanUnavailable(Kind kind, const std::string& what) : std::runtime_error(what), kind_(kind) {}
  Kind kind() const { return kind_; }

 private:
  Kind kind_;
};

// An open bus failed (interface went down, adapter unplugged): reopen.
class CanLinkLost : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Received {
  CanFrame frame;
  std::int64_t receive_mono_us = 0;  // when the appliance read it (monotonic)
  std::int64_t device_wall_us = -1;  // kernel receive timestamp (SocketCAN), -1 if none
};

struct TransportCounters {
  std::int64_t frames = 0;          // data/remote frames delivered
  std::int64_t error_frames = 0;    // error frames delivered (SocketCAN) or made from slcan status
  std::int64_t garbage_bytes = 0;   // slcan: bytes dropped while resynchronising
  std::int64_t resyncs = 0;         // slcan
  std::int64_t malformed = 0;       // slcan: lines dropped
  std::int64_t adapter_errors = 0;  // slcan: BEL replies
  std::int64_t overruns = 0;        // frames dropped before the appliance read them (SO_RXQ_OVFL / slcan overrun flag)

  // Adds another link's counts (the totals over the links opened so far).
  TransportCounters& operator+=(const TransportCounters& o) {
    frames += o.frames;
    error_frames += o.error_frames;
    garbage_bytes += o.garbage_bytes;
    resyncs += o.resyncs;
    malformed += o.malformed;
    adapter_errors += o.adapter_errors;
    overruns += o.overruns;
    return *this;
  }
};

class CanTransport {
 public:
  virtual ~CanTransport() = default;
  // Waits up to timeout for one frame; false on timeout. Throws CanLinkLost.
  virtual bool receive(Received& out, std::chrono::microseconds timeout) = 0;
  // Sends one data or remote frame. Throws CanLinkLost.
  virtual void send(const CanFrame& f) = 0;
  virtual std::string name() const = 0;  // "vcan0", "slcan:/dev/ttyUSB0"
  virtual std::string detail() const { return {}; }  // adapter version etc.
  virtual TransportCounters counters() const = 0;
};

}  // namespace arnav::can
