#include "host/app/tool_freshness.hpp"

#include <algorithm>

#include "protocol/pose_convert.hpp"

namespace arnav::host {

ToolFreshnessTracker::ToolFreshnessTracker(std::int64_t stale_after_us, std::int64_t rate_window_us)
    : stale_after_us_(stale_after_us), rate_window_us_(rate_window_us) {}

void ToolFreshnessTracker::on_pose(const tool_pose_t& msg, std::int64_t arrival_us) {
  ToolFreshness& t = tools_[msg.tool_name];
  t.name = msg.tool_name;
  ++t.messages;
  if (t.last_sequence >= 0 && msg.sequence > t.last_sequence + 1) t.sequence_gaps += msg.sequence - t.last_sequence - 1;
  t.last_sequence = msg.sequence;
  if (t.last_frame >= 0) {
    if (msg.device_frame_number == t.last_frame)
      ++t.duplicate_frames;
    else if (msg.device_frame_number < t.last_frame)
      ++t.counter_restarts;
    else if (msg.device_frame_number > t.last_frame + 1)
      t.frame_gaps += msg.device_frame_number - t.last_frame - 1;
  }
  t.last_frame = msg.device_frame_number;
  t.last_arrival_us = arrival_us;
  t.last_status = msg.status;
  if (msg.status == tool_pose_t::STATUS_VALID) {
    ++t.valid;
    if (t.last_valid_arrival_us >= 0) t.max_valid_gap_us = std::max(t.max_valid_gap_us, arrival_us - t.last_valid_arrival_us);
    t.last_valid_arrival_us = arrival_us;
    t.recent_valid_us.push_back(arrival_us);
    try {
      t.X_ParentChild = get_pose(msg);
    } catch (const std::invalid_argument&) {
      // A VALID pose with a zero quaternion is a publisher bug: keep the last good one.
    }
    t.frame_parent = msg.frame_parent;
    t.frame_child = msg.frame_child;
  }
  update(arrival_us);
}

void ToolFreshnessTracker::on_health(const device_health_t& msg, std::int64_t /*arrival_us*/) {
  health_[msg.device] = msg;
  float& worst = worst_p99_[msg.device];
  worst = std::max(worst, msg.latency_p99_us);
}

void ToolFreshnessTracker::on_event(const appliance_event_t& msg) { events_.push_back(msg); }

void ToolFreshnessTracker::update(std::int64_t now_us) {
  for (auto& [name, t] : tools_) {
    const bool stale = t.last_valid_arrival_us < 0 || now_us - t.last_valid_arrival_us > stale_after_us_;
    if (stale && !t.stale && t.last_valid_arrival_us >= 0) ++t.stale_episodes;
    t.stale = stale;
    auto& r = t.recent_valid_us;
    while (!r.empty() && r.front() <= now_us - rate_window_us_) r.pop_front();
    t.rate_hz = static_cast<double>(r.size()) * 1e6 / static_cast<double>(rate_window_us_);
  }
}

}  // namespace arnav::host
