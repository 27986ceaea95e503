#pragma once
// Hand-eye calibration between the camera and the NDI tracker with a hybrid target: an
// AprilTag board rigidly fixed to an NDI tool, seen by both. Camera and tracker stay
// fixed to each other while the target is moved through N poses.
//   measured: X_NdiTool_i (tracker), X_CamBoard_i (camera, board PnP)
//   unknown:  X_CamNdi (fixed camera/tracker), X_ToolBoard (fixed on the target)
//   model:    X_CamBoard_i = X_CamNdi * X_NdiTool_i * X_ToolBoard
// AX=ZB: A_i = X_CamBoard_i, X = X_BoardTool, Z = X_CamNdi, B_i = X_NdiTool_i, solved by
//   cv::calibrateRobotWorldHandEye (Shah or Li).
// AX=XB: relative motions, solved by cv::calibrateHandEye in its eye-to-hand form
//   (gripper = Tool, base = Ndi, target = Board; Tsai, Park, Horaud, Andreff,
//   Daniilidis); X_ToolBoard is then the rotation-averaged per-pose estimate.
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "calibration/lib/solver_summary.hpp"

namespace arnav::calib {

enum class HandEyeMethod { AXXB_Tsai, AXXB_Park, AXXB_Horaud, AXXB_Andreff, AXXB_Daniilidis, AXZB_Shah, AXZB_Li };
std::string to_string(HandEyeMethod method);
// "axxb-tsai", "axxb-park", "axxb-horaud", "axxb-andreff", "axxb-daniilidis",
// "axzb-shah", "axzb-li"
HandEyeMethod parse_hand_eye_method(const std::string& name);

struct HandEyeOptions {
  HandEyeMethod method = HandEyeMethod::AXZB_Shah;
  int min_poses = 5;
  double min_rotation_spread_deg = 10.0;  // of the target poses X_NdiTool
};

struct HandEyeResult {
  Eigen::Isometry3d X_CamNdi = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d X_ToolBoard = Eigen::Isometry3d::Identity();
  // Per pose: X_CamBoard_i predicted by the model against the measured one.
  std::vector<double> translation_residual_mm;
  std::vector<double> rotation_residual_deg;
  double rms_mm = 0.0;
  double max_mm = 0.0;
  double rms_deg = 0.0;
  double rotation_spread_deg = 0.0;
  SolverSummary summary;
};

// Throws DegenerateInput (too few poses, too little rotation) or CalibError (size mismatch).
HandEyeResult calibrate_hand_eye(const std::vector<Eigen::Isometry3d>& X_NdiTool,
                                 const std::vector<Eigen::Isometry3d>& X_CamBoard,
                                 const HandEyeOptions& options = {});

// Residuals of a given solution (also used by the AR evaluation).
void hand_eye_residuals(const std::vector<Eigen::Isometry3d>& X_NdiTool,
                        const std::vector<Eigen::Isometry3d>& X_CamBoard, HandEyeResult& result);

}  // namespace arnav::calib
