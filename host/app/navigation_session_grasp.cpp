// NavigationSession: the tracked grasper (tools.grasper) coupled to the tissue model
// (docs/overlay.md, "Grasper"; the coupling itself: host/app/grasp_coupling.hpp).
#include <cstdio>
#include <cstdlib>

#include "host/app/navigation_session.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host {

void NavigationSession::grasp_request(std::int64_t now_us) {
  const GrasperRole& g = *config_.grasper;
  if (g.grasp_always) {
    grasp_cmd_.requested = true;
    grasp_cmd_.why_not.clear();
  } else {
    const InputBinding& b = *g.grasp_input;
    const HeldState h = inputs_.held(b.input, b.state_stale_after_ms, now_us);
    grasp_cmd_.requested = h == HeldState::kHeld;
    grasp_cmd_.why_not = h == HeldState::kReleased ? "input '" + b.input + "' released"
                         : h == HeldState::kHeld   ? std::string()
                                                   : "input '" + b.input + "' stale";
  }
  model_->set_grasper(grasp_cmd_);
  drain_grasp();  // what the model thread did with the previous ones (sessions without a camera too)
}

void NavigationSession::grasper_pose(const tool_pose_t& msg, std::int64_t now_us) {
  // An invalid pose changes nothing: the last valid one ages, and past stale_after_ms the
  // model releases the grasp.
  if (msg.status == tool_pose_t::STATUS_VALID && X_RefModel_) {
    std::optional<Eigen::Isometry3d> X_RefTool;
    if (msg.frame_parent == "Ref") {
      X_RefTool = get_pose(msg);
    } else if (auto it = poses_.find(config_.reference->name); it != poses_.end()) {
      // The reference in the same parent frame that is fresh now (arrived within its own
      // stale_after_ms, the overlay's rule), nearest in device time. A camera-measured
      // reference arrives after the camera's latency (~0.1-0.2 s on the bench), later than
      // the tracker's grasper poses: the newest fresh one is used, never a stale one.
      const PoseSample* best = nullptr;
      const auto limit_us = static_cast<std::int64_t>(config_.reference->stale_after_ms * 1000.0);
      for (const auto& r : it->second.recent) {
        if (r.msg.status != tool_pose_t::STATUS_VALID || r.msg.frame_parent != msg.frame_parent || r.arrival_us > now_us ||
            now_us - r.arrival_us > limit_us)
          continue;
        if (!best || std::llabs(r.msg.receive_time_mono_us - msg.receive_time_mono_us) <
                         std::llabs(best->msg.receive_time_mono_us - msg.receive_time_mono_us))
          best = &r;
      }
      if (best) X_RefTool = get_pose(best->msg).inverse() * get_pose(msg);
    }
    if (X_RefTool) {
      grasp_cmd_.X_ModelTool = X_RefModel_->inverse() * *X_RefTool;
      grasp_cmd_.pose_time_us = now_us;
      grasp_cmd_.device_time_us = msg.receive_time_mono_us;
    }
  }
  grasp_request(now_us);
}

void NavigationSession::drain_grasp() {
  const GraspStatus s = model_->grasp_status();
  for (; grasp_messages_seen_ < s.messages.size(); ++grasp_messages_seen_) say(s.messages[grasp_messages_seen_]);
}

void NavigationSession::grasp_frame(std::string& flags, std::vector<std::string>& banners) {
  std::lock_guard lock(mutex_);
  drain_grasp();
  const GraspStatus s = model_->grasp_status();
  const GrasperRole& g = *config_.grasper;
  // Before a live registration the grasper has no pose in Model: the frame says
  // `unregistered` and the registration banner why; the grasper is not stale for that.
  if (s.stale && (s.stale_releases > 0 || (grasp_cmd_.requested && X_RefModel_))) {
    // Never a silently frozen grasp: the organ is released and the banner says why.
    flags += (flags.empty() ? "" : "|") + std::string("grasper_stale");
    ++grasper_stale_frames_;
    char text[200];
    if (s.stale_releases > 0)
      std::snprintf(text, sizeof text, "GRASPER STALE: '%s' - tissue released (%lld stale release(s))", g.name.c_str(),
                    static_cast<long long>(s.stale_releases));
    else
      std::snprintf(text, sizeof text, "GRASPER STALE: '%s' - no fresh pose in Model, not grasping", g.name.c_str());
    banners.emplace_back(text);
  } else if (s.grasping) {
    flags += (flags.empty() ? "" : "|") + std::string("grasping");
  }
}

nlohmann::json NavigationSession::grasp_summary() {
  drain_grasp();
  const GraspStatus s = model_->grasp_status();
  const GrasperRole& g = *config_.grasper;
  return {{"name", g.name},
          {"grasp", g.grasp_always ? std::string("always") : "input " + g.grasp_input->input},
          {"radius_mm", g.radius_mm},
          {"grasps", s.grasps},
          {"releases", s.releases},
          {"stale_releases", s.stale_releases},
          {"refused", s.refused},
          {"steps_grasping", s.steps_grasping},
          {"grasping_at_exit", s.grasping},
          {"attached_vertices", s.attached_vertices},
          {"max_tip_travel_mm", s.max_tip_travel_mm},
          {"frames_stale_banner", grasper_stale_frames_}};
}

std::optional<GraspStatus> NavigationSession::grasp_status() const {
  if (!model_ || !model_->has_grasper()) return std::nullopt;
  return model_->grasp_status();
}

}  // namespace arnav::host
