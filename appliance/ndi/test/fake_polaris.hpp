#pragma once
// In-process scripted Polaris for session tests (tests only; the HIL bench has the real
// simulator on a pseudo-terminal). It answers the commands the session sends, models
// the baud rate of both ends (bytes sent at the wrong rate are lost) and injects faults.
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "appliance/serial/transport.hpp"

namespace arnav::ndi::test {

struct FakeDevice {
  // ---- behaviour knobs -------------------------------------------------------------
  bool break_resets = true;           // false: like a pty, a break does nothing
  std::set<int> refuse_rates;         // COMM to these answers ERROR06
  std::set<int> broken_rates;         // COMM OKAY, but nothing works at that rate
  int bx_corrupt_every = 0;           // every n-th BX frame has a flipped byte (0: never)
  bool bx_always_corrupt = false;
  std::string garbage_before_bx;      // bytes sent before every BX frame
  std::size_t chunk = 0;              // read() returns at most this many bytes (0: all)
  int drop_replies = 0;               // the next n replies are not sent
  bool unplugged = false;             // port gone: reads/writes throw, reopen fails
  std::string firmware = "Polaris Vicra Control Firmware\nNDI S/N: P6-01234\nFreeze Tag: Vicra Rev 007\n";
  std::uint32_t frame_step = 1;       // frame counter increment per tracking reply
  bool init_ok_while_tracking = false;  // some units answer INIT with OKAY and keep tracking

  // ---- observed state ------------------------------------------------------------------
  int device_baud = 9600;
  int host_baud = 9600;
  bool initialised = false;
  bool tracking = false;
  std::uint32_t frame = 100;
  std::vector<std::string> commands;  // names in order ("INIT", "COMM", ...)
  std::vector<std::string> comm_params;
  std::map<std::uint8_t, std::vector<std::uint8_t>> roms;  // handle -> bytes written by PVWR
  std::set<std::uint8_t> enabled;
  std::size_t bytes_from_host = 0;
  int breaks = 0;
  int opens = 0;
  std::uint8_t next_handle = 0x0A;
  int bx_count = 0;

  std::deque<std::uint8_t> to_host;
  std::string line;  // partial command

  void reset_device();  // what a break or power cycle does
  void on_host_bytes(const std::uint8_t* data, std::size_t n);
  void handle_command(const std::string& line);
  void reply(const std::string& bytes);
  void spontaneous_reset();
};

class FakeTransport final : public Transport {
 public:
  explicit FakeTransport(std::shared_ptr<FakeDevice> dev);
  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override;
  void write(std::span<const std::uint8_t> bytes) override;
  void set_baud(int baud) override { dev_->host_baud = baud; }
  bool supports_baud(int baud) const override { return baud != 14400 && baud != 1228739; }
  void send_break(std::chrono::milliseconds duration) override;
  void drain_input() override {}
  std::string name() const override { return "fake0"; }

 private:
  std::shared_ptr<FakeDevice> dev_;
};

// Factory for Session: opens a FakeTransport on dev, fails while unplugged.
TransportFactory fake_factory(std::shared_ptr<FakeDevice> dev);

}  // namespace arnav::ndi::test
