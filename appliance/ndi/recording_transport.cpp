#include "appliance/ndi/recording_transport.hpp"

namespace arnav::ndi {

RecordingTransport::RecordingTransport(std::unique_ptr<Transport> inner, std::ostream& out)
    : inner_(std::move(inner)), out_(out), t0_(std::chrono::steady_clock::now()) {
  out_ << kTranscriptHeader << '\n' << "# port " << inner_->name() << '\n';
}

RecordingTransport::~RecordingTransport() {
  flush_reply();
  out_.flush();
}

std::int64_t RecordingTransport::now_us() const {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::steady_clock::now() - t0_).count();
}

void RecordingTransport::put(TranscriptRecord r) { out_ << format_record(r) << '\n'; }

void RecordingTransport::flush_reply() {
  if (pending_.empty()) return;
  TranscriptRecord r;
  r.t_us = pending_t_us_;
  r.kind = TranscriptRecord::Kind::Reply;
  r.bytes.swap(pending_);
  put(std::move(r));
  pending_.clear();
}

std::size_t RecordingTransport::read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  const std::size_t n = inner_->read(buffer, timeout);
  if (n > 0) {
    if (pending_.empty()) pending_t_us_ = now_us();
    pending_.append(reinterpret_cast<const char*>(buffer.data()), n);
  }
  return n;
}

void RecordingTransport::write(std::span<const std::uint8_t> bytes) {
  flush_reply();
  TranscriptRecord r;
  r.t_us = now_us();
  r.kind = TranscriptRecord::Kind::Command;
  r.bytes.assign(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  put(std::move(r));
  inner_->write(bytes);
}

void RecordingTransport::set_baud(int baud) {
  flush_reply();
  inner_->set_baud(baud);
  TranscriptRecord r;
  r.t_us = now_us();
  r.kind = TranscriptRecord::Kind::Baud;
  r.value = baud;
  put(std::move(r));
}

void RecordingTransport::send_break(std::chrono::milliseconds duration) {
  flush_reply();
  TranscriptRecord r;
  r.t_us = now_us();
  r.kind = TranscriptRecord::Kind::Break;
  r.value = duration.count();
  put(std::move(r));
  inner_->send_break(duration);
}

}  // namespace arnav::ndi
