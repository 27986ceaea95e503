#include "calibration/lib/hand_eye.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/pivot_calibration.hpp"

namespace arnav::calib {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

void split(const Eigen::Isometry3d& X, std::vector<cv::Mat>& R, std::vector<cv::Mat>& t) {
  cv::Mat Rm;
  cv::Mat tm;
  const Eigen::Matrix3d Re = X.linear();
  const Eigen::Vector3d te = X.translation();
  cv::eigen2cv(Re, Rm);
  cv::eigen2cv(te, tm);
  R.push_back(Rm);
  t.push_back(tm);
}

Eigen::Isometry3d join(const cv::Mat& R, const cv::Mat& t) {
  Eigen::Matrix3d Re;
  Eigen::Vector3d te;
  cv::cv2eigen(R, Re);
  cv::cv2eigen(t, te);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = mean_rotation({Re});  // re-orthonormalise
  X.translation() = te;
  return X;
}

}  // namespace

std::string to_string(HandEyeMethod m) {
  switch (m) {
    case HandEyeMethod::AXXB_Tsai: return "axxb-tsai";
    case HandEyeMethod::AXXB_Park: return "axxb-park";
    case HandEyeMethod::AXXB_Horaud: return "axxb-horaud";
    case HandEyeMethod::AXXB_Andreff: return "axxb-andreff";
    case HandEyeMethod::AXXB_Daniilidis: return "axxb-daniilidis";
    case HandEyeMethod::AXZB_Shah: return "axzb-shah";
    case HandEyeMethod::AXZB_Li: return "axzb-li";
  }
  return "unknown";
}

HandEyeMethod parse_hand_eye_method(const std::string& name) {
  for (auto m : {HandEyeMethod::AXXB_Tsai, HandEyeMethod::AXXB_Park, HandEyeMethod::AXXB_Horaud,
                 HandEyeMethod::AXXB_Andreff, HandEyeMethod::AXXB_Daniilidis, HandEyeMethod::AXZB_Shah,
                 HandEyeMethod::AXZB_Li}) {
    if (to_string(m) == name) return m;
  }
  throw CalibError("hand-eye method '" + name +
                   "' unknown (axxb-tsai, axxb-park, axxb-horaud, axxb-andreff, axxb-daniilidis, "
                   "axzb-shah, axzb-li)");
}

void hand_eye_residuals(const std::vector<Eigen::Isometry3d>& X_NdiTool,
                        const std::vector<Eigen::Isometry3d>& X_CamBoard, HandEyeResult& r) {
  r.translation_residual_mm.clear();
  r.rotation_residual_deg.clear();
  double st = 0.0;
  double sr = 0.0;
  r.max_mm = 0.0;
  for (std::size_t i = 0; i < X_NdiTool.size(); ++i) {
    const Eigen::Isometry3d pred = r.X_CamNdi * X_NdiTool[i] * r.X_ToolBoard;
    const double et = (pred.translation() - X_CamBoard[i].translation()).norm();
    const double er = Eigen::AngleAxisd(pred.linear().transpose() * X_CamBoard[i].linear()).angle() * kRadToDeg;
    r.translation_residual_mm.push_back(et);
    r.rotation_residual_deg.push_back(er);
    st += et * et;
    sr += er * er;
    r.max_mm = std::max(r.max_mm, et);
  }
  const double n = static_cast<double>(X_NdiTool.size());
  r.rms_mm = std::sqrt(st / n);
  r.rms_deg = std::sqrt(sr / n);
}

HandEyeResult calibrate_hand_eye(const std::vector<Eigen::Isometry3d>& X_NdiTool,
                                 const std::vector<Eigen::Isometry3d>& X_CamBoard,
                                 const HandEyeOptions& opt) {
  const auto start = std::chrono::steady_clock::now();
  if (X_NdiTool.size() != X_CamBoard.size()) {
    throw CalibError("hand-eye: " + std::to_string(X_NdiTool.size()) + " tracker poses but " +
                     std::to_string(X_CamBoard.size()) + " camera poses; they must be paired");
  }
  const int n = static_cast<int>(X_NdiTool.size());
  if (n < std::max(opt.min_poses, 3)) {
    throw DegenerateInput("hand-eye: " + std::to_string(n) + " pose pairs, at least " +
                          std::to_string(std::max(opt.min_poses, 3)) +
                          " needed: move the hybrid target to more positions");
  }
  HandEyeResult res;
  res.rotation_spread_deg = rotation_spread_deg(X_NdiTool);
  if (res.rotation_spread_deg < opt.min_rotation_spread_deg) {
    throw DegenerateInput("hand-eye: the target poses spread only " +
                          std::to_string(res.rotation_spread_deg) + " deg in rotation (at least " +
                          std::to_string(opt.min_rotation_spread_deg) +
                          " deg needed): tilt the hybrid target about at least two different axes");
  }
  std::vector<cv::Mat> R_a, t_a, R_b, t_b;
  const bool axzb = opt.method == HandEyeMethod::AXZB_Shah || opt.method == HandEyeMethod::AXZB_Li;
  if (axzb) {
    // OpenCV: world2cam = X_CamBoard, base2gripper = X_NdiTool (gripper = Ndi, base =
    // Tool); outputs base2world = X_BoardTool and gripper2cam = X_CamNdi.
    for (int i = 0; i < n; ++i) {
      split(X_CamBoard[static_cast<std::size_t>(i)], R_a, t_a);
      split(X_NdiTool[static_cast<std::size_t>(i)], R_b, t_b);
    }
    cv::Mat R_BoardTool, t_BoardTool, R_CamNdi, t_CamNdi;
    cv::calibrateRobotWorldHandEye(R_a, t_a, R_b, t_b, R_BoardTool, t_BoardTool, R_CamNdi, t_CamNdi,
                                   opt.method == HandEyeMethod::AXZB_Shah ? cv::CALIB_ROBOT_WORLD_HAND_EYE_SHAH
                                                                          : cv::CALIB_ROBOT_WORLD_HAND_EYE_LI);
    res.X_CamNdi = join(R_CamNdi, t_CamNdi);
    res.X_ToolBoard = join(R_BoardTool, t_BoardTool).inverse();
    res.summary.method = "hand-eye AX=ZB (OpenCV calibrateRobotWorldHandEye, " +
                         std::string(opt.method == HandEyeMethod::AXZB_Shah ? "Shah" : "Li") + ")";
  } else {
    // Eye-to-hand: gripper2base = X_ToolNdi_i, target2cam = X_CamBoard_i,
    // output cam2gripper = X_NdiCam (the fixed camera in the tracker "base").
    for (int i = 0; i < n; ++i) {
      split(X_NdiTool[static_cast<std::size_t>(i)].inverse(), R_a, t_a);
      split(X_CamBoard[static_cast<std::size_t>(i)], R_b, t_b);
    }
    cv::HandEyeCalibrationMethod m = cv::CALIB_HAND_EYE_TSAI;
    std::string name = "Tsai";
    switch (opt.method) {
      case HandEyeMethod::AXXB_Park: m = cv::CALIB_HAND_EYE_PARK; name = "Park"; break;
      case HandEyeMethod::AXXB_Horaud: m = cv::CALIB_HAND_EYE_HORAUD; name = "Horaud"; break;
      case HandEyeMethod::AXXB_Andreff: m = cv::CALIB_HAND_EYE_ANDREFF; name = "Andreff"; break;
      case HandEyeMethod::AXXB_Daniilidis: m = cv::CALIB_HAND_EYE_DANIILIDIS; name = "Daniilidis"; break;
      default: break;
    }
    cv::Mat R_NdiCam, t_NdiCam;
    cv::calibrateHandEye(R_a, t_a, R_b, t_b, R_NdiCam, t_NdiCam, m);
    res.X_CamNdi = join(R_NdiCam, t_NdiCam).inverse();
    // X_ToolBoard_i = X_ToolNdi_i X_NdiCam X_CamBoard_i, averaged.
    std::vector<Eigen::Matrix3d> Rs;
    Eigen::Vector3d t = Eigen::Vector3d::Zero();
    for (int i = 0; i < n; ++i) {
      const auto k = static_cast<std::size_t>(i);
      const Eigen::Isometry3d X = X_NdiTool[k].inverse() * res.X_CamNdi.inverse() * X_CamBoard[k];
      Rs.push_back(X.linear());
      t += X.translation();
    }
    res.X_ToolBoard.linear() = mean_rotation(Rs);
    res.X_ToolBoard.translation() = t / n;
    res.summary.method = "hand-eye AX=XB (OpenCV calibrateHandEye eye-to-hand, " + name + ")";
  }
  if (!res.X_CamNdi.matrix().allFinite() || !res.X_ToolBoard.matrix().allFinite()) {
    throw DegenerateInput("hand-eye: the solver returned no finite solution; the poses do not "
                          "constrain it (move the target through more varied rotations)");
  }
  hand_eye_residuals(X_NdiTool, X_CamBoard, res);
  res.summary.termination = "closed form";
  res.summary.initial_cost = res.rms_mm;
  res.summary.final_cost = res.rms_mm;
  res.summary.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

}  // namespace arnav::calib
