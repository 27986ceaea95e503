#pragma once
// What the host knows about each tracked tool: when its last valid pose arrived (host
// monotonic clock), whether it is stale (no valid pose for longer than a configurable
// age), its rate, and the continuity of the device frame counter (duplicates, gaps).
// Also keeps the last health message per device and counts events. Pure bookkeeping:
// the caller passes the arrival time, so it is testable without a clock.
#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/tool_pose_t.hpp"

namespace arnav::host {

struct ToolFreshness {
  std::string name;
  std::int64_t messages = 0;
  std::int64_t valid = 0;
  std::int64_t duplicate_frames = 0;  // same device frame number published twice
  std::int64_t frame_gaps = 0;        // frames skipped (counter jumped by more than 1)
  std::int64_t counter_restarts = 0;  // counter went backwards (device reset)
  std::int64_t sequence_gaps = 0;     // LCM messages lost (per-channel sequence)
  std::int64_t stale_episodes = 0;    // fresh -> stale transitions
  std::int64_t max_valid_gap_us = 0;  // longest time between two valid poses (outages)
  std::int64_t last_frame = -1;
  std::int64_t last_sequence = -1;
  std::int64_t last_arrival_us = -1;
  std::int64_t last_valid_arrival_us = -1;
  std::int8_t last_status = -1;
  bool stale = true;  // until the first valid pose
  Eigen::Isometry3d X_ParentChild = Eigen::Isometry3d::Identity();
  std::string frame_parent, frame_child;
  double rate_hz = 0.0;  // valid poses over the last rate window
  std::deque<std::int64_t> recent_valid_us;  // arrival times inside the rate window
};

class ToolFreshnessTracker {
 public:
  explicit ToolFreshnessTracker(std::int64_t stale_after_us, std::int64_t rate_window_us = 1'000'000);

  void on_pose(const tool_pose_t& msg, std::int64_t arrival_us);
  void on_health(const device_health_t& msg, std::int64_t arrival_us);
  void on_event(const appliance_event_t& msg);
  // Re-evaluates staleness and rates at `now_us`.
  void update(std::int64_t now_us);

  const std::map<std::string, ToolFreshness>& tools() const { return tools_; }
  const std::map<std::string, device_health_t>& health() const { return health_; }
  // Worst latency p99 (us) any health message of the device reported during the run.
  const std::map<std::string, float>& worst_latency_p99_us() const { return worst_p99_; }
  const std::vector<appliance_event_t>& events() const { return events_; }
  std::int64_t stale_after_us() const { return stale_after_us_; }

 private:
  std::int64_t stale_after_us_;
  std::int64_t rate_window_us_;
  std::map<std::string, ToolFreshness> tools_;
  std::map<std::string, device_health_t> health_;
  std::map<std::string, float> worst_p99_;
  std::vector<appliance_event_t> events_;
};

}  // namespace arnav::host
