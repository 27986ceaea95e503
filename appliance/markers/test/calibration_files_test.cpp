// Boards and intrinsics come from the calibration library's files; a printed marker board
// (arnav-calib's generator) must be tracked where the synthetic camera put it.
#include <gtest/gtest.h>

#include <fstream>
#include <numbers>

#include "appliance/markers/board_pose.hpp"
#include "appliance/markers/calibration_files.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace arnav::markers {
namespace {

TEST(CalibrationFiles, MarkerBoardLayoutIsTrackedAtItsRenderedPose) {
  const calib::BoardLayout layout = calib::make_marker_board("tag36h11", 40.0, 30.0, 20, 10.0);
  const TagBoard board = board_from_layout(layout, "liver_marker", "generated");
  ASSERT_EQ(board.tags.size(), 4u);
  EXPECT_NEAR(board.tags[0].size_mm, 40.0, 1e-9);
  EXPECT_FALSE(board.paper_mm.isEmpty());
  // Corners survive the conversion exactly.
  for (size_t t = 0; t < 4; ++t) {
    const auto c = tag_corners_in_board(board.tags[t]);
    const calib::BoardTag* src = layout.find_tag(board.tags[t].id);
    ASSERT_NE(src, nullptr);
    for (size_t k = 0; k < 4; ++k) EXPECT_LT((c[k] - src->p_BoardCorner_mm[k]).norm(), 1e-9);
  }
  CameraModel cam = pinhole_camera(1280, 720, 70.0);
  cam.distortion = {-0.2, 0.05, 0, 0, 0};
  camera_sim::SyntheticRenderer renderer(cam);
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  // Printed side towards the camera, whichever side of the board frame that is.
  truth.linear() = (Eigen::AngleAxisd(front_side(board) > 0 ? std::numbers::pi : 0.0, Eigen::Vector3d::UnitX()) *
                    Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()))
                       .toRotationMatrix();
  truth.translation() = Eigen::Vector3d(-60, 50, 500);
  const auto frame = renderer.render({{&board, truth}}, camera_sim::RenderOptions{});
  TagDetector detector(DetectorSettings{});
  const auto out = BoardPoseEstimator(board, cam).estimate(detector.detect(frame.image));
  ASSERT_TRUE(out.pose) << out.reason;
  EXPECT_EQ(out.pose->tags_used, 4);
  EXPECT_LT((out.pose->X_CamBoard.translation() - truth.translation()).norm(), 1.5);
}

TEST(CalibrationFiles, ChessboardAndBentTagsAreRejectedNamingTheSource) {
  const calib::BoardLayout chess = calib::make_chessboard(9, 6, 25.0, 10.0);
  EXPECT_THROW(board_from_layout(chess, "x", "chess.yaml"), std::invalid_argument);
  calib::BoardLayout layout = calib::make_marker_board("tag36h11", 40.0, 30.0, 0, 10.0);
  layout.tags[1].p_BoardCorner_mm[2].x() += 3.0;
  try {
    board_from_layout(layout, "x", "board.yaml");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("board.yaml"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("not a square"), std::string::npos);
  }
}

TEST(CalibrationFiles, IntrinsicsFileBecomesACameraModel) {
  calib::CameraIntrinsics in;
  in.camera_name = "bench";
  in.image_width = 1280;
  in.image_height = 720;
  in.camera_matrix = cv::Matx33d(900, 0, 640, 0, 905, 360, 0, 0, 1);
  in.distortion = {-0.1, 0.02, 0.001, 0.0, 0.0};
  const auto path = std::filesystem::temp_directory_path() / ("arnav_intr_" + std::to_string(::getpid()) + ".yaml");
  calib::write_intrinsics(path, in);
  const CameraModel cam = read_camera(path);
  EXPECT_EQ(cam.width, 1280);
  EXPECT_DOUBLE_EQ(cam.K(1, 1), 905);
  EXPECT_EQ(cam.distortion.size(), 5u);
  std::ofstream(path) << "%YAML:1.0\nimage_width: 12\n";
  EXPECT_THROW(read_camera(path), std::exception);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace arnav::markers
