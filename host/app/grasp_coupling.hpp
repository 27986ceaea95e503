#pragma once
// A tracked grasper coupled to the session's tissue model (docs/overlay.md, "Grasper"):
// while the grasp is on (its input held, or always), the organ surface vertices within
// radius_mm of the grasper tip at grasp start (Model, through the registration) are held
// by springs (the tissue model's attachments, as host/cut's push) whose targets follow the
// tool's rigid motion since grasp start: target_i = X_ModelTool(now) * X_ModelTool(start)^-1
// * p_i(start). A grasp starts only when the tip is within radius_mm of the surface (some
// surface vertex that close). Releasing the input, or a grasper pose older than its
// stale_after_ms (tracking lost, or no pose at all), removes the springs: the organ is never
// left pinned to a stale pose; stale releases are counted and bannered.
// Runs on the model thread, before each step (ModelRunner); the session hands it the
// newest grasper pose in Model and whether the grasp is requested (GraspCommand).
#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "host/app/session_config.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct GraspCommand {
  std::optional<Eigen::Isometry3d> X_ModelTool;  // newest valid grasper pose in Model (nullopt: none)
  std::int64_t pose_time_us = -1;                // when it arrived (session clock)
  std::int64_t device_time_us = -1;              // when the tracker measured it (the appliance's clock: tool_pose_t.receive_time_mono_us)
  bool requested = false;                        // input held with a fresh state (always mode: true)
  std::string why_not;                           // why not requested (input released, input stale), for the banner
};

struct GraspStatus {
  bool grasping = false;
  int attached_vertices = 0;
  double tip_travel_mm = 0.0;            // tip displacement since grasp start (while grasping)
  bool stale = false;                    // the grasper pose is older than its limit now
  std::int64_t grasps = 0;               // grasps started
  std::int64_t releases = 0;             // released by the input (or the session)
  std::int64_t stale_releases = 0;       // released because the grasper pose went stale
  std::int64_t refused = 0;              // grasp requested with the tip farther than radius_mm from the surface (episodes)
  std::int64_t steps_grasping = 0;       // model steps with the grasp on
  double max_tip_travel_mm = 0.0;
  std::vector<std::string> messages;     // grasp / release / stale events, in order
};

class GraspCoupling {
 public:
  // `scene` must outlive this (its organ surface and volume mesh pick the grasped points).
  GraspCoupling(const GrasperRole& role, const Scene& scene);
  // Before a model step at now_us (session clock): grasps, moves the targets or releases.
  void apply(TissueModel& model, const GraspCommand& cmd, std::int64_t now_us);
  // Releases a grasp held now (the session stops), counted as a release.
  void release(TissueModel& model, const std::string& why);
  const GraspStatus& status() const { return status_; }
  // Surface vertices (indices into the scene's organ surface) held now.
  const std::vector<int>& grasped_surface_vertices() const { return grasped_; }

 private:
  GrasperRole role_;
  const Scene& scene_;
  GraspStatus status_;
  std::vector<int> grasped_;                  // organ surface vertex ids
  std::vector<Eigen::Vector3d> start_Model_mm;  // their positions at grasp start
  std::vector<AttachmentId> ids_;
  Eigen::Isometry3d X_ModelToolStart_ = Eigen::Isometry3d::Identity();
  bool refused_episode_ = false;              // a refusal counted for the current request
};

}  // namespace arnav::host
