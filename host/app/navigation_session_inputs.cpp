// NavigationSession: the scalpel's and the grasper's poses on their way to the tissue model
// (docs/overlay.md, "Model clock"). Each pose of those tools is brought into Model at the
// device time the tracker measured it, through the reference measured nearest to that time,
// and handed to the model (ModelRunner::push_blade / push_grasp) with the cut pedal's level
// at that time. A pose in a frame other than Ref waits until a reference sample measured at
// or after its time has arrived (a camera-measured reference comes after the camera's
// latency, later than the tracker's poses), or until it has waited model.input_wait_ms; the
// poses go on in the order they were measured. So what the model is given does not depend on
// which thread ran first or how busy the machine was.
#include <algorithm>
#include <cstdlib>

#include "host/app/navigation_session.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host {

void NavigationSession::queue_model_pose(const tool_pose_t& msg, std::int64_t now_us) {
  // Every pose goes through the queue: the scalpel's and the grasper's to the model, the
  // others' device times tell the model's clock how far the tracker has got (in order, so a
  // reference measured later does not run ahead of the tool poses still waiting for it).
  if (!model_->has_inputs()) return;
  model_poses_.push_back({msg, now_us});
  resolve_model_poses(now_us);
}

void NavigationSession::resolve_model_poses(std::int64_t now_us) {
  while (!model_poses_.empty()) {
    const PoseSample& p = model_poses_.front();
    bool decided = false;
    const std::optional<Eigen::Isometry3d> X_RefTool = X_RefTool_at(p, now_us, decided);
    if (!decided) return;  // waits for the reference measured at its time
    if (is_blade_tool(p.msg))
      hand_blade(p.msg, X_RefTool, now_us);
    else if (is_grasper_tool(p.msg))
      hand_grasp(p.msg, X_RefTool, now_us);
    else
      model_->tracker_at(p.msg.receive_time_mono_us, now_us);
    model_poses_.pop_front();
  }
}

bool NavigationSession::is_blade_tool(const tool_pose_t& msg) const {
  return config_.scalpel && model_->cutting() && msg.tool_name == config_.scalpel->name;
}

bool NavigationSession::is_grasper_tool(const tool_pose_t& msg) const { return config_.grasper && msg.tool_name == config_.grasper->name; }

std::optional<Eigen::Isometry3d> NavigationSession::X_RefTool_at(const PoseSample& p, std::int64_t now_us, bool& decided) {
  decided = true;
  if (!is_blade_tool(p.msg) && !is_grasper_tool(p.msg)) return std::nullopt;  // another tool: only its time counts
  if (p.msg.status != tool_pose_t::STATUS_VALID || !X_RefModel_) return std::nullopt;
  if (p.msg.frame_parent == "Ref") return get_pose(p.msg);
  if (!config_.reference) return std::nullopt;  // no reference comes to bring it into Ref
  const auto it = poses_.find(config_.reference->name);
  const std::int64_t t = p.msg.receive_time_mono_us;
  const PoseSample* best = nullptr;
  bool measured_after = false;  // a reference sample measured at or after t has arrived
  if (it != poses_.end()) {
    for (const auto& r : it->second.recent) {
      measured_after = measured_after || r.msg.receive_time_mono_us >= t;
      if (r.msg.status != tool_pose_t::STATUS_VALID || r.msg.frame_parent != p.msg.frame_parent) continue;
      if (!best || std::llabs(r.msg.receive_time_mono_us - t) < std::llabs(best->msg.receive_time_mono_us - t)) best = &r;
    }
  }
  const bool waited_out = static_cast<double>(now_us - p.arrival_us) > config_.model.input_wait_ms * 1e3;
  if (!measured_after && !waited_out) {
    decided = false;
    return std::nullopt;
  }
  // The reference measured nearest to the tool's measurement, no farther from it than the
  // longer of its stale_after_ms and the model's input wait (a camera-measured reference
  // comes at the camera's rate, with gaps when frames are late: the bench's synthetic camera
  // on a busy machine made 7-11 frames a second where 15 were due, and a 150 ms bound left
  // the grasper's poses without a reference for 250 ms: the grasp was released as stale).
  if (!best) return std::nullopt;
  const double limit_us = std::max(config_.reference->stale_after_ms, config_.model.input_wait_ms) * 1e3;
  if (static_cast<double>(std::llabs(best->msg.receive_time_mono_us - t)) > limit_us) return std::nullopt;
  return get_pose(best->msg).inverse() * get_pose(p.msg);
}

bool NavigationSession::cut_pedal_at(std::int64_t device_time_us, std::int64_t now_us) const {
  if (config_.cutting.mode == "always") return true;
  if (config_.cutting.mode != "input") return false;
  const InputBinding& b = *config_.inputs.cut_enable;
  const HeldState h = inputs_.held(b.input, b.state_stale_after_ms, now_us);
  if (h == HeldState::kStale || h == HeldState::kNeverSeen) return false;  // disarmed (cutting_armed says so on the frame)
  return inputs_.pressed_at(b.input, device_time_us);
}

void NavigationSession::hand_blade(const tool_pose_t& msg, const std::optional<Eigen::Isometry3d>& X_RefTool, std::int64_t now_us) {
  BladeSample s;
  s.device_time_us = msg.receive_time_mono_us;
  if (X_RefTool) {
    const Eigen::Isometry3d X_ModelTool = X_RefModel_->inverse() * *X_RefTool;
    s.blade_Model_mm = std::array<Eigen::Vector3d, 2>{X_ModelTool * config_.scalpel->tip_Tool_mm, X_ModelTool * config_.scalpel->heel_Tool_mm};
  }
  s.cutting = s.blade_Model_mm && cut_pedal_at(s.device_time_us, now_us);
  if (!config_.camera && s.cutting) ++cutting_frames_;  // with a camera, counted per displayed frame
  model_->push_blade(s, now_us);
}

void NavigationSession::hand_grasp(const tool_pose_t& msg, const std::optional<Eigen::Isometry3d>& X_RefTool, std::int64_t now_us) {
  // An invalid pose changes nothing: the last valid one ages, and past stale_after_ms (on the
  // device clock, at the model's step) the model releases the grasp.
  if (X_RefTool) {
    grasp_cmd_.X_ModelTool = X_RefModel_->inverse() * *X_RefTool;
    grasp_cmd_.pose_time_us = msg.receive_time_mono_us;
    grasp_cmd_.device_time_us = msg.receive_time_mono_us;
  }
  grasp_request(now_us);
  model_->push_grasp(GraspSample{msg.receive_time_mono_us, grasp_cmd_}, now_us);
}

}  // namespace arnav::host
