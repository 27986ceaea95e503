#pragma once
// SocketCAN raw socket (PF_CAN / SOCK_RAW / CAN_RAW) on a named interface (can0, vcan0):
// receive filters for the configured ids (CAN_RAW_FILTER), error frames (CAN_RAW_ERR_FILTER:
// bus-off, controller error states, restarts), kernel receive timestamps (SO_TIMESTAMPNS)
// and drop counts (SO_RXQ_OVFL). Bus-off recovery is the kernel's (`ip link set can0 type
// can restart-ms 100`); the appliance reports it.
#include <utility>
#include <vector>

#include "appliance/can/can_transport.hpp"

namespace arnav::can {

class SocketCanTransport final : public CanTransport {
 public:
  // ids: (id, extended) to receive; empty: every frame. error_mask: err::* classes.
  // Throws CanUnavailable (no AF_CAN, no such interface, permissions).
  SocketCanTransport(std::string interface, const std::vector<std::pair<std::uint32_t, bool>>& ids,
                     std::uint32_t error_mask = err::kAllClasses);
  ~SocketCanTransport() override;
  SocketCanTransport(const SocketCanTransport&) = delete;
  SocketCanTransport& operator=(const SocketCanTransport&) = delete;

  bool receive(Received& out, std::chrono::microseconds timeout) override;
  void send(const CanFrame& f) override;
  std::string name() const override { return interface_; }
  TransportCounters counters() const override { return counters_; }
  int interface_index() const { return ifindex_; }

 private:
  std::string interface_;
  int fd_ = -1;
  int ifindex_ = 0;
  std::uint32_t last_drops_ = 0;
  TransportCounters counters_;
};

}  // namespace arnav::can
