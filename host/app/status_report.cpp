#include "host/app/status_report.hpp"

#include <cstdio>
#include <map>

namespace arnav::host {

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

std::string format_summary(const ToolFreshnessTracker& tracker, double run_s) {
  std::string out;
  char line[512];
  std::snprintf(line, sizeof line, "== arnav-host summary: %.1f s ==\n", run_s);
  out += line;
  for (const auto& [name, t] : tracker.tools()) {
    std::snprintf(line, sizeof line,
                  "tool %-12s %7lld valid poses (%.1f Hz mean), %lld duplicate frames, %lld frame gaps, %lld counter restarts, "
                  "%lld stale episodes, longest outage %.3f s%s\n",
                  name.c_str(), static_cast<long long>(t.valid), run_s > 0 ? static_cast<double>(t.valid) / run_s : 0.0,
                  static_cast<long long>(t.duplicate_frames), static_cast<long long>(t.frame_gaps),
                  static_cast<long long>(t.counter_restarts), static_cast<long long>(t.stale_episodes),
                  static_cast<double>(t.max_valid_gap_us) * 1e-6, t.stale ? " (STALE at exit)" : "");
    out += line;
  }
  for (const auto& [device, h] : tracker.health()) {
    const auto worst = tracker.worst_latency_p99_us().find(device);
    std::snprintf(line, sizeof line,
                  "device %-6s link %s, %lld frames, crc errors %lld, timeouts %lld, resyncs %lld, error replies %lld, resets %lld, "
                  "reconnects %lld, dropped frames %lld\n"
                  "device %-6s latency (last period) p50 %.0f us, p99 %.0f us, max %.0f us; worst p99 of the run %.0f us\n",
                  device.c_str(), link_name(h.link_state), static_cast<long long>(h.frames_total), static_cast<long long>(h.crc_errors),
                  static_cast<long long>(h.timeouts), static_cast<long long>(h.resyncs), static_cast<long long>(h.error_replies),
                  static_cast<long long>(h.resets), static_cast<long long>(h.reconnects), static_cast<long long>(h.dropped_frames),
                  device.c_str(), static_cast<double>(h.latency_p50_us), static_cast<double>(h.latency_p99_us),
                  static_cast<double>(h.latency_max_us), worst == tracker.worst_latency_p99_us().end() ? 0.0 : static_cast<double>(worst->second));
    out += line;
  }
  std::map<std::string, int> counts;
  for (const auto& e : tracker.events()) ++counts[e.code];
  out += "events:";
  for (const auto& [code, n] : counts) out += " " + code + " x" + std::to_string(n);
  out += counts.empty() ? " none\n" : "\n";
  for (const auto& e : tracker.events())
    if (e.severity != appliance_event_t::SEVERITY_INFO || e.code.find("RECOVERED") != std::string::npos)
      out += "  " + e.code + ": " + e.text + "\n";
  return out;
}

}  // namespace arnav::host
