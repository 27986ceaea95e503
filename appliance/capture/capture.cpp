#include "appliance/capture/capture.hpp"

#include <chrono>
#include <thread>

namespace arnav::capture {

const char* to_string(LinkState s) {
  switch (s) {
    case LinkState::Down: return "down";
    case LinkState::Connecting: return "connecting";
    case LinkState::Streaming: return "streaming";
    case LinkState::Recovering: return "recovering";
    case LinkState::Ended: return "ended";
  }
  return "?";
}

Capture::Capture(std::unique_ptr<FrameSource> source, double retry_interval_s, EventSink on_event)
    : source_(std::move(source)), retry_interval_s_(retry_interval_s), on_event_(std::move(on_event)) {
  if (!source_) throw CaptureError("capture: no source");
  if (!(retry_interval_s_ > 0.0)) throw CaptureError("capture: retry interval must be > 0 s");
}

void Capture::emit(int severity, const std::string& code, const std::string& text) {
  if (on_event_) on_event_({severity, code, text});
}

bool Capture::try_open() {
  stats_.state = was_lost_ ? LinkState::Recovering : LinkState::Connecting;
  try {
    source_->open();
  } catch (const CaptureError& e) {
    stats_.last_fault = e.what();
    if (!open_failure_reported_) {  // once per outage, not once per retry
      emit(2, "CAMERA_OPEN_FAILED", std::string(e.what()) + "; retrying every " + std::to_string(retry_interval_s_) + " s");
      open_failure_reported_ = true;
    }
    return false;
  }
  open_failure_reported_ = false;
  stats_.state = LinkState::Streaming;
  if (was_lost_) {
    ++stats_.reconnects;
    emit(0, "CAMERA_RECOVERED", source_->describe() + ": reopened after a loss (reconnect " +
                                    std::to_string(stats_.reconnects) + ")");
  } else if (!opened_once_) {
    emit(0, "CAMERA_OPENED", source_->describe());
  }
  opened_once_ = true;
  was_lost_ = false;
  return true;
}

Capture::Next Capture::next(Frame& frame, const std::atomic<bool>& stop) {
  while (!stop.load()) {
    if (stats_.state == LinkState::Ended) return Next::End;
    if (stats_.state != LinkState::Streaming) {
      if (!try_open()) {
        // Sleep in small steps so a stop request is honoured quickly.
        const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(retry_interval_s_);
        while (!stop.load() && std::chrono::steady_clock::now() < until) {
          std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        continue;
      }
    }
    const ReadResult r = source_->read(frame);
    switch (r.status) {
      case ReadStatus::Ok:
        ++stats_.frames;
        if (last_sequence_ >= 0 && frame.sequence > last_sequence_ + 1) {
          stats_.dropped_frames += frame.sequence - last_sequence_ - 1;
        }
        last_sequence_ = frame.sequence;
        return Next::Frame;
      case ReadStatus::Skipped:
        ++stats_.skipped;
        stats_.last_fault = r.detail;
        emit(1, "CAMERA_IMAGE_SKIPPED", r.detail);
        continue;
      case ReadStatus::EndOfStream:
        stats_.state = LinkState::Ended;
        emit(0, "CAMERA_END", r.detail);
        return Next::End;
      case ReadStatus::Lost:
        source_->close();
        stats_.last_fault = r.detail;
        was_lost_ = true;
        stats_.state = LinkState::Recovering;
        emit(2, "CAMERA_LOST", r.detail + "; reopening");
        continue;
    }
  }
  return Next::Stopped;
}

}  // namespace arnav::capture
