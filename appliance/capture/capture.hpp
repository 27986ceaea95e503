#pragma once
// A frame source kept alive: opens it, reads frames, counts dropped frames (sequence
// gaps) and unusable items, and when the device is lost closes it and reopens it at a
// fixed interval until it comes back. What happens is reported as events (code + text
// naming the device) and in the counters for the health message.
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "appliance/capture/frame_source.hpp"

namespace arnav::capture {

enum class LinkState { Down, Connecting, Streaming, Recovering, Ended };

struct CaptureStats {
  std::int64_t frames = 0;
  std::int64_t dropped_frames = 0;
  std::int64_t skipped = 0;        // unreadable images passed over
  std::int64_t reconnects = 0;     // successful reopens after a loss
  LinkState state = LinkState::Down;
  std::string last_fault;
};

struct CaptureEvent {
  int severity = 0;  // 0 info, 1 warning, 2 error (appliance_event_t::SEVERITY_*)
  std::string code;  // CAMERA_OPENED, CAMERA_OPEN_FAILED, CAMERA_LOST, CAMERA_RECOVERED, CAMERA_IMAGE_SKIPPED, CAMERA_END
  std::string text;
};

class Capture {
 public:
  using EventSink = std::function<void(const CaptureEvent&)>;
  Capture(std::unique_ptr<FrameSource> source, double retry_interval_s, EventSink on_event);

  enum class Next { Frame, End, Stopped };
  // Blocks until a frame, the end of a finite source, or stop. Never throws for device
  // trouble: that becomes events, counters and retries.
  Next next(Frame& frame, const std::atomic<bool>& stop);
  CaptureStats stats() const { return stats_; }
  const FrameSource& source() const { return *source_; }

 private:
  bool try_open();
  void emit(int severity, const std::string& code, const std::string& text);

  std::unique_ptr<FrameSource> source_;
  double retry_interval_s_;
  EventSink on_event_;
  CaptureStats stats_;
  bool opened_once_ = false;
  bool was_lost_ = false;
  bool open_failure_reported_ = false;
  std::int64_t last_sequence_ = -1;
};

const char* to_string(LinkState state);

}  // namespace arnav::capture
