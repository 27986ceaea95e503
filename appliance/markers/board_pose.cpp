#include "appliance/markers/board_pose.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <stdexcept>

namespace arnav::markers {
namespace {

Eigen::Isometry3d to_isometry(const cv::Mat& rvec, const cv::Mat& tvec) {
  cv::Matx33d R;
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d Re;
  cv::cv2eigen(cv::Mat(R), Re);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Re;
  X.translation() = Eigen::Vector3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  return X;
}

void to_rvec_tvec(const Eigen::Isometry3d& X, cv::Mat& rvec, cv::Mat& tvec) {
  cv::Mat R;
  cv::eigen2cv(Eigen::Matrix3d(X.linear()), R);
  cv::Rodrigues(R, rvec);
  tvec = (cv::Mat_<double>(3, 1) << X.translation().x(), X.translation().y(), X.translation().z());
}

// Quality in 0..1: falls with the reprojection error (0.5 at 1 px), halves when the
// pose is ambiguous, and grows with the share of the board's corners that were seen.
double quality(double rms_px, bool ambiguous, int corners_used, int corners_total) {
  const double q_err = 1.0 / (1.0 + rms_px * rms_px);
  const double q_amb = ambiguous ? 0.5 : 1.0;
  const double coverage = static_cast<double>(corners_used) / std::max(1, corners_total);
  return q_err * q_amb * (0.5 + 0.5 * coverage);
}

}  // namespace

double rotation_angle_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

BoardPoseEstimator::BoardPoseEstimator(TagBoard board, CameraModel camera, PoseSettings settings)
    : board_(std::move(board)), camera_(std::move(camera)), settings_(settings) {
  validate(board_);  // planar: the joint IPPE solve needs it
  validate(camera_);
  if (!(settings_.ambiguity_ratio >= 1.0)) throw std::invalid_argument("pose: ambiguity_ratio must be >= 1");
  if (!(settings_.max_reprojection_px > 0.0)) throw std::invalid_argument("pose: max_reprojection_px must be > 0");
}

PoseOutcome BoardPoseEstimator::estimate(const std::vector<TagDetection>& detections,
                                         const std::optional<Eigen::Isometry3d>& X_CamBoard_prior) const {
  const auto t_start = std::chrono::steady_clock::now();
  std::map<int, const BoardTag*> by_id;
  for (const auto& t : board_.tags) by_id[t.id] = &t;

  std::vector<cv::Point3d> object;     // board frame, mm
  std::vector<cv::Point2d> image_px;   // distorted, as detected
  PoseEstimate est;
  for (const auto& det : detections) {
    auto it = by_id.find(det.id);
    if (it == by_id.end()) continue;
    if (std::find(est.tag_ids.begin(), est.tag_ids.end(), det.id) != est.tag_ids.end()) continue;  // duplicate id
    const auto corners = tag_corners_in_board(*it->second);
    for (size_t k = 0; k < 4; ++k) {
      object.emplace_back(corners[k].x(), corners[k].y(), corners[k].z());
      image_px.push_back(det.corners_px[k]);
    }
    est.tag_ids.push_back(det.id);
  }
  PoseOutcome out;
  if (est.tag_ids.empty()) {
    out.reason = "no tag of board '" + board_.name + "' detected";
    return out;
  }
  est.tags_used = static_cast<int>(est.tag_ids.size());
  est.corners_used = static_cast<int>(object.size());

  // Undistorted normalised corners: the solve then runs on an ideal pinhole (K = I).
  const std::vector<cv::Point2d> normalised = camera_.normalised(image_px);
  const cv::Matx33d I = cv::Matx33d::eye();
  std::vector<cv::Mat> rvecs, tvecs;
  if (est.tags_used == 1) {
    // IPPE_SQUARE wants the square's corners in its own order, in the tag frame:
    // (-h, h), (h, h), (h, -h), (-h, -h), which are our corners 3, 2, 1, 0.
    const BoardTag& tag = *by_id.at(est.tag_ids.front());
    const double h = 0.5 * tag.size_mm;
    const std::vector<cv::Point3d> square = {{-h, h, 0}, {h, h, 0}, {h, -h, 0}, {-h, -h, 0}};
    const std::vector<cv::Point2d> img = {normalised[3], normalised[2], normalised[1], normalised[0]};
    cv::solvePnPGeneric(square, img, I, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE_SQUARE);
    for (size_t s = 0; s < rvecs.size(); ++s) {
      const Eigen::Isometry3d X_CamBoard = to_isometry(rvecs[s], tvecs[s]) * tag.X_BoardTag.inverse();
      to_rvec_tvec(X_CamBoard, rvecs[s], tvecs[s]);
    }
  } else {
    cv::solvePnPGeneric(object, normalised, I, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE);
  }
  if (rvecs.empty()) {
    out.reason = "pose solve failed for board '" + board_.name + "' (degenerate corners)";
    return out;
  }

  struct Candidate {
    Eigen::Isometry3d X;
    double rms_px;
    double initial_rms_px;
  };
  // RMS reprojection error in distorted pixels; negative when a corner is behind the camera.
  auto rms_of = [&](const Eigen::Isometry3d& X) {
    std::vector<Eigen::Vector3d> p_Cam;
    for (const auto& p : object) {
      p_Cam.push_back(X * Eigen::Vector3d(p.x, p.y, p.z));
      if (p_Cam.back().z() <= 0.0) return -1.0;
    }
    const auto proj = camera_.project(p_Cam);
    double sum = 0.0;
    for (size_t k = 0; k < proj.size(); ++k) {
      const cv::Point2d d = proj[k] - image_px[k];
      sum += d.dot(d);
    }
    return std::sqrt(sum / static_cast<double>(proj.size()));
  };
  std::vector<Candidate> candidates;
  for (size_t s = 0; s < rvecs.size(); ++s) {
    cv::Mat r = rvecs[s].clone(), t = tvecs[s].clone();
    const double initial = rms_of(to_isometry(r, t));
    if (est.tags_used > 1) {
      cv::solvePnPRefineLM(object, normalised, I, cv::noArray(), r, t);
    }
    const Eigen::Isometry3d X = to_isometry(r, t);
    const double rms = rms_of(X);
    if (rms < 0.0) continue;
    candidates.push_back({X, rms, initial});
  }
  if (candidates.empty()) {
    out.reason = "pose solve for board '" + board_.name + "' put it behind the camera";
    return out;
  }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.rms_px < b.rms_px; });

  size_t chosen = 0;
  if (candidates.size() > 1) {
    const double best = std::max(candidates[0].rms_px, 0.02);  // floor: noise-free corners
    const double apart_deg = rotation_angle_between(candidates[0].X, candidates[1].X) * 180.0 / M_PI;
    est.ambiguous = candidates[1].rms_px < settings_.ambiguity_ratio * best && apart_deg > settings_.ambiguity_min_angle_deg;
    est.alt_reprojection_rms_px = candidates[1].rms_px;
    if (est.ambiguous && X_CamBoard_prior) {
      const double a0 = rotation_angle_between(*X_CamBoard_prior, candidates[0].X);
      const double a1 = rotation_angle_between(*X_CamBoard_prior, candidates[1].X);
      if (a1 < a0) chosen = 1;
    }
  }
  est.X_CamBoard = candidates[chosen].X;
  est.reprojection_rms_px = candidates[chosen].rms_px;
  est.summary.method = est.tags_used == 1 ? "IPPE_SQUARE" : "IPPE+LM";
  est.summary.initial_rms_px = candidates[chosen].initial_rms_px;
  est.summary.final_rms_px = candidates[chosen].rms_px;
  est.summary.wall_time_us =
      std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t_start).count();
  est.flipped = chosen != 0;
  if (X_CamBoard_prior) {
    // The board normal turning by more than 30 deg between frames is a flip, not motion.
    const Eigen::Vector3d n_prev = X_CamBoard_prior->linear().col(2);
    const Eigen::Vector3d n_now = est.X_CamBoard.linear().col(2);
    if (std::acos(std::clamp(n_prev.dot(n_now), -1.0, 1.0)) > 30.0 * M_PI / 180.0) est.flipped = true;
  }
  est.quality = quality(est.reprojection_rms_px, est.ambiguous, est.corners_used,
                        4 * static_cast<int>(board_.tags.size()));
  if (est.reprojection_rms_px > settings_.max_reprojection_px) {
    out.reason = "board '" + board_.name + "': reprojection error " + std::to_string(est.reprojection_rms_px) +
                 " px exceeds " + std::to_string(settings_.max_reprojection_px) + " px";
    return out;
  }
  out.pose = est;
  return out;
}

}  // namespace arnav::markers
