#include "appliance/markers/board_tracker.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace arnav::markers {

void validate(const TrackerSettings& s) {
  if (!(s.smoothing_alpha > 0.0 && s.smoothing_alpha <= 1.0)) {
    throw std::invalid_argument("tracker: smoothing_alpha " + std::to_string(s.smoothing_alpha) + " outside (0, 1]");
  }
  if (!(s.prior_max_age_s >= 0.0)) throw std::invalid_argument("tracker: prior_max_age_s must be >= 0");
  if (!(s.reset_jump_mm > 0.0) || !(s.reset_jump_deg > 0.0)) {
    throw std::invalid_argument("tracker: reset_jump_mm and reset_jump_deg must be > 0");
  }
}

BoardTracker::BoardTracker(BoardPoseEstimator estimator, TrackerSettings settings)
    : estimator_(std::move(estimator)), settings_(settings) {
  validate(settings_);
}

std::optional<TrackedPose> BoardTracker::update(const std::vector<TagDetection>& detections, std::int64_t time_us,
                                                std::string* reason) {
  const double age_s = 1e-6 * static_cast<double>(time_us - prior_time_us_);
  const bool prior_fresh = prior_ && age_s >= 0.0 && age_s <= settings_.prior_max_age_s;
  PoseOutcome outcome = estimator_.estimate(detections, prior_fresh ? prior_ : std::nullopt);
  if (!outcome.pose) {
    if (reason != nullptr) *reason = outcome.reason;
    return std::nullopt;
  }
  PoseEstimate est = *outcome.pose;
  if (est.flipped) ++flips_;
  if (est.ambiguous) ++ambiguous_;
  if (prior_fresh && age_s > 0.0) {
    // Running estimate of the frame interval for the latency report.
    frame_interval_s_ = frame_interval_s_ == 0.0 ? age_s : 0.9 * frame_interval_s_ + 0.1 * age_s;
  }
  prior_ = est.X_CamBoard;

  TrackedPose tracked;
  const double alpha = settings_.smoothing_alpha;
  if (alpha < 1.0) {
    bool restart = !smoothed_ || !prior_fresh;
    if (!restart) {
      const double jump_mm = (smoothed_->translation() - est.X_CamBoard.translation()).norm();
      const double jump_deg = rotation_angle_between(*smoothed_, est.X_CamBoard) * 180.0 / std::numbers::pi;
      restart = jump_mm > settings_.reset_jump_mm || jump_deg > settings_.reset_jump_deg;
    }
    if (restart) {
      smoothed_ = est.X_CamBoard;
    } else {
      const Eigen::Quaterniond q_old(smoothed_->linear()), q_new(est.X_CamBoard.linear());
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.linear() = q_old.slerp(alpha, q_new).toRotationMatrix();
      X.translation() = (1.0 - alpha) * smoothed_->translation() + alpha * est.X_CamBoard.translation();
      smoothed_ = X;
    }
    est.X_CamBoard = *smoothed_;
    tracked.added_latency_s = (1.0 - alpha) / alpha * frame_interval_s_;
  }
  prior_time_us_ = time_us;
  tracked.estimate = est;
  return tracked;
}

}  // namespace arnav::markers
