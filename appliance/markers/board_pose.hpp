#pragma once
// Pose of a tag board from AprilTag detections: corners undistorted with the calibrated
// intrinsics, then one joint solve over all visible corners of the board (IPPE for a
// planar target, refined by Levenberg-Marquardt). The planar ambiguity (two poses that
// explain a small or far tag almost equally well, mirrored about the view ray) is handled
// by keeping both IPPE solutions: when their errors are close the pose is marked
// ambiguous and the one closer to the previous pose is taken (temporal consistency); a
// choice against the lower error, or a jump of the board normal, is reported as a flip.
// Frames: X_CamBoard (Cam: OpenCV camera frame; Board: tag_board.hpp). Units: mm, px.
#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"
#include "appliance/markers/tag_detector.hpp"

namespace arnav::markers {

struct PoseSettings {
  // Both solutions' RMS errors within this factor, and the two poses more than
  // ambiguity_min_angle_deg apart (near a frontal view they coincide): ambiguous.
  double ambiguity_ratio = 1.5;
  double ambiguity_min_angle_deg = 3.0;
  // Poses whose RMS reprojection error exceeds this are rejected (a wrong or bent board).
  double max_reprojection_px = 3.0;
};

// Summary of the solve (the conventions' solver summary): closed-form IPPE, then OpenCV's
// Levenberg-Marquardt refinement (its own criterion: 20 iterations or a tiny step) for
// boards of several tags. RMS in distorted pixels over the corners used.
struct SolveSummary {
  std::string method;            // "IPPE_SQUARE" (one tag) or "IPPE+LM" (several)
  double initial_rms_px = 0.0;   // chosen solution before refinement
  double final_rms_px = 0.0;     // after refinement (= reprojection_rms_px)
  double wall_time_us = 0.0;     // undistortion + solve + scoring
};

struct PoseEstimate {
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  double reprojection_rms_px = 0.0;       // chosen solution, distorted pixels
  double alt_reprojection_rms_px = 0.0;   // the other planar solution
  double quality = 0.0;                   // 0..1, see quality() in board_pose.cpp
  int tags_used = 0;
  int corners_used = 0;
  bool ambiguous = false;
  bool flipped = false;                   // took the higher-error solution, or the normal jumped
  std::vector<int> tag_ids;
  SolveSummary summary;
};

struct PoseOutcome {
  std::optional<PoseEstimate> pose;
  std::string reason;  // why there is no pose (board not seen, error too large)
};

class BoardPoseEstimator {
 public:
  // Throws std::invalid_argument for an invalid board, camera or settings.
  BoardPoseEstimator(TagBoard board, CameraModel camera, PoseSettings settings = {});

  const TagBoard& board() const { return board_; }
  // detections: all tags of the frame (tags of other boards are ignored).
  // X_CamBoard_prior: the previous accepted pose and its age, for disambiguation.
  PoseOutcome estimate(const std::vector<TagDetection>& detections,
                       const std::optional<Eigen::Isometry3d>& X_CamBoard_prior = std::nullopt) const;

 private:
  TagBoard board_;
  CameraModel camera_;
  PoseSettings settings_;
};

// Angle (rad) of the relative rotation between two poses.
double rotation_angle_between(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);

}  // namespace arnav::markers
