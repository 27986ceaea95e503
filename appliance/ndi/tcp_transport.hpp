#pragma once
// Transport over TCP for NDI trackers on Ethernet (Polaris Vega, Lyra: the Combined API
// on port 8765 by default). Non-blocking connect with a timeout, TCP_NODELAY (commands
// are a few bytes and must not wait for Nagle), keep-alive probes and TCP_USER_TIMEOUT so
// that a pulled cable is noticed within seconds even while nothing is sent (streaming),
// poll-based reads. Errors name host:port and say what to check.
#include <chrono>
#include <optional>
#include <string>

#include "appliance/serial/transport.hpp"

namespace arnav::ndi {

struct TcpOptions {
  std::string host;  // name or address; resolved with getaddrinfo on every (re)connect
  int port = 8765;
  std::chrono::milliseconds connect_timeout{3000};
  // Unacknowledged data or failed keep-alives for this long close the link (PortLost).
  std::chrono::milliseconds user_timeout{2000};
};

inline constexpr int kNdiTcpPort = 8765;

class TcpTransport final : public Transport {
 public:
  // Connects; throws PortError naming host:port (unknown host, refused, timed out).
  explicit TcpTransport(TcpOptions options);
  ~TcpTransport() override;
  TcpTransport(const TcpTransport&) = delete;
  TcpTransport& operator=(const TcpTransport&) = delete;

  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override;
  void write(std::span<const std::uint8_t> bytes) override;
  void set_baud(int /*baud*/) override {}  // no rate on a network link
  bool supports_baud(int baud) const override { return baud == 9600; }
  void send_break(std::chrono::milliseconds /*duration*/) override {}  // RESET is a command on TCP
  void drain_input() override;
  std::string name() const override { return label_; }
  bool is_network() const override { return true; }

 private:
  TcpOptions options_;
  std::string label_;  // "tcp:host:port"
  int fd_ = -1;
};

// "tcp:HOST:PORT" or "tcp:HOST" (port 8765) -> options; nullopt for anything else (a
// serial port path). Used by arnav-ndi's PORT argument.
std::optional<TcpOptions> parse_tcp_address(const std::string& text);

}  // namespace arnav::ndi
