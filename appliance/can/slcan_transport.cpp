#include "appliance/can/slcan_transport.hpp"

#include <array>

#include "protocol/clock.hpp"

namespace arnav::can {

SlcanTransport::SlcanTransport(std::unique_ptr<ndi::Transport> port, std::string label, SlcanOptions options)
    : port_(std::move(port)), label_(std::move(label)), options_(options) {
  const auto code = slcan::bitrate_code(options_.bitrate);
  if (!code) throw CanUnavailable(CanUnavailable::Kind::Refused, label_ + ": " + std::to_string(options_.bitrate) + " bit/s has no slcan code");
  try {
    // An adapter left open by a previous run answers C with OK; a closed one with BEL
    // (already closed): both are fine.
    write(slcan::kClose);
    pump(std::chrono::milliseconds(50));
    port_->drain_input();
    reader_.clear();
    queue_.clear();
    command(slcan::kVersion, "version (V)", false);
    command(slcan::bitrate_command(*code), "bit rate (S)", true);
    command(slcan::kOpen, "open (O)", true);
  } catch (const ndi::PortLost& e) {
    throw CanUnavailable(CanUnavailable::Kind::NoInterface, label_ + ": " + e.what());
  }
  next_status_us_ = monotonic_us() + static_cast<std::int64_t>(options_.status_poll.count()) * 1000;
}

SlcanTransport::~SlcanTransport() {
  try {
    write(slcan::kClose);
  } catch (...) {
  }
}

void SlcanTransport::write(std::string_view s) {
  port_->write(std::span(reinterpret_cast<const std::uint8_t*>(s.data()), s.size()));
}

void SlcanTransport::command(std::string_view cmd, const char* what, bool required) {
  const int oks = oks_, bels = bels_;
  const std::string version = version_;
  write(cmd);
  const std::int64_t deadline = monotonic_us() + static_cast<std::int64_t>(options_.reply_timeout.count()) * 1000;
  while (monotonic_us() < deadline) {
    pump(std::chrono::microseconds(deadline - monotonic_us()));
    if (oks_ > oks || version_ != version) return;
    if (bels_ > bels) {
      if (!required) return;
      throw CanUnavailable(CanUnavailable::Kind::Refused,
                           label_ + ": the slcan adapter refused the " + what + " command (BEL); check can.bitrate and that it is an slcan adapter");
    }
  }
  if (required)
    throw CanUnavailable(CanUnavailable::Kind::Refused,
                         label_ + ": no answer to the slcan " + what + " command within " + std::to_string(options_.reply_timeout.count()) +
                             " ms; check that the adapter speaks slcan and can.serial_baud");
}

void SlcanTransport::queue_error(std::uint32_t cls, std::uint8_t crtl, std::int64_t now_us) {
  Received r;
  r.frame.error = true;
  r.frame.id = cls;
  r.frame.dlc = 8;
  r.frame.data[1] = crtl;
  r.receive_mono_us = now_us;
  counters_.error_frames += 1;
  queue_.push_back(r);
}

void SlcanTransport::on_status(std::uint8_t flags, std::int64_t now_us) {
  using namespace slcan::status;
  if (flags & kDataOverrun) counters_.overruns += 1;
  if (flags & kBusError) {
    if (!bus_off_) {
      bus_off_ = true;
      queue_error(err::kBusOff, 0, now_us);
    }
    write(slcan::kClose);  // the adapter restarts its controller on close + open
    write(slcan::kOpen);
  } else if (bus_off_) {
    bus_off_ = false;
    queue_error(err::kRestarted, 0, now_us);
  } else if (flags & kErrorPassive) {
    if (!(last_flags_ & kErrorPassive)) queue_error(err::kCrtl, err::kCrtlRxPassive | err::kCrtlTxPassive, now_us);
  } else if (flags & kErrorWarning) {
    if (!(last_flags_ & kErrorWarning) || (last_flags_ & kErrorPassive)) queue_error(err::kCrtl, err::kCrtlRxWarning | err::kCrtlTxWarning, now_us);
  } else if (last_flags_ & (kErrorPassive | kErrorWarning)) {
    queue_error(err::kCrtl, err::kCrtlActive, now_us);
  }
  last_flags_ = flags;
}

void SlcanTransport::pump(std::chrono::microseconds timeout) {
  std::array<std::uint8_t, 512> buf;
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(timeout + std::chrono::microseconds(999));
  const std::size_t n = port_->read(buf, ms);
  const std::int64_t now = monotonic_us();
  if (n == 0) return;
  reader_.feed(std::span<const std::uint8_t>(buf.data(), n));
  slcan::Message m;
  while (reader_.next(m)) {
    switch (m.kind) {
      case slcan::Message::Kind::Frame: {
        Received r;
        r.frame = m.frame;
        r.receive_mono_us = now;
        counters_.frames += 1;
        queue_.push_back(r);
        break;
      }
      case slcan::Message::Kind::Ok: ++oks_; break;
      case slcan::Message::Kind::Error: ++bels_; break;
      case slcan::Message::Kind::Status: on_status(m.flags, now); break;
      case slcan::Message::Kind::Version: version_ = std::string(m.text.data(), 4); break;
      case slcan::Message::Kind::Serial:
      case slcan::Message::Kind::TxAck: break;
    }
  }
}

bool SlcanTransport::receive(Received& out, std::chrono::microseconds timeout) {
  const std::int64_t deadline = monotonic_us() + timeout.count();
  for (;;) {
    if (!queue_.empty()) {
      out = queue_.front();
      queue_.pop_front();
      return true;
    }
    std::int64_t now = monotonic_us();
    try {
      if (now >= next_status_us_) {
        write(slcan::kStatus);
        next_status_us_ = now + static_cast<std::int64_t>(options_.status_poll.count()) * 1000;
      }
      if (now >= deadline) return false;
      pump(std::chrono::microseconds(std::min(deadline, next_status_us_) - now));
    } catch (const ndi::PortLost& e) {
      throw CanLinkLost(label_ + ": " + e.what());
    }
  }
}

void SlcanTransport::send(const CanFrame& f) {
  const std::string line = slcan::encode_frame(f);
  if (line.empty()) return;
  try {
    write(line);
  } catch (const ndi::PortLost& e) {
    throw CanLinkLost(label_ + ": " + e.what());
  }
}

TransportCounters SlcanTransport::counters() const {
  TransportCounters c = counters_;
  c.garbage_bytes = reader_.counters().garbage_bytes;
  c.resyncs = reader_.counters().resyncs;
  c.malformed = reader_.counters().malformed;
  c.adapter_errors = reader_.counters().errors;
  return c;
}

}  // namespace arnav::can
