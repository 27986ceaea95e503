#pragma once
// Transport over a real serial port through libserialport, and port listing.
#include <optional>
#include <string>
#include <vector>

#include "appliance/serial/transport.hpp"

struct sp_port;

namespace arnav::ndi {

struct PortInfo {
  std::string name;         // e.g. /dev/ttyUSB0
  std::string description;  // libserialport's description
  std::string transport;    // "usb", "native", "bluetooth"
  std::optional<int> usb_vid, usb_pid;
  std::string usb_manufacturer, usb_product, usb_serial;
};

// Every serial port libserialport sees. Throws PortError if enumeration fails.
std::vector<PortInfo> list_ports();
// "name (description, USB 0403:6001 FTDI ...)" lines, one per port, or "(none)".
std::string describe_ports(const std::vector<PortInfo>& ports);
// True when libserialport knows the port by this name.
bool port_exists(const std::string& name);

class SerialTransport final : public Transport {
 public:
  // Opens 8N1, no flow control, 9600 baud. Throws PortError naming the port.
  explicit SerialTransport(const std::string& name);
  ~SerialTransport() override;
  SerialTransport(const SerialTransport&) = delete;
  SerialTransport& operator=(const SerialTransport&) = delete;

  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override;
  void write(std::span<const std::uint8_t> bytes) override;
  void set_baud(int baud) override;
  bool supports_baud(int) const override { return true; }
  void send_break(std::chrono::milliseconds duration) override;
  void drain_input() override;
  std::string name() const override { return name_; }

 private:
  std::string name_;
  sp_port* port_ = nullptr;
};

}  // namespace arnav::ndi
