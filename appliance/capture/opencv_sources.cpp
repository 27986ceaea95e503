#include "appliance/capture/opencv_sources.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <thread>

#include "protocol/clock.hpp"

namespace arnav::capture {
namespace {

// 8-bit gray or BGR, whatever the file held (16-bit PNGs are scaled, alpha dropped).
cv::Mat to_8bit(const cv::Mat& in) {
  cv::Mat out = in;
  if (out.depth() == CV_16U) out.convertTo(out, CV_8U, 1.0 / 257.0);
  else if (out.depth() != CV_8U) out.convertTo(out, CV_8U);
  if (out.channels() == 4) cv::cvtColor(out, out, cv::COLOR_BGRA2BGR);
  return out;
}

}  // namespace

void sleep_until_mono_us(std::int64_t target_us) {
  const std::int64_t now = monotonic_us();
  if (target_us > now) std::this_thread::sleep_for(std::chrono::microseconds(target_us - now));
}

// ---- V4L2 ----

V4l2Source::V4l2Source(V4l2Settings settings) : settings_(std::move(settings)) {
  if (settings_.width <= 0 || settings_.height <= 0 || !(settings_.fps > 0)) {
    throw CaptureError("camera " + settings_.device + ": width, height and fps must be > 0");
  }
  if (!settings_.fourcc.empty() && settings_.fourcc.size() != 4) {
    throw CaptureError("camera " + settings_.device + ": fourcc '" + settings_.fourcc + "' must have 4 characters");
  }
}

void V4l2Source::open() {
  cap_.open(settings_.device, cv::CAP_V4L2);
  if (!cap_.isOpened()) {
    throw CaptureError("camera " + settings_.device +
                       ": cannot open through V4L2 (does it exist? `ls /dev/video*`; is the user in group 'video'?)");
  }
  if (!settings_.fourcc.empty()) {
    const auto& f = settings_.fourcc;
    cap_.set(cv::CAP_PROP_FOURCC, cv::VideoWriter::fourcc(f[0], f[1], f[2], f[3]));
  }
  cap_.set(cv::CAP_PROP_FRAME_WIDTH, settings_.width);
  cap_.set(cv::CAP_PROP_FRAME_HEIGHT, settings_.height);
  cap_.set(cv::CAP_PROP_FPS, settings_.fps);
  // V4L2 through OpenCV: auto exposure 1 = manual, 3 = aperture priority (automatic).
  if (settings_.exposure) {
    cap_.set(cv::CAP_PROP_AUTO_EXPOSURE, 1);
    cap_.set(cv::CAP_PROP_EXPOSURE, *settings_.exposure);
  } else {
    cap_.set(cv::CAP_PROP_AUTO_EXPOSURE, 3);
  }
  if (settings_.gain) cap_.set(cv::CAP_PROP_GAIN, *settings_.gain);
  const int w = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_WIDTH));
  const int h = static_cast<int>(cap_.get(cv::CAP_PROP_FRAME_HEIGHT));
  if (w != settings_.width || h != settings_.height) {
    cap_.release();
    throw CaptureError("camera " + settings_.device + ": asked for " + std::to_string(settings_.width) + "x" +
                       std::to_string(settings_.height) + ", the driver gives " + std::to_string(w) + "x" +
                       std::to_string(h) + " (set camera.width/height to a supported mode: `v4l2-ctl --list-formats-ext`)");
  }
  actual_fps_ = cap_.get(cv::CAP_PROP_FPS);
  last_time_us_ = 0;
}

void V4l2Source::close() { cap_.release(); }

ReadResult V4l2Source::read(Frame& frame) {
  if (!cap_.isOpened() || !cap_.grab()) return {ReadStatus::Lost, "camera " + settings_.device + ": no frame (unplugged?)"};
  const std::int64_t t = monotonic_us();
  if (!cap_.retrieve(frame.image) || frame.image.empty()) {
    return {ReadStatus::Lost, "camera " + settings_.device + ": frame could not be decoded"};
  }
  // The exposure instant: the driver's buffer timestamp (OpenCV's V4L2 backend returns
  // v4l2_buffer.timestamp as CAP_PROP_POS_MSEC; on CLOCK_MONOTONIC for drivers that set
  // V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC, e.g. uvcvideo, stamped at the start of the frame).
  // One that is not within a second before the read is not on this clock: the read time
  // stands in and the description says so (docs/camera.md, "Timestamps").
  const double driver_ms = cap_.get(cv::CAP_PROP_POS_MSEC);
  const auto driver_us = static_cast<std::int64_t>(std::llround(driver_ms * 1000.0));
  const bool driver_ok = driver_ms > 0 && driver_us <= t && t - driver_us < 1'000'000;
  if (!driver_ok) ++exposure_fallbacks_;
  const std::int64_t exposure_us = driver_ok ? driver_us : t;
  // V4L2's own buffer counter is not exposed by OpenCV: count frame periods between
  // timestamps instead, so a stall of k periods shows as k - 1 dropped frames.
  const double fps = nominal_fps();
  std::int64_t step = 1;
  if (last_time_us_ != 0 && fps > 0) {
    step = std::max<std::int64_t>(1, std::llround(static_cast<double>(exposure_us - last_time_us_) * fps * 1e-6));
  }
  sequence_ += step;
  last_time_us_ = exposure_us;
  frame.capture_time_mono_us = exposure_us;
  frame.delivered_time_mono_us = t;
  frame.sequence = sequence_;
  frame.origin.clear();
  return {};
}

std::string V4l2Source::describe() const {
  return "v4l2:" + settings_.device + " " + std::to_string(settings_.width) + "x" + std::to_string(settings_.height) +
         "@" + std::to_string(static_cast<int>(std::lround(nominal_fps()))) +
         (exposure_fallbacks_ > 0 ? "; exposure = read time for " + std::to_string(exposure_fallbacks_) +
                                        " frame(s) (driver timestamp not on CLOCK_MONOTONIC)"
                                  : std::string());
}

// ---- video file ----

VideoFileSource::VideoFileSource(std::filesystem::path path, bool realtime, bool loop)
    : path_(std::move(path)), realtime_(realtime), loop_(loop) {}

void VideoFileSource::open() {
  if (!std::filesystem::is_regular_file(path_)) throw CaptureError("video file " + path_.string() + ": not found");
  cap_.open(path_.string());
  if (!cap_.isOpened()) {
    throw CaptureError("video file " + path_.string() + ": cannot be decoded (unsupported container or codec)");
  }
  fps_ = cap_.get(cv::CAP_PROP_FPS);
  if (!(fps_ > 0 && fps_ < 1000)) fps_ = 0.0;
  index_ = 0;
  start_us_ = monotonic_us();
}

void VideoFileSource::close() { cap_.release(); }

ReadResult VideoFileSource::read(Frame& frame) {
  if (!cap_.isOpened()) return {ReadStatus::Lost, "video file " + path_.string() + ": not open"};
  if (!cap_.read(frame.image) || frame.image.empty()) {
    if (!loop_ || index_ == 0) return {ReadStatus::EndOfStream, "video file " + path_.string() + ": end"};
    cap_.set(cv::CAP_PROP_POS_FRAMES, 0);
    if (!cap_.read(frame.image) || frame.image.empty()) {
      return {ReadStatus::EndOfStream, "video file " + path_.string() + ": cannot rewind"};
    }
  }
  if (realtime_ && fps_ > 0) sleep_until_mono_us(start_us_ + static_cast<std::int64_t>(1e6 * static_cast<double>(index_) / fps_));
  frame.capture_time_mono_us = monotonic_us();
  frame.delivered_time_mono_us = frame.capture_time_mono_us;
  frame.sequence = index_++;
  frame.origin = path_.string();
  return {};
}

std::string VideoFileSource::describe() const { return "file:" + path_.string(); }

// ---- image folder ----

ImageFolderSource::ImageFolderSource(std::filesystem::path folder, double fps, bool loop)
    : folder_(std::move(folder)), fps_(fps), loop_(loop) {
  if (!(fps_ >= 0)) throw CaptureError("image folder " + folder_.string() + ": fps must be >= 0");
}

void ImageFolderSource::open() {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder_, ec)) throw CaptureError("image folder " + folder_.string() + ": not a folder");
  files_.clear();
  for (const auto& entry : std::filesystem::directory_iterator(folder_, ec)) {
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".bmp" || ext == ".tif" || ext == ".tiff" ||
        ext == ".pgm" || ext == ".ppm") {
      files_.push_back(entry.path());
    }
  }
  if (ec) throw CaptureError("image folder " + folder_.string() + ": cannot list (" + ec.message() + ")");
  if (files_.empty()) {
    throw CaptureError("image folder " + folder_.string() + ": no images (.png .jpg .jpeg .bmp .tif .tiff .pgm .ppm)");
  }
  std::sort(files_.begin(), files_.end());
  next_ = 0;
  sequence_ = 0;
  start_us_ = monotonic_us();
}

void ImageFolderSource::close() {}

ReadResult ImageFolderSource::read(Frame& frame) {
  if (next_ >= files_.size()) {
    if (!loop_) return {ReadStatus::EndOfStream, "image folder " + folder_.string() + ": all images read"};
    next_ = 0;
  }
  const std::filesystem::path& file = files_[next_++];
  const std::int64_t seq = sequence_++;
  if (fps_ > 0) sleep_until_mono_us(start_us_ + static_cast<std::int64_t>(1e6 * static_cast<double>(seq) / fps_));
  cv::Mat img;
  try {
    img = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return {ReadStatus::Skipped, file.string() + ": unreadable image (" + e.what() + ")"};
  }
  if (img.empty()) {
    return {ReadStatus::Skipped, file.string() + ": unreadable image (not an image file, or truncated); skipped"};
  }
  frame.image = to_8bit(img);
  frame.capture_time_mono_us = monotonic_us();
  frame.delivered_time_mono_us = frame.capture_time_mono_us;
  frame.sequence = seq;
  frame.origin = file.string();
  return {};
}

std::string ImageFolderSource::describe() const {
  return "folder:" + folder_.string() + " (" + std::to_string(files_.size()) + " images)";
}

}  // namespace arnav::capture
