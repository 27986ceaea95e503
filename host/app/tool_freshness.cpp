#include "host/app/tool_freshness.hpp"

#include <algorithm>
#include <cstdio>

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

void ToolFreshnessTracker::on_health(const device_health_t& msg, std::int64_t /*arrival_us*/) { health_[msg.device] = msg; }

void ToolFreshnessTracker::on_event(const appliance_event_t& msg) { events_.push_back(msg); }

void ToolFreshnessTracker::update(std::int64_t now_us) {
  for (auto& [name, t] : tools_) {
    const bool stale = t.last_valid_arrival_us < 0 || now_us - t.last_valid_arrival_us > stale_after_us_;
    if (stale && !t.stale && t.last_valid_arrival_us >= 0) ++t.stale_episodes;
    t.stale = stale;
    auto& r = t.recent_valid_us;
    r.erase(r.begin(), std::find_if(r.begin(), r.end(), [&](std::int64_t a) { return a > now_us - rate_window_us_; }));
    t.rate_hz = static_cast<double>(r.size()) * 1e6 / static_cast<double>(rate_window_us_);
  }
}

namespace {
const char* status_name(std::int8_t s) {
  switch (s) {
    case tool_pose_t::STATUS_VALID: return "VALID";
    case tool_pose_t::STATUS_MISSING: return "MISSING";
    case tool_pose_t::STATUS_OUT_OF_VOLUME: return "OUT_OF_VOL";
    case tool_pose_t::STATUS_PARTIALLY_OUT_OF_VOLUME: return "PARTIAL";
    case tool_pose_t::STATUS_DISABLED: return "DISABLED";
    default: return "-";
  }
}
const char* link_name(std::int8_t s) {
  switch (s) {
    case device_health_t::LINK_DOWN: return "DOWN";
    case device_health_t::LINK_CONNECTING: return "CONNECTING";
    case device_health_t::LINK_INITIALISING: return "INITIALISING";
    case device_health_t::LINK_TRACKING: return "TRACKING";
    case device_health_t::LINK_RECOVERING: return "RECOVERING";
    default: return "?";
  }
}
}  // namespace

std::string format_status_table(const ToolFreshnessTracker& tracker, std::int64_t now_us) {
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "%-14s %-6s %-10s %8s %9s %10s %6s %6s  %s\n", "tool", "fresh", "status", "rate_Hz", "age_ms",
                "frame", "gaps", "dups", "position (mm) and frames");
  out += line;
  for (const auto& [name, t] : tracker.tools()) {
    const double age_ms = t.last_valid_arrival_us < 0 ? -1.0 : static_cast<double>(now_us - t.last_valid_arrival_us) * 1e-3;
    const Eigen::Vector3d p = t.X_ParentChild.translation();
    std::snprintf(line, sizeof line, "%-14s %-6s %-10s %8.1f %9.1f %10lld %6lld %6lld  (%.2f, %.2f, %.2f) X_%s%s\n", name.c_str(),
                  t.stale ? "STALE" : "fresh", status_name(t.last_status), t.rate_hz, age_ms, static_cast<long long>(t.last_frame),
                  static_cast<long long>(t.frame_gaps), static_cast<long long>(t.duplicate_frames), p.x(), p.y(), p.z(),
                  t.frame_parent.c_str(), t.frame_child.c_str());
    out += line;
  }
  for (const auto& [device, h] : tracker.health()) {
    std::snprintf(line, sizeof line,
                  "device %-6s link %-12s %6.1f Hz  frames %lld  crc %lld  timeouts %lld  resets %lld  reconnects %lld  "
                  "dropped %lld  latency p50/p99/max %.0f/%.0f/%.0f us  %s\n",
                  device.c_str(), link_name(h.link_state), static_cast<double>(h.frame_rate_hz), static_cast<long long>(h.frames_total),
                  static_cast<long long>(h.crc_errors), static_cast<long long>(h.timeouts), static_cast<long long>(h.resets),
                  static_cast<long long>(h.reconnects), static_cast<long long>(h.dropped_frames), static_cast<double>(h.latency_p50_us),
                  static_cast<double>(h.latency_p99_us), static_cast<double>(h.latency_max_us), h.detail.c_str());
    out += line;
  }
  return out;
}

}  // namespace arnav::host
