// Hand-eye (AX=XB and AX=ZB) against a synthetic bench: known X_CamNdi and X_ToolBoard,
// noisy tracker and camera poses; degenerate motion rejected.
#include <gtest/gtest.h>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/hand_eye.hpp"
#include "calibration/lib/test/test_util.hpp"

using namespace arnav::calib;
using arnav::calib::test::gaussian3;
using arnav::calib::test::random_rotation;
using arnav::calib::test::rotation_angle_deg;

namespace {

struct Bench {
  Eigen::Isometry3d X_CamNdi;
  Eigen::Isometry3d X_ToolBoard;
  std::vector<Eigen::Isometry3d> X_NdiTool;
  std::vector<Eigen::Isometry3d> X_CamBoard;
};

Bench make_bench(int n, double max_tilt_deg, double ndi_mm, double cam_mm, double cam_deg, unsigned seed) {
  std::mt19937 rng(seed);
  Bench b;
  b.X_CamNdi = Eigen::Translation3d(150, -300, 900) *
               Eigen::AngleAxisd(2.5, Eigen::Vector3d(0.3, 1, 0.1).normalized());
  b.X_ToolBoard = Eigen::Translation3d(20, 60, -15) * Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 0, 0.2).normalized());
  // Target in front of the camera ~600 mm, tilted about random axes.
  const Eigen::Isometry3d X_CamBoard0 = Eigen::Translation3d(0, 0, 600) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX());
  for (int i = 0; i < n; ++i) {
    Eigen::Isometry3d X_CamBoard = X_CamBoard0;
    X_CamBoard.linear() = random_rotation(rng, max_tilt_deg * M_PI / 180) * X_CamBoard.linear();
    X_CamBoard.translation() += gaussian3(rng, 60);
    const Eigen::Isometry3d X_NdiTool = b.X_CamNdi.inverse() * X_CamBoard * b.X_ToolBoard.inverse();
    Eigen::Isometry3d noisy_ndi = X_NdiTool;
    noisy_ndi.translation() += gaussian3(rng, ndi_mm);
    noisy_ndi.linear() = random_rotation(rng, 0) * noisy_ndi.linear();
    Eigen::Isometry3d noisy_cam = X_CamBoard;
    noisy_cam.translation() += gaussian3(rng, cam_mm);
    noisy_cam.linear() = Eigen::AngleAxisd(cam_deg * M_PI / 180, gaussian3(rng, 1).normalized()) * noisy_cam.linear();
    b.X_NdiTool.push_back(noisy_ndi);
    b.X_CamBoard.push_back(noisy_cam);
  }
  return b;
}

const HandEyeMethod kAll[] = {HandEyeMethod::AXXB_Tsai, HandEyeMethod::AXXB_Park, HandEyeMethod::AXXB_Horaud,
                              HandEyeMethod::AXXB_Andreff, HandEyeMethod::AXXB_Daniilidis,
                              HandEyeMethod::AXZB_Shah, HandEyeMethod::AXZB_Li};

}  // namespace

TEST(HandEye, NoiseFreeRecoversBothTransformsWithEveryMethod) {
  const Bench b = make_bench(15, 40, 0, 0, 0, 1);
  for (auto m : kAll) {
    HandEyeOptions o;
    o.method = m;
    const HandEyeResult r = calibrate_hand_eye(b.X_NdiTool, b.X_CamBoard, o);
    EXPECT_LT((r.X_CamNdi.translation() - b.X_CamNdi.translation()).norm(), 1e-4) << to_string(m);
    EXPECT_LT(rotation_angle_deg(r.X_CamNdi.linear(), b.X_CamNdi.linear()), 1e-5) << to_string(m);
    EXPECT_LT((r.X_ToolBoard.translation() - b.X_ToolBoard.translation()).norm(), 1e-4) << to_string(m);
    EXPECT_LT(r.rms_mm, 1e-4) << to_string(m);
  }
}

TEST(HandEye, NoisyBenchWithinTolerance) {
  // NDI 0.25 mm, camera board pose 0.5 mm / 0.1 deg, 30 poses tilted up to 35 deg.
  const Bench b = make_bench(30, 35, 0.25, 0.5, 0.1, 2);
  for (auto m : {HandEyeMethod::AXXB_Park, HandEyeMethod::AXXB_Daniilidis, HandEyeMethod::AXZB_Shah,
                 HandEyeMethod::AXZB_Li}) {
    HandEyeOptions o;
    o.method = m;
    const HandEyeResult r = calibrate_hand_eye(b.X_NdiTool, b.X_CamBoard, o);
    EXPECT_LT((r.X_CamNdi.translation() - b.X_CamNdi.translation()).norm(), 5.0) << to_string(m);
    EXPECT_LT(rotation_angle_deg(r.X_CamNdi.linear(), b.X_CamNdi.linear()), 0.3) << to_string(m);
    EXPECT_LT((r.X_ToolBoard.translation() - b.X_ToolBoard.translation()).norm(), 5.0) << to_string(m);
    EXPECT_LT(r.rms_mm, 3.0) << to_string(m);
    EXPECT_GT(r.rms_mm, 0.1) << to_string(m);  // noise shows in the residuals
    EXPECT_EQ(r.translation_residual_mm.size(), 30u);
  }
}

TEST(HandEye, RejectsDegenerateMotion) {
  Bench b = make_bench(10, 2, 0, 0, 0, 3);
  try {
    calibrate_hand_eye(b.X_NdiTool, b.X_CamBoard);
    FAIL() << "2 degree rotation spread accepted";
  } catch (const DegenerateInput& e) {
    EXPECT_NE(std::string(e.what()).find("tilt the hybrid target"), std::string::npos) << e.what();
  }
  b = make_bench(3, 40, 0, 0, 0, 4);
  EXPECT_THROW(calibrate_hand_eye(b.X_NdiTool, b.X_CamBoard), DegenerateInput);
  b = make_bench(10, 40, 0, 0, 0, 5);
  b.X_CamBoard.pop_back();
  EXPECT_THROW(calibrate_hand_eye(b.X_NdiTool, b.X_CamBoard), CalibError);
  EXPECT_THROW(parse_hand_eye_method("axxb"), CalibError);
}
