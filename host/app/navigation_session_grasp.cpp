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
  drain_grasp();  // what the model thread did with the previous ones (sessions without a camera too)
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
    add_flag(flags, "grasper_stale");
    ++grasper_stale_frames_;
    char text[200];
    if (s.stale_releases > 0)
      std::snprintf(text, sizeof text, "GRASPER STALE: '%s' - tissue released (%lld stale release(s))", g.name.c_str(),
                    static_cast<long long>(s.stale_releases));
    else
      std::snprintf(text, sizeof text, "GRASPER STALE: '%s' - no fresh pose in Model, not grasping", g.name.c_str());
    banners.emplace_back(text);
  } else if (s.grasping) {
    add_flag(flags, "grasping");
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
