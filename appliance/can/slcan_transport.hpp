#pragma once
// slcan adapter on a byte transport (libserialport for a real port, termios for a tty
// libserialport does not list). Opening: close any open channel ("C"), ask the version
// ("V"), set the bit rate ("S0".."S8"), open ("O"); each must be answered CR (OK), a BEL
// is refused. While open, the adapter's status flags ("F") are read every status_poll
// and turned into SocketCAN-style error frames, so the decoder sees one kind of bus
// state: error warning / passive -> a controller error frame, bus error -> bus-off (then
// the channel is closed and reopened, "C" + "O", and a restart frame follows once the
// flags are clear), clear flags after a problem -> error-active.
#include <deque>
#include <memory>

#include "appliance/can/can_transport.hpp"
#include "appliance/can/slcan.hpp"
#include "appliance/serial/transport.hpp"

namespace arnav::can {

struct SlcanOptions {
  int bitrate = 500000;
  std::chrono::milliseconds status_poll{500};
  std::chrono::milliseconds reply_timeout{500};  // for each opening command
};

class SlcanTransport final : public CanTransport {
 public:
  // Takes an open byte transport (already at the serial rate) and opens the CAN channel.
  // Throws CanUnavailable (Refused) when the adapter refuses or does not answer.
  SlcanTransport(std::unique_ptr<ndi::Transport> port, std::string label, SlcanOptions options);
  ~SlcanTransport() override;  // closes the channel ("C"), best effort

  bool receive(Received& out, std::chrono::microseconds timeout) override;
  void send(const CanFrame& f) override;
  std::string name() const override { return label_; }
  std::string detail() const override { return version_.empty() ? "slcan adapter" : "slcan adapter version " + version_; }
  TransportCounters counters() const override;

 private:
  void write(std::string_view s);
  void command(std::string_view cmd, const char* what, bool required);  // waits for CR / BEL
  void pump(std::chrono::microseconds timeout);  // reads once, queues what arrives
  void on_status(std::uint8_t flags, std::int64_t now_us);
  void queue_error(std::uint32_t cls, std::uint8_t crtl, std::int64_t now_us);

  std::unique_ptr<ndi::Transport> port_;
  std::string label_;
  SlcanOptions options_;
  slcan::Reader reader_;
  std::deque<Received> queue_;
  std::string version_;
  int oks_ = 0, bels_ = 0;  // replies seen (opening handshake)
  std::uint8_t last_flags_ = 0;
  bool bus_off_ = false;
  std::int64_t next_status_us_ = 0;
  TransportCounters counters_;
};

}  // namespace arnav::can
