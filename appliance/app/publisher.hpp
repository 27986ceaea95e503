#pragma once
// Turns session output into LCM messages: one tool_pose_t per configured tool and device
// frame (ARNAV_POSE_<tool>), device_health_t (ARNAV_HEALTH_ndi), appliance_event_t
// (ARNAV_EVENT). Messages are built once and reused so the per-frame path only fills
// numbers. Latency: last byte of the reply read -> all poses of the frame published.
#include <lcm/lcm-cpp.hpp>

#include <string>
#include <vector>

#include "appliance/app/latency_stats.hpp"
#include "appliance/ndi/session.hpp"
#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/tool_pose_t.hpp"

namespace arnav::app {

class Publisher {
 public:
  Publisher(lcm::LCM& lcm, const std::vector<ndi::ToolConfig>& tools, double device_rate_hz);

  // Publishes every configured tool's pose for one new frame; returns the latency (us).
  float publish_frame(const ndi::Session& session, const ndi::TrackingReply& reply, std::int64_t receive_mono_us);
  // Returns the message published (for logging).
  device_health_t publish_health(const ndi::Session& session, const std::string& port_label, double frame_rate_hz);
  void publish_event(const ndi::Event& event);

 private:
  lcm::LCM& lcm_;
  double device_rate_hz_;
  std::vector<std::string> channels_;
  std::vector<tool_pose_t> poses_;
  std::string health_channel_;
  std::int64_t event_sequence_ = 0;
  LatencyWindow latency_;
};

}  // namespace arnav::app
