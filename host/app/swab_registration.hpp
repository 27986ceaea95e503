#pragma once
// Surface swab step of a live registration (session key registration.live.swab,
// docs/overlay.md "Swab registration"): after the landmark step (or from a prior pose),
// the appliance's swab messages (arnav.point_cloud_t on ARNAV_CLOUD_<source>, the
// pointer's tip sampled while a pedal/button is held or continuously) are collected in
// Ref, and an accept press refines X_RefModel by point-to-plane ICP on the organ surface
// (host/register's icp_point_to_plane: robust, trimmed), started from the current pose.
// The refinement is kept only when it is no worse than the pose it started from: the
// trimmed surface residual must drop (by 2 %, host/register's rule for "never worse than
// rigid"), the ICP must have converged or run out of iterations (not lost its inliers), the
// change must stay within the configured bounds, and the landmarks (if any) must stay
// consistent; otherwise the starting pose is kept with the reason.
// Frames: Ref (the patient reference tool), Model (the scene frame). Units: mm, deg.
// Threads: none of its own; the session calls begin/add/try_accept under its lock and runs
// refine() (pure, no shared state) on a worker thread.
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "host/app/session_config.hpp"
#include "host/register/cloud_collector.hpp"
#include "host/register/rigid_registration.hpp"

namespace arnav::host {

// What the refinement works on: a snapshot, so it runs without any lock.
struct SwabJob {
  Eigen::Matrix3Xd points_Ref_mm;
  Eigen::Isometry3d X_RefModel_start = Eigen::Isometry3d::Identity();
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> landmarks_Model_Ref;  // model point, touched point in Ref
  double landmark_fre_mm = 0.0;  // RMS of the landmark fit at the start pose
};

struct SwabOutcome {
  bool accepted = false;
  std::string message;                 // for the console, the event log and the summary
  Eigen::Isometry3d X_RefModel = Eigen::Isometry3d::Identity();  // the pose in use afterwards
  IcpSummary icp;
  int points = 0;
  double rms_before_mm = 0.0;          // trimmed RMS distance of the swab to the organ surface at the start pose
  double rms_after_mm = 0.0;           // ... at the ICP result
  double change_deg = 0.0;             // rotation between the start and the ICP pose
  double change_at_target_mm = 0.0;    // displacement of the target (tumour centroid) between them
  double landmark_rms_after_mm = 0.0;  // landmarks under the ICP pose (0 without landmarks)
  double wall_time_s = 0.0;
};

class SwabRegistration {
 public:
  // surface: the organ's display surface in Model; target: where the change is measured.
  SwabRegistration(const SwabRegistrationSettings& settings, Eigen::Matrix3Xd surface_Model_mm, std::vector<std::array<int, 3>> tris,
                   const Eigen::Vector3d& target_Model_mm);

  const SwabRegistrationSettings& settings() const { return settings_; }
  // The step starts (the landmark step done, or the prior pose): points before are ignored.
  void begin(const Eigen::Isometry3d& X_RefModel, std::string origin,
             std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> landmarks_Model_Ref = {}, double landmark_fre_mm = 0.0);
  bool started() const { return started_; }
  bool running() const { return running_; }
  bool done() const { return done_; }

  // A message already mapped into Ref (frame_name "Ref"). Returns the points taken.
  int add(const PointCloud& cloud_Ref);
  // Messages that could not be used, with why (counted; the first of each kind is reported).
  void refuse_message(const std::string& why) { ++refused_messages_; last_refusal_ = why; }
  void ignore_message(int points) { ++ignored_messages_; ignored_points_ += points; }
  int points() const { return collector_.points(); }

  // An accept press: a job to run, or the refusal message (the cloud stays and grows).
  std::optional<SwabJob> try_accept(std::string* refusal);
  // The refinement itself (any thread).
  SwabOutcome refine(const SwabJob& job) const;
  // The outcome of the job (back under the session's lock): done when accepted, else the
  // cloud is cleared for a new swab.
  void finish(const SwabOutcome& outcome);

  std::string status() const;  // banner / footer text
  std::string origin() const { return origin_; }
  const std::optional<SwabOutcome>& last_outcome() const { return last_; }
  int attempts() const { return attempts_; }
  int refused_presses() const { return refused_presses_; }
  const PointCloudCollector& collector() const { return collector_; }
  int refused_messages() const { return refused_messages_; }
  int ignored_messages() const { return ignored_messages_; }
  long long ignored_points() const { return ignored_points_; }
  const std::string& last_refusal() const { return last_refusal_; }

 private:
  SwabRegistrationSettings settings_;
  Eigen::Matrix3Xd surface_Model_mm_;
  std::vector<std::array<int, 3>> tris_;
  Eigen::Vector3d target_Model_mm_;
  double model_extent_mm_ = 0.0;
  PointCloudCollector collector_{"Ref"};
  Eigen::Isometry3d X_RefModel_start_ = Eigen::Isometry3d::Identity();
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> landmarks_;
  double landmark_fre_mm_ = 0.0;
  std::string origin_;
  bool started_ = false, running_ = false, done_ = false;
  int attempts_ = 0, refused_presses_ = 0, refused_messages_ = 0, ignored_messages_ = 0;
  long long ignored_points_ = 0;
  std::string last_refusal_, last_press_refusal_;
  std::optional<SwabOutcome> last_;
};

}  // namespace arnav::host
