#pragma once
// Turns session output into LCM messages: one tool_pose_t per configured tool and device
// frame (ARNAV_POSE_<tool>), device_health_t (ARNAV_HEALTH_ndi), appliance_event_t
// (ARNAV_EVENT). Messages are built once and reused so the per-frame path only fills
// numbers. Latency: last byte of the reply read -> all poses of the frame published.
// Frame: X_NdiTool, or the configured reference (appliance/frames): X_RefTool when the
// reference tool was seen in the same frame, X_CamTool with a hand-eye. A pose that
// cannot be expressed in the reference (reference tool not visible) goes out as
// X_NdiTool with frame_parent "Ndi", so a consumer always knows the frame it reads.
#include <lcm/lcm-cpp.hpp>

#include <memory>
#include <string>
#include <vector>

#include "appliance/realtime/latency_stats.hpp"
#include "appliance/frames/reference_frames.hpp"
#include "appliance/ndi/session.hpp"
#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace arnav::app {

class Publisher {
 public:
  Publisher(seal::SealedLcm& lcm, const std::vector<ndi::ToolConfig>& tools, double device_rate_hz);

  // Publishes every configured tool's pose for one new frame; returns the latency (us).
  float publish_frame(const ndi::Session& session, const ndi::TrackingReply& reply, std::int64_t receive_mono_us);
  // Returns the message published (for logging).
  device_health_t publish_health(const ndi::Session& session, const std::string& port_label, double frame_rate_hz);
  void publish_event(const ndi::Event& event);

  // Express poses in this reference from now on. For Ref, the reference tool's own pose is
  // still published as X_NdiRef (it defines Ref), and update_reference() must be fed with
  // each frame's reference pose before publish_frame() (the appliance does this).
  void set_reference_frames(std::shared_ptr<const frames::ReferenceFrames> reference_frames);

 private:
  seal::SealedLcm& lcm_;
  double device_rate_hz_;
  std::vector<std::string> channels_;
  std::vector<tool_pose_t> poses_;
  std::string health_channel_;
  std::int64_t event_sequence_ = 0;
  LatencyWindow latency_;
  std::shared_ptr<const frames::ReferenceFrames> frames_;
};

}  // namespace arnav::app
