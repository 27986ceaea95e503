#pragma once
// Transport decorator that writes everything crossing the link to a transcript
// (appliance/ndi/transcript.hpp). Bytes read between two host actions are written as one
// reply record, timed at their first byte.
#include <chrono>
#include <memory>
#include <ostream>
#include <string>

#include "appliance/ndi/transcript.hpp"
#include "appliance/serial/transport.hpp"

namespace arnav::ndi {

class RecordingTransport final : public Transport {
 public:
  // out must outlive this object; the header line is written at once.
  RecordingTransport(std::unique_ptr<Transport> inner, std::ostream& out);
  ~RecordingTransport() override;

  std::size_t read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) override;
  void write(std::span<const std::uint8_t> bytes) override;
  void set_baud(int baud) override;
  bool supports_baud(int baud) const override { return inner_->supports_baud(baud); }
  void send_break(std::chrono::milliseconds duration) override;
  void drain_input() override { inner_->drain_input(); }
  std::string name() const override { return inner_->name(); }
  bool is_network() const override { return inner_->is_network(); }

 private:
  std::int64_t now_us() const;
  void flush_reply();
  void put(TranscriptRecord r);

  std::unique_ptr<Transport> inner_;
  std::ostream& out_;
  std::chrono::steady_clock::time_point t0_;
  std::string pending_;
  std::int64_t pending_t_us_ = 0;
};

}  // namespace arnav::ndi
