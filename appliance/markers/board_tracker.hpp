#pragma once
// Follows one board over frames: keeps the last accepted pose as the prior for the
// planar-ambiguity choice (only while it is recent), counts flips, and optionally smooths.
// Smoothing is an exponential filter (translation lerp, rotation slerp, weight alpha on the
// new pose); under steady motion it lags by (1 - alpha) / alpha frame intervals, which is
// reported as added_latency_s. It restarts after a gap or a jump so it never drags a pose
// across a re-acquisition.
#include <Eigen/Geometry>

#include <cstdint>
#include <optional>

#include "appliance/markers/board_pose.hpp"

namespace arnav::markers {

struct TrackerSettings {
  double prior_max_age_s = 0.5;   // older priors are not used for disambiguation
  double smoothing_alpha = 1.0;   // 1: no smoothing; (0, 1): weight of the new pose
  double reset_jump_mm = 20.0;    // smoothing restarts on a larger jump...
  double reset_jump_deg = 15.0;   // ...or rotation
};

void validate(const TrackerSettings& settings);

struct TrackedPose {
  PoseEstimate estimate;          // X_CamBoard smoothed when smoothing is on
  double added_latency_s = 0.0;   // lag of the smoother at the current frame interval
};

class BoardTracker {
 public:
  BoardTracker(BoardPoseEstimator estimator, TrackerSettings settings);

  // time_us: capture time of the frame (monotonic). reason is set when there is no pose.
  std::optional<TrackedPose> update(const std::vector<TagDetection>& detections, std::int64_t time_us,
                                    std::string* reason = nullptr);
  const BoardPoseEstimator& estimator() const { return estimator_; }
  std::int64_t flips() const { return flips_; }
  std::int64_t ambiguous_frames() const { return ambiguous_; }

 private:
  BoardPoseEstimator estimator_;
  TrackerSettings settings_;
  std::optional<Eigen::Isometry3d> prior_;
  std::optional<Eigen::Isometry3d> smoothed_;
  std::int64_t prior_time_us_ = 0;
  double frame_interval_s_ = 0.0;
  std::int64_t flips_ = 0;
  std::int64_t ambiguous_ = 0;
};

}  // namespace arnav::markers
