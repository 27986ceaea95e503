#pragma once
// In-process stand-ins for the unit tests: an slcan adapter behind the byte-transport
// interface (answers C/V/S/O/F like a Lawicel adapter, frames pushed by the test), and a
// CAN transport fed from a queue.
#include <deque>
#include <mutex>
#include <string>
#include <thread>

#include "appliance/can/can_transport.hpp"
#include "appliance/can/slcan.hpp"
#include "appliance/serial/transport.hpp"
#include "protocol/clock.hpp"

namespace arnav::can::test {

struct AdapterState {
  std::mutex m;
  std::string to_host;         // bytes the host will read
  std::string from_host;       // everything the host wrote
  bool open = false;
  int bitrate_code = -1;
  std::uint8_t flags = 0;
  bool refuse_bitrate = false;
  bool silent = false;
  bool lost = false;
  int opens = 0, closes = 0;
};

class FakeAdapterPort final : public ndi::Transport {
 public:
  explicit FakeAdapterPort(std::shared_ptr<AdapterState> s) : s_(std::move(s)) {}
  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override {
    const std::int64_t deadline = monotonic_us() + timeout.count() * 1000;
    for (;;) {
      {
        std::lock_guard lock(s_->m);
        if (s_->lost) throw ndi::PortLost("fake: unplugged");
        if (!s_->to_host.empty()) {
          const std::size_t n = std::min(buffer.size(), s_->to_host.size());
          std::copy_n(s_->to_host.begin(), n, buffer.begin());
          s_->to_host.erase(0, n);
          return n;
        }
      }
      if (monotonic_us() >= deadline) return 0;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  }
  void write(std::span<const std::uint8_t> bytes) override {
    std::lock_guard lock(s_->m);
    if (s_->lost) throw ndi::PortLost("fake: unplugged");
    for (auto b : bytes) {
      s_->from_host += static_cast<char>(b);
      line_ += static_cast<char>(b);
      if (b != '\r') continue;
      answer(line_.substr(0, line_.size() - 1));
      line_.clear();
    }
  }
  void set_baud(int) override {}
  bool supports_baud(int) const override { return true; }
  void send_break(std::chrono::milliseconds) override {}
  void drain_input() override {
    std::lock_guard lock(s_->m);
    s_->to_host.clear();
  }
  std::string name() const override { return "fake"; }

 private:
  void answer(const std::string& cmd) {
    if (s_->silent) return;
    const char c = cmd.empty() ? 0 : cmd[0];
    if (c == 'C') {
      s_->to_host += s_->open ? "\r" : "\a";
      s_->open = false;
      ++s_->closes;
    } else if (c == 'O') {
      s_->to_host += s_->open || s_->bitrate_code < 0 ? "\a" : "\r";
      if (s_->bitrate_code >= 0) {
        s_->open = true;
        ++s_->opens;
        s_->flags &= static_cast<std::uint8_t>(~slcan::status::kBusError);
      }
    } else if (c == 'S' && cmd.size() == 2) {
      if (s_->refuse_bitrate || s_->open) s_->to_host += "\a";
      else {
        s_->bitrate_code = cmd[1] - '0';
        s_->to_host += "\r";
      }
    } else if (c == 'V') {
      s_->to_host += "V1013\r";
    } else if (c == 'F') {
      char b[8];
      std::snprintf(b, sizeof b, "F%02X\r", s_->flags);
      s_->to_host += b;
    } else {
      s_->to_host += "\a";
    }
  }
  std::shared_ptr<AdapterState> s_;
  std::string line_;
};

struct QueueState {
  std::mutex m;
  std::deque<CanFrame> frames;
  bool lost = false;
};

class QueueTransport final : public CanTransport {
 public:
  explicit QueueTransport(std::shared_ptr<QueueState> s) : s_(std::move(s)) {}
  bool receive(Received& out, std::chrono::microseconds timeout) override {
    const std::int64_t deadline = monotonic_us() + timeout.count();
    for (;;) {
      {
        std::lock_guard lock(s_->m);
        if (s_->lost) throw CanLinkLost("queue: gone");
        if (!s_->frames.empty()) {
          out.frame = s_->frames.front();
          s_->frames.pop_front();
          out.receive_mono_us = monotonic_us();
          out.device_wall_us = wall_us();
          if (out.frame.error) ++counters_.error_frames;
          else ++counters_.frames;
          return true;
        }
      }
      if (monotonic_us() >= deadline) return false;
      std::this_thread::sleep_for(std::chrono::microseconds(100));
    }
  }
  void send(const CanFrame&) override {}
  std::string name() const override { return "queue"; }
  TransportCounters counters() const override { return counters_; }

 private:
  std::shared_ptr<QueueState> s_;
  TransportCounters counters_;
};

}  // namespace arnav::can::test
