#include "appliance/camera/camera_pipeline.hpp"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>

#include "appliance/markers/board_tracker.hpp"
#include "appliance/markers/tag_detector.hpp"
#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/image_frame_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::camera {
namespace {

int8_t link_state(capture::LinkState s) {
  switch (s) {
    case capture::LinkState::Streaming: return device_health_t::LINK_TRACKING;
    case capture::LinkState::Connecting: return device_health_t::LINK_CONNECTING;
    case capture::LinkState::Recovering: return device_health_t::LINK_RECOVERING;
    case capture::LinkState::Down:
    case capture::LinkState::Ended: return device_health_t::LINK_DOWN;
  }
  return device_health_t::LINK_DOWN;
}

float percentile(std::vector<float> v, double q) {
  if (v.empty()) return 0.f;
  const auto k = static_cast<size_t>(std::min<double>(static_cast<double>(v.size() - 1), std::floor(q * static_cast<double>(v.size()))));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

std::shared_ptr<seal::SealedLcm> open_lcm(const std::string& url, const seal::BusSecurity& security) {
  auto lcm = std::make_shared<seal::SealedLcm>(url, security);
  if (!lcm->good()) throw CameraConfigError("camera: cannot open LCM at '" + url + "'");
  return lcm;
}

}  // namespace

std::unique_ptr<capture::FrameSource> make_source(const CameraConfig& c) {
  switch (c.source) {
    case SourceKind::V4l2: return std::make_unique<capture::V4l2Source>(c.v4l2);
    case SourceKind::File: return std::make_unique<capture::VideoFileSource>(c.path, c.realtime, c.loop);
    case SourceKind::Folder: return std::make_unique<capture::ImageFolderSource>(c.path, c.folder_fps, c.loop);
    case SourceKind::Synthetic: return std::make_unique<capture::SyntheticSource>(*c.synthetic);
  }
  throw CameraConfigError("camera: unknown source kind");
}

struct CameraPipeline::Impl {
  struct Tool {
    explicit Tool(markers::BoardTracker t) : tracker(std::move(t)) {}
    markers::BoardTracker tracker;
    tool_pose_t msg{};
    std::string channel;
    bool seen = false;
    std::string last_reason;
    double added_latency_s = 0.0;
  };

  CameraConfig cfg;
  std::shared_ptr<frames::ReferenceFrames> frames;
  std::shared_ptr<seal::SealedLcm> lcm_ptr;
  seal::SealedLcm& lcm;
  std::unique_ptr<capture::Capture> capture;
  markers::TagDetector detector;
  std::vector<Tool> tools;
  std::int64_t event_sequence = 0;
  std::int64_t health_sequence_next_us = 0;
  std::vector<float> latencies_us;
  std::int64_t window_start_us = 0;
  std::int64_t window_frames = 0;
  bool size_mismatch_reported = false;
  mutable std::mutex stats_mutex;
  PipelineStats stats;

  Impl(CameraConfig c, std::shared_ptr<frames::ReferenceFrames> f, std::shared_ptr<seal::SealedLcm> l)
      : cfg(std::move(c)), frames(std::move(f)), lcm_ptr(std::move(l)), lcm(*lcm_ptr), detector(cfg.detector) {
    if (!lcm.good()) throw CameraConfigError(cfg.source_file + ": cannot open LCM");
    if (!frames) frames = std::make_shared<frames::ReferenceFrames>(frames::Reference::Cam, std::nullopt, "", 0.05);
    for (const auto& t : cfg.tools) {
      Tool tool(markers::BoardTracker(markers::BoardPoseEstimator(t.board, cfg.camera, cfg.pose), cfg.tracker));
      tool.channel = channels::pose(t.board.name);
      tool.msg.tool_name = t.board.name;
      tool.msg.tool_id = t.tool_id;
      tool.msg.source = tool_pose_t::SOURCE_CAMERA;
      tool.msg.frame_child = "Board";
      tools.push_back(std::move(tool));
    }
    std::unique_ptr<capture::FrameSource> source;
    try {
      source = make_source(cfg);
    } catch (const capture::CaptureError& e) {
      throw CameraConfigError(cfg.source_file + ": camera: " + e.what());
    }
    capture = std::make_unique<capture::Capture>(std::move(source), cfg.retry_interval_s,
                                                 [this](const capture::CaptureEvent& e) { event(e.severity, e.code, e.text); });
  }

  void event(int severity, const std::string& code, const std::string& text) {
    appliance_event_t e;
    e.source = "camera";
    e.severity = static_cast<int8_t>(severity);
    e.code = code;
    e.text = text;
    e.time_mono_us = monotonic_us();
    e.time_wall_us = wall_us();
    e.sequence = event_sequence++;
    lcm.publish(std::string(channels::kEvents), &e);
    static const char* names[] = {"info", "WARNING", "ERROR"};
    std::cerr << "arnav-appliance: [camera] " << names[std::clamp(severity, 0, 2)] << " " << code << ": " << text << "\n";
  }

  void process(const capture::Frame& frame) {
    if (frame.image.cols != cfg.camera.width || frame.image.rows != cfg.camera.height) {
      if (!size_mismatch_reported) {
        event(2, "CAMERA_IMAGE_SIZE",
              (frame.origin.empty() ? capture->source().describe() : frame.origin) + ": image is " +
                  std::to_string(frame.image.cols) + "x" + std::to_string(frame.image.rows) + " but the intrinsics are for " +
                  std::to_string(cfg.camera.width) + "x" + std::to_string(cfg.camera.height) + "; frames skipped");
        size_mismatch_reported = true;
      }
      return;
    }
    const std::vector<markers::TagDetection> dets = detector.detect(frame.image);
    const std::int64_t recv_wall = wall_us() - (monotonic_us() - frame.capture_time_mono_us);
    for (auto& tool : tools) {
      std::string reason;
      const auto tracked = tool.tracker.update(dets, frame.capture_time_mono_us, &reason);
      tool_pose_t& m = tool.msg;
      m.status = tool_pose_t::STATUS_MISSING;
      m.reprojection_error_px = 0.f;
      m.quality = 0.f;
      m.frame_parent = frames::to_string(frames->reference());
      if (tracked) {
        const frames::Converted conv = frames->camera_pose(tracked->estimate.X_CamBoard, frame.capture_time_mono_us);
        m.frame_parent = conv.frame_parent;
        m.reprojection_error_px = static_cast<float>(tracked->estimate.reprojection_rms_px);
        m.quality = static_cast<float>(tracked->estimate.quality);
        tool.added_latency_s = tracked->added_latency_s;
        if (conv.X_ParentChild) {
          set_pose(m, *conv.X_ParentChild);
          m.status = tool_pose_t::STATUS_VALID;
        } else {
          reason = conv.reason;
        }
        if (tracked->estimate.flipped) {
          event(1, "CAMERA_POSE_FLIP", "tool '" + m.tool_name + "': planar pose ambiguity, the pose flipped (reprojection " +
                                           std::to_string(tracked->estimate.reprojection_rms_px) + " px vs " +
                                           std::to_string(tracked->estimate.alt_reprojection_rms_px) + " px)");
        }
      }
      const bool valid = m.status == tool_pose_t::STATUS_VALID;
      if (valid && !tool.seen) event(0, "CAMERA_TOOL_FOUND", "tool '" + m.tool_name + "' tracked by the camera");
      if (!valid && (tool.seen || tool.last_reason.empty())) {
        event(1, "CAMERA_TOOL_LOST", "tool '" + m.tool_name + "': " + reason);
      }
      tool.seen = valid;
      tool.last_reason = valid ? std::string() : reason;
      m.rms_error_mm = 0.f;
      m.port_status = 0;
      m.device_frame_number = frame.sequence;
      m.device_time_us = frame.capture_time_mono_us;
      m.receive_time_mono_us = frame.capture_time_mono_us;
      m.receive_time_wall_us = recv_wall;
      m.publish_time_mono_us = monotonic_us();
      m.publish_time_wall_us = wall_us();
      lcm.publish(tool.channel, &m);
      ++m.sequence;
      if (valid) {
        std::lock_guard lock(stats_mutex);
        ++stats.poses_published;
      }
    }
    // The appliance's own share: from the frame's delivery by the source (not its exposure:
    // the sensor's readout is the camera's, docs/camera.md "Timestamps").
    const auto latency = static_cast<float>(monotonic_us() - frame.delivered_time_mono_us);
    latencies_us.push_back(latency);
    if (cfg.publish_frames.enabled && frame.sequence % cfg.publish_frames.every == 0) publish_image(frame);
    std::lock_guard lock(stats_mutex);
    ++stats.frames;
    stats.last_latency_us = static_cast<double>(latency);
  }

  void publish_image(const capture::Frame& frame) {
    cv::Mat img = frame.image;
    if (img.cols > cfg.publish_frames.max_width) {
      const double s = static_cast<double>(cfg.publish_frames.max_width) / img.cols;
      cv::resize(img, img, cv::Size(), s, s, cv::INTER_AREA);
    }
    std::vector<uchar> jpeg;
    cv::imencode(".jpg", img, jpeg, {cv::IMWRITE_JPEG_QUALITY, cfg.publish_frames.jpeg_quality});
    image_frame_t m;
    m.camera_name = cfg.name;
    m.sequence = frame.sequence;
    m.capture_time_mono_us = frame.capture_time_mono_us;
    m.capture_time_wall_us = wall_us() - (monotonic_us() - frame.capture_time_mono_us);
    m.width = img.cols;
    m.height = img.rows;
    m.source_width = frame.image.cols;
    m.source_height = frame.image.rows;
    m.channels = static_cast<int8_t>(img.channels());
    m.encoding = image_frame_t::ENCODING_JPEG;
    m.data.assign(jpeg.begin(), jpeg.end());
    m.size = static_cast<int32_t>(m.data.size());
    m.publish_time_mono_us = monotonic_us();
    lcm.publish(channels::frame(cfg.name), &m);
  }

  void health(std::int64_t now) {
    const capture::CaptureStats cs = capture->stats();
    device_health_t h{};
    h.device = "camera";
    h.link_state = link_state(cs.state);
    h.port = capture->source().describe();
    h.frame_rate_hz = static_cast<float>(static_cast<double>(window_frames) * 1e6 / std::max<std::int64_t>(1, now - window_start_us));
    h.frames_total = cs.frames;
    h.reconnects = cs.reconnects;
    h.dropped_frames = cs.dropped_frames;
    h.latency_p50_us = percentile(latencies_us, 0.5);
    h.latency_p99_us = percentile(latencies_us, 0.99);
    h.latency_max_us = latencies_us.empty() ? 0.f : *std::max_element(latencies_us.begin(), latencies_us.end());
    h.publish_time_mono_us = now;
    h.publish_time_wall_us = wall_us();
    double smoothing_ms = 0.0;
    std::int64_t flips = 0, ambiguous = 0;
    for (const auto& t : tools) {
      smoothing_ms = std::max(smoothing_ms, 1e3 * t.added_latency_s);
      flips += t.tracker.flips();
      ambiguous += t.tracker.ambiguous_frames();
    }
    h.detail = "family " + cfg.detector.family + ", decimate " + std::to_string(cfg.detector.decimate).substr(0, 4) +
               ", threads " + std::to_string(cfg.detector.threads) + "; smoothing adds " +
               std::to_string(smoothing_ms).substr(0, 5) + " ms; ambiguous frames " + std::to_string(ambiguous) +
               ", flips " + std::to_string(flips) + "; skipped images " + std::to_string(cs.skipped) +
               (cs.last_fault.empty() ? "" : "; last fault: " + cs.last_fault);
    lcm.publish(channels::health("camera"), &h);
    latencies_us.clear();
    window_frames = 0;
    window_start_us = now;
    std::lock_guard lock(stats_mutex);
    stats.dropped_frames = cs.dropped_frames;
    stats.reconnects = cs.reconnects;
    stats.flips = flips;
  }
};

CameraPipeline::CameraPipeline(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames,
                               const std::string& lcm_url, const seal::BusSecurity& security)
    : CameraPipeline(std::move(config), std::move(frames), open_lcm(lcm_url, security)) {}

CameraPipeline::CameraPipeline(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames,
                               std::shared_ptr<seal::SealedLcm> lcm)
    : impl_(std::make_unique<Impl>(std::move(config), std::move(frames), std::move(lcm))) {}

CameraPipeline::~CameraPipeline() { stop(); }

void CameraPipeline::start() {
  if (thread_.joinable()) return;
  stop_ = false;
  thread_ = std::thread([this] { run(stop_); });
}

void CameraPipeline::stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

std::int64_t CameraPipeline::run(const std::atomic<bool>& stop) {
  Impl& d = *impl_;
  const auto health_period_us = static_cast<std::int64_t>(1e6 / d.cfg.health_rate_hz);
  d.window_start_us = monotonic_us();
  std::int64_t next_health = d.window_start_us + health_period_us;
  std::int64_t processed = 0;
  capture::Frame frame;
  while (!stop.load()) {
    const auto next = d.capture->next(frame, stop);
    if (next == capture::Capture::Next::Frame) {
      try {
        d.process(frame);
      } catch (const std::exception& e) {  // a bad frame must not take the appliance down
        d.event(2, "CAMERA_FRAME_FAILED", "frame " + std::to_string(frame.sequence) + ": " + e.what());
      }
      ++processed;
      ++d.window_frames;
    }
    const std::int64_t now = monotonic_us();
    if (now >= next_health || next != capture::Capture::Next::Frame) {
      d.health(now);
      next_health = now + health_period_us;
    }
    if (next != capture::Capture::Next::Frame) break;
  }
  finished_ = true;
  return processed;
}

PipelineStats CameraPipeline::stats() const {
  std::lock_guard lock(impl_->stats_mutex);
  PipelineStats s = impl_->stats;
  return s;
}

}  // namespace arnav::camera
