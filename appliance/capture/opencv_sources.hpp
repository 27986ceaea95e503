#pragma once
// Capture sources backed by OpenCV: a V4L2 camera, a video file, a folder of images.
#include <opencv2/videoio.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "appliance/capture/frame_source.hpp"

namespace arnav::capture {

struct V4l2Settings {
  std::string device = "/dev/video0";
  int width = 1280;
  int height = 720;
  double fps = 30.0;
  std::string fourcc = "MJPG";            // pixel format asked of the driver ("" = driver default)
  std::optional<double> exposure;         // manual exposure in V4L2 units (100 us); unset = auto
  std::optional<double> gain;
};

// The image size the camera delivers must be the one asked for (the intrinsics are only
// valid for it): a mismatch is an open error, not a silent default.
class V4l2Source : public FrameSource {
 public:
  explicit V4l2Source(V4l2Settings settings);
  void open() override;
  void close() override;
  ReadResult read(Frame& frame) override;
  std::string describe() const override;
  double nominal_fps() const override { return actual_fps_ > 0 ? actual_fps_ : settings_.fps; }

 private:
  V4l2Settings settings_;
  cv::VideoCapture cap_;
  double actual_fps_ = 0.0;
  std::int64_t sequence_ = -1;
  std::int64_t last_time_us_ = 0;
  std::int64_t exposure_fallbacks_ = 0;  // frames whose driver timestamp was unusable (read time used)
};

class VideoFileSource : public FrameSource {
 public:
  // realtime: deliver at the file's frame rate; else as fast as read. loop: restart at the end.
  VideoFileSource(std::filesystem::path path, bool realtime, bool loop);
  void open() override;
  void close() override;
  ReadResult read(Frame& frame) override;
  std::string describe() const override;
  double nominal_fps() const override { return fps_; }

 private:
  std::filesystem::path path_;
  bool realtime_, loop_;
  cv::VideoCapture cap_;
  double fps_ = 0.0;
  std::int64_t index_ = 0;
  std::int64_t start_us_ = 0;
};

// Images of a folder in name order (.png .jpg .jpeg .bmp .tif .tiff .pgm .ppm). An
// unreadable file is reported (ReadStatus::Skipped, naming it) and passed over.
class ImageFolderSource : public FrameSource {
 public:
  // fps > 0: paced at that rate; 0: as fast as read.
  ImageFolderSource(std::filesystem::path folder, double fps, bool loop);
  void open() override;
  void close() override;
  ReadResult read(Frame& frame) override;
  std::string describe() const override;
  double nominal_fps() const override { return fps_; }
  const std::vector<std::filesystem::path>& files() const { return files_; }

 private:
  std::filesystem::path folder_;
  double fps_;
  bool loop_;
  std::vector<std::filesystem::path> files_;
  size_t next_ = 0;
  std::int64_t sequence_ = 0;
  std::int64_t start_us_ = 0;
};

// Sleeps until the monotonic time target_us (no-op when already past).
void sleep_until_mono_us(std::int64_t target_us);

}  // namespace arnav::capture
