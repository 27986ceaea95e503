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
// The model is a TissueModel, or a host/cut CutSession on a cutting scene: the grasped
// points are the scene's organ surface vertices embedded in the scene's volume mesh (tet
// vertex ids and weights), which stay valid through cuts (a cut only appends vertices; the
// cut session re-adds its attachments to every rebuilt model and drops released ones).
#include <Eigen/Geometry>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "host/app/session_config.hpp"
#include "host/cut/cut_session.hpp"
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

// What the grasper holds: the volume's vertex positions (the scene mesh's vertex ids first)
// and the model's attachments.
class GraspBody {
 public:
  virtual ~GraspBody() = default;
  virtual Eigen::Matrix3Xd positions_World_mm() const = 0;
  virtual int add_attachment(const AttachmentSpec& spec) = 0;
  virtual void set_attachment_target(int id, const Eigen::Vector3d& target_World_mm) = 0;
  virtual void remove_attachment(int id) = 0;
};

class TissueModelBody final : public GraspBody {
 public:
  explicit TissueModelBody(TissueModel& m) : m_(m) {}
  Eigen::Matrix3Xd positions_World_mm() const override { return m_.positions_World_mm(); }
  int add_attachment(const AttachmentSpec& spec) override { return m_.add_attachment(spec); }
  void set_attachment_target(int id, const Eigen::Vector3d& t) override { m_.set_attachment_target(id, t); }
  void remove_attachment(int id) override { m_.remove_attachment(id); }

 private:
  TissueModel& m_;
};

// A cutting model: attachments kept through cuts and model rebuilds (host/cut).
class CutSessionBody final : public GraspBody {
 public:
  explicit CutSessionBody(cut::CutSession& s) : s_(s) {}
  Eigen::Matrix3Xd positions_World_mm() const override { return s_.positions_World_mm(); }
  int add_attachment(const AttachmentSpec& spec) override { return s_.add_attachment(spec); }
  void set_attachment_target(int id, const Eigen::Vector3d& t) override { s_.set_attachment_target(id, t); }
  void remove_attachment(int id) override { s_.remove_attachment(id); }

 private:
  cut::CutSession& s_;
};

class GraspCoupling {
 public:
  // `scene` must outlive this (its organ surface and volume mesh pick the grasped points).
  GraspCoupling(const GrasperRole& role, const Scene& scene);
  // Before a model step at now_us (session clock): grasps, moves the targets or releases.
  void apply(GraspBody& model, const GraspCommand& cmd, std::int64_t now_us);
  void apply(TissueModel& model, const GraspCommand& cmd, std::int64_t now_us) {
    TissueModelBody body(model);
    apply(body, cmd, now_us);
  }
  // Releases a grasp held now (the session stops), counted as a release.
  void release(GraspBody& model, const std::string& why);
  void release(TissueModel& model, const std::string& why) {
    TissueModelBody body(model);
    release(body, why);
  }
  const GraspStatus& status() const { return status_; }
  // Surface vertices (indices into the scene's organ surface) held now.
  const std::vector<int>& grasped_surface_vertices() const { return grasped_; }

 private:
  GrasperRole role_;
  const Scene& scene_;
  GraspStatus status_;
  std::vector<int> grasped_;                  // organ surface vertex ids
  std::vector<Eigen::Vector3d> start_Model_mm;  // their positions at grasp start
  std::vector<int> ids_;
  Eigen::Isometry3d X_ModelToolStart_ = Eigen::Isometry3d::Identity();
  bool refused_episode_ = false;              // a refusal counted for the current request
};

}  // namespace arnav::host
