#pragma once
// The camera path of the appliance: capture -> AprilTag detection -> board poses ->
// reference frame -> LCM. Runs on its own thread (start/stop) when the configuration has
// a `camera:` section. Publishes, on its own LCM instance:
//   ARNAV_POSE_<tool>    tool_pose_t, source camera, every frame (STATUS_MISSING when not seen)
//   ARNAV_HEALTH_camera  device_health_t at camera.health_rate_hz
//   ARNAV_EVENT          appliance_event_t (source "camera") on changes: camera lost or
//                        recovered, tool found or lost (with the reason), pose flips
//   ARNAV_FRAME_<name>   image_frame_t (JPEG) when camera.publish_frames is enabled
// Latency in health: frame delivered by the source -> all poses of the frame published
// (the exposure instant, capture_time_mono_us in the messages, is earlier by the sensor's
// readout: docs/camera.md, "Timestamps").
#include <lcm/lcm-cpp.hpp>

#include "protocol/seal/sealed_lcm.hpp"

#include <atomic>
#include <memory>
#include <mutex>
#include <thread>

#include "appliance/capture/capture.hpp"
#include "appliance/frames/reference_frames.hpp"
#include "appliance/camera/camera_config.hpp"

namespace arnav::camera {

struct PipelineStats {
  std::int64_t frames = 0;
  std::int64_t poses_published = 0;
  std::int64_t dropped_frames = 0;
  std::int64_t reconnects = 0;
  std::int64_t flips = 0;
  double last_latency_us = 0.0;
};

class CameraPipeline {
 public:
  // Throws CameraConfigError when the LCM URL cannot be opened or the source not built.
  // frames: null means reference Cam without hand-eye. The pipeline opens its own LCM
  // instance (publishing from two threads through one instance is not relied upon).
  CameraPipeline(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames, const std::string& lcm_url,
                 const seal::BusSecurity& security);
  // Publishes through a given instance (tests: memq:// shared with the subscriber).
  CameraPipeline(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames, std::shared_ptr<seal::SealedLcm> lcm);
  ~CameraPipeline();
  CameraPipeline(const CameraPipeline&) = delete;
  CameraPipeline& operator=(const CameraPipeline&) = delete;

  void start();                           // runs run() on a thread
  void stop();                            // asks it to stop and joins
  // Blocking loop, until stop or the end of a finite source. Returns the frames processed.
  std::int64_t run(const std::atomic<bool>& stop);
  bool finished() const { return finished_.load(); }
  PipelineStats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::atomic<bool> stop_{false};
  std::atomic<bool> finished_{false};
  std::thread thread_;
};

// Builds the configured capture source.
std::unique_ptr<capture::FrameSource> make_source(const CameraConfig& config);

}  // namespace arnav::camera
