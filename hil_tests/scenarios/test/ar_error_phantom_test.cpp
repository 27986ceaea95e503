// arnav-ar-error's measurement against a deforming phantom, on hand-made files: the error
// is taken against the deformed tumour centroid of the frame (px, and mm at its depth), the
// rigid-overlay comparison is the rest centroid through the registration and the true board
// pose, and the tumour displacement is the 3D distance between the two.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <unistd.h>

#include <opencv2/calib3d.hpp>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/scenarios/ar_error.hpp"
#include "host/scene/scene.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::hil {
namespace {

std::string slurp(const std::filesystem::path& p) { return arnav::testing::read_text(p); }

TEST(ArErrorPhantom, ScoresAgainstTheDeformedCentroidAndTheRigidOverlay) {
  const std::filesystem::path src = arnav::testing::source_dir() + "/hil_tests/scenarios/ar_demo";
  const std::string data = arnav::testing::data_dir();
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_arerr_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  for (const char* f : {"camera.yaml", "X_RefModel_phantom.yaml", "session_phantom.yaml"})
    std::filesystem::copy_file(src / f, dir / f, std::filesystem::copy_options::overwrite_existing);
  std::ofstream(dir / "liver_navigation.scene.yaml")
      << std::regex_replace(slurp(src / "liver_navigation.scene.yaml"), std::regex("\\.\\./\\.\\./\\.\\./data/"), data + "/");

  const host::Scene scene = host::load_scene((dir / "liver_navigation.scene.yaml").string());
  const Eigen::Vector3d c_Model = host::tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm);
  const Eigen::Isometry3d X_RefModel = calib::read_transform(dir / "X_RefModel_phantom.yaml").X_ParentChild;
  const calib::CameraIntrinsics cam = calib::read_intrinsics(dir / "camera.yaml");
  const auto project = [&](const Eigen::Vector3d& p) {
    std::vector<cv::Point2d> px;
    cv::projectPoints(std::vector<cv::Point3d>{{p.x(), p.y(), p.z()}}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                      cv::Mat(cam.camera_matrix), cv::Mat(cam.distortion), px);
    return px[0];
  };
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  X_CamBoard.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  X_CamBoard.translation() = Eigen::Vector3d(37, 68, 450);
  const Eigen::Vector3d rigid_Cam = X_CamBoard * X_RefModel * c_Model;
  const Eigen::Vector3d shift_Model(6, -3, 2);  // the phantom moved the tumour
  const Eigen::Vector3d deformed_Cam = X_CamBoard * X_RefModel * (c_Model + shift_Model);
  const cv::Point2d rigid_px = project(rigid_Cam), deformed_px = project(deformed_Cam);
  {
    camera_sim::GroundTruthWriter w(dir / "gt.csv", 2);
    for (int k = 0; k < 2; ++k) {
      w.write({k, k / 15.0, "liver_marker", X_CamBoard, 4, ""});
      camera_sim::GroundTruthRow t;
      t.sequence = k;
      t.time_s = k / 15.0;
      t.board = "target:tumour_centroid";
      t.X_CamBoard.translation() = deformed_Cam;
      t.tags_visible = 1;
      t.has_px = true;
      t.u_px = deformed_px.x;
      t.v_px = deformed_px.y;
      w.write(t);
    }
  }
  {
    // Frame 0: an overlay that did not deform (drawn at the rest centroid); frame 1: one
    // that followed the phantom (drawn at the deformed centroid).
    std::ofstream csv(dir / "overlay.csv");
    csv << "camera_sequence,capture_time_mono_us,pose_time_mono_us,model_step_time_mono_us,render_done_mono_us,"
           "motion_to_photon_ms,tumour_u_px,tumour_v_px,blade_to_margin_mm,flags\n";
    csv << "0,100,100,110,120,20.0," << rigid_px.x << "," << rigid_px.y << ",,\n";
    csv << "1,200,200,210,220,20.0," << deformed_px.x << "," << deformed_px.y << ",,\n";
  }
  const ArErrorReport rep = evaluate_ar_error((dir / "session_phantom.yaml").string(), (dir / "gt.csv").string(),
                                              (dir / "overlay.csv").string());
  ASSERT_TRUE(rep.phantom);
  ASSERT_EQ(rep.frames.size(), 2u);
  const double f = 0.5 * (cam.camera_matrix(0, 0) + cam.camera_matrix(1, 1));
  const double moved_px = cv::norm(rigid_px - deformed_px);
  ASSERT_GT(moved_px, 5.0);
  EXPECT_NEAR(rep.frames[0].error_px, moved_px, 1e-3);
  EXPECT_NEAR(rep.frames[0].error_mm, moved_px * deformed_Cam.z() / f, 1e-3);
  EXPECT_NEAR(rep.frames[1].error_px, 0.0, 1e-3);
  for (const auto& fr : rep.frames) {
    EXPECT_TRUE(fr.deformed_truth);
    EXPECT_NEAR(fr.rigid_error_px, moved_px, 1e-6);
    EXPECT_NEAR(fr.tumour_displacement_mm, shift_Model.norm(), 1e-5);
  }
  const nlohmann::json j = rep.summary();
  EXPECT_NEAR(j["ar_error_px"]["mean"].get<double>(), 0.5 * moved_px, 1e-3);
  EXPECT_NEAR(j["rigid_overlay"]["ar_error_px"]["mean"].get<double>(), moved_px, 1e-3);
  EXPECT_NEAR(j["tumour_displacement_mm"]["max"].get<double>(), shift_Model.norm(), 1e-5);

  // A phantom truth missing a frame's tumour row is an error naming the file, not a silent rigid fallback.
  {
    std::ofstream gt(dir / "gt_missing.csv");
    std::string text = slurp(dir / "gt.csv");
    const auto pos = text.rfind("1,0.066667,target:tumour_centroid");
    ASSERT_NE(pos, std::string::npos);
    gt << text.substr(0, pos);
  }
  try {
    evaluate_ar_error((dir / "session_phantom.yaml").string(), (dir / "gt_missing.csv").string(), (dir / "overlay.csv").string());
    ADD_FAILURE() << "accepted a phantom truth without the tumour row of frame 1";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("gt_missing.csv: frame 1 has the board but no target:tumour_centroid row"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil
