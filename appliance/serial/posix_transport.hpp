#pragma once
// Transport over a POSIX tty with termios: used for pseudo-terminals (the bench
// simulator), which libserialport 0.1.1 cannot open.
#include "appliance/serial/transport.hpp"

namespace arnav::ndi {

class PosixTransport final : public Transport {
 public:
  // Opens path raw 8N1 at 9600 baud. Throws PortError naming the path.
  explicit PosixTransport(std::string path);
  ~PosixTransport() override;
  PosixTransport(const PosixTransport&) = delete;
  PosixTransport& operator=(const PosixTransport&) = delete;

  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override;
  void write(std::span<const std::uint8_t> bytes) override;
  void set_baud(int baud) override;
  bool supports_baud(int baud) const override;
  void send_break(std::chrono::milliseconds duration) override;
  void drain_input() override;
  std::string name() const override { return path_; }

 private:
  std::string path_;
  int fd_ = -1;
};

}  // namespace arnav::ndi
