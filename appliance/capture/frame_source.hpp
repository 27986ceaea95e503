#pragma once
// Capture: every camera-like input behind one interface. A source hands out frames with
// an exposure timestamp and a delivery timestamp (both CLOCK_MONOTONIC, us) and a sequence
// number from the device side, so a gap in sequence numbers is a dropped frame. Sources: V4L2 camera (OpenCV), video
// file, image folder, and the synthetic camera of the bench (synthetic_source.hpp).
#include <opencv2/core.hpp>

#include <cstdint>
#include <stdexcept>
#include <string>

namespace arnav::capture {

// Open failures and configuration problems; the message names the device or file.
class CaptureError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Frame {
  cv::Mat image;                       // CV_8UC1 or CV_8UC3 (BGR)
  // The exposure instant (docs/camera.md, "Timestamps"): the synthetic camera's world time
  // of the scene the frame shows; V4L2: the driver's buffer timestamp (CLOCK_MONOTONIC),
  // the read time when the driver gives none; files and folders: the read time.
  std::int64_t capture_time_mono_us = 0;
  // When the source made the frame available to its reader (synthetic: the end of its
  // modelled readout, or its rendering when that finished later; other sources: the read's
  // return). The appliance's own latency is counted from here.
  std::int64_t delivered_time_mono_us = 0;
  std::int64_t sequence = 0;           // device-side counter: gaps are dropped frames
  std::string origin;                  // file name for folder/file sources, else empty
};

enum class ReadStatus {
  Ok,           // frame filled
  EndOfStream,  // a file or folder is exhausted (not a fault)
  Skipped,      // this item was unusable (unreadable image): detail says which and why
  Lost,         // the device stopped delivering: close and reopen
};

struct ReadResult {
  ReadStatus status = ReadStatus::Ok;
  std::string detail;
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Throws CaptureError naming the device/file and what to check.
  virtual void open() = 0;
  virtual void close() = 0;
  // Blocks until the next frame (paced sources wait for their frame time).
  virtual ReadResult read(Frame& frame) = 0;
  // "v4l2:/dev/video0 1280x720@30", "folder:/data/run1 (240 images)", ...
  virtual std::string describe() const = 0;
  // Nominal frame rate, 0 when unknown; used for drop detection by timestamp.
  virtual double nominal_fps() const = 0;
};

}  // namespace arnav::capture
