#include "appliance/app/publisher.hpp"

#include <cstdio>

#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::app {

namespace {
// Writes the pose in the publisher's reference frame when it can be expressed there.
void write_pose(tool_pose_t& msg, const Eigen::Isometry3d& X_NdiTool, const frames::ReferenceFrames* reference_frames,
                const std::string& tool_name, std::int64_t time_us) {
  if (reference_frames && !(reference_frames->reference() == frames::Reference::Ref &&
                            tool_name == reference_frames->reference_tool())) {
    const frames::Converted c = reference_frames->ndi_pose(X_NdiTool, time_us);
    if (c.X_ParentChild) {
      set_pose(msg, *c.X_ParentChild);
      msg.frame_parent = c.frame_parent;
      return;
    }
  }
  set_pose(msg, X_NdiTool);
  msg.frame_parent = "Ndi";
}
}  // namespace

void Publisher::set_reference_frames(std::shared_ptr<const frames::ReferenceFrames> reference_frames) {
  frames_ = std::move(reference_frames);
}

Publisher::Publisher(lcm::LCM& lcm, const std::vector<ndi::ToolConfig>& tools, double device_rate_hz)
    : lcm_(lcm), device_rate_hz_(device_rate_hz), health_channel_(channels::health("ndi")) {
  for (const auto& t : tools) {
    channels_.push_back(channels::pose(t.name));
    tool_pose_t msg{};
    msg.tool_name = t.name;
    msg.source = tool_pose_t::SOURCE_NDI;
    msg.frame_parent = "Ndi";
    msg.frame_child = "Tool";
    msg.q_ParentChild_wxyz[0] = 1.0;
    poses_.push_back(msg);
  }
}

float Publisher::publish_frame(const ndi::Session& session, const ndi::TrackingReply& reply,
                               std::int64_t receive_mono_us) {
  const std::int64_t now_mono = monotonic_us();
  const std::int64_t receive_wall_us = wall_us() - (now_mono - receive_mono_us);
  const auto& tools = session.tools();
  for (std::size_t i = 0; i < poses_.size() && i < tools.size(); ++i) {
    tool_pose_t& msg = poses_[i];
    const ndi::HandleRecord* r = reply.find(tools[i].handle);
    msg.tool_id = tools[i].handle;
    msg.rms_error_mm = 0.0f;
    msg.quality = 0.0f;
    msg.reprojection_error_px = 0.0f;
    if (!r) {
      msg.status = +tool_pose_t::STATUS_MISSING;
      msg.port_status = 0;
    } else {
      msg.port_status = static_cast<std::int32_t>(r->port_status);
      switch (r->state) {
        case ndi::HandleState::Valid:
          write_pose(msg, ndi::X_NdiTool(*r), frames_.get(), tools[i].config.name, receive_mono_us);
          msg.rms_error_mm = static_cast<float>(r->rms_error_mm);
          msg.quality = 1.0f;
          msg.status = r->out_of_volume()         ? +tool_pose_t::STATUS_OUT_OF_VOLUME
                       : r->partially_in_volume() ? +tool_pose_t::STATUS_PARTIALLY_OUT_OF_VOLUME
                                                  : +tool_pose_t::STATUS_VALID;
          break;
        case ndi::HandleState::Missing: msg.status = +tool_pose_t::STATUS_MISSING; break;
        case ndi::HandleState::Disabled:
        case ndi::HandleState::Unoccupied: msg.status = +tool_pose_t::STATUS_DISABLED; break;
      }
    }
    const std::uint32_t fn = r && r->has_status ? r->frame_number : reply.frame_number();
    msg.device_frame_number = fn;
    // BX2 carries the device's own timestamp of the frame; BX/TX only the frame counter.
    msg.device_time_us = reply.has_device_time ? reply.device_time_ns / 1000
                                               : static_cast<std::int64_t>(static_cast<double>(fn) * 1e6 / device_rate_hz_);
    msg.receive_time_mono_us = receive_mono_us;
    msg.receive_time_wall_us = receive_wall_us;
    msg.publish_time_mono_us = monotonic_us();
    msg.publish_time_wall_us = wall_us();
    ++msg.sequence;
    lcm_.publish(channels_[i], &msg);
  }
  const auto latency = static_cast<float>(monotonic_us() - receive_mono_us);
  latency_.add(latency);
  return latency;
}

device_health_t Publisher::publish_health(const ndi::Session& session, const std::string& port_label, double frame_rate_hz) {
  const auto c = session.counters();
  const LatencySummary l = latency_.take();
  device_health_t h{};
  h.device = "ndi";
  switch (session.state()) {
    case ndi::LinkState::Down: h.link_state = +device_health_t::LINK_DOWN; break;
    case ndi::LinkState::Connecting: h.link_state = +device_health_t::LINK_CONNECTING; break;
    case ndi::LinkState::Initialising: h.link_state = +device_health_t::LINK_INITIALISING; break;
    case ndi::LinkState::Tracking: h.link_state = +device_health_t::LINK_TRACKING; break;
    case ndi::LinkState::Recovering: h.link_state = +device_health_t::LINK_RECOVERING; break;
  }
  h.port = session.port_name().empty() ? port_label : session.port_name();
  h.baud = session.baud();
  h.firmware = session.firmware();
  h.serial_number = session.serial_number();
  h.frame_rate_hz = static_cast<float>(frame_rate_hz);
  h.frames_total = c.frames_total;
  h.crc_errors = c.crc_errors;
  h.timeouts = c.timeouts;
  h.resyncs = c.resyncs;
  h.garbage_bytes = c.garbage_bytes;
  h.error_replies = c.error_replies;
  h.resets = c.resets;
  h.reconnects = c.reconnects;
  h.dropped_frames = c.dropped_frames;
  h.latency_p50_us = l.p50_us;
  h.latency_p99_us = l.p99_us;
  h.latency_max_us = l.max_us;
  h.publish_time_mono_us = monotonic_us();
  h.publish_time_wall_us = wall_us();
  h.detail = std::string(ndi::to_string(session.state())) + (session.using_bx() ? ", BX" : ", TX") +
             (session.detail().empty() ? "" : "; last fault: " + session.detail());
  lcm_.publish(health_channel_, &h);
  return h;
}

void Publisher::publish_event(const ndi::Event& event) {
  appliance_event_t e{};
  e.source = "ndi";
  e.severity = event.severity == ndi::Severity::Info      ? +appliance_event_t::SEVERITY_INFO
               : event.severity == ndi::Severity::Warning ? +appliance_event_t::SEVERITY_WARNING
                                                          : +appliance_event_t::SEVERITY_ERROR;
  e.code = std::string(event.code);
  e.text = event.text;
  e.time_mono_us = monotonic_us();
  e.time_wall_us = wall_us();
  e.sequence = ++event_sequence_;
  lcm_.publish(std::string(channels::kEvents), &e);
}

}  // namespace arnav::app
