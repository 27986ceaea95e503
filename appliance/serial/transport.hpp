#pragma once
// Byte transport under the session: a serial port (libserialport), a pseudo-terminal
// (POSIX termios; libserialport cannot open ptys), a TCP connection (Ethernet trackers
// such as the Polaris Vega), or an in-process peer in tests.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>

namespace arnav::ndi {

// The port failed in a way that needs a reopen (unplugged USB adapter, closed pty, EIO).
class PortLost : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The port cannot be opened or configured (missing device, permissions, bad rate).
class PortError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Transport {
 public:
  virtual ~Transport() = default;
  // Waits up to timeout for at least one byte; returns the bytes read (0 on timeout).
  // Throws PortLost when the port is gone.
  virtual std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) = 0;
  // Writes all bytes (blocking until handed to the driver). Throws PortLost.
  virtual void write(std::span<const std::uint8_t> bytes) = 0;
  // Changes the host side rate. Throws PortError for a rate the port cannot do.
  virtual void set_baud(int baud) = 0;
  // Whether set_baud can do this rate (the session only negotiates rates both ends can do).
  virtual bool supports_baud(int baud) const = 0;
  // Holds the line in break for the duration (device reset). A pty swallows it.
  virtual void send_break(std::chrono::milliseconds duration) = 0;
  // Discards bytes received but not yet read.
  virtual void drain_input() = 0;
  virtual std::string name() const = 0;
  // A network link (TCP): no baud rate, no break; the session skips COMM and resets the
  // device with a command instead, and may ask it to stream.
  virtual bool is_network() const { return false; }
};

// Opens (or reopens after PortLost) the transport; throws PortError.
using TransportFactory = std::function<std::unique_ptr<Transport>()>;

}  // namespace arnav::ndi
