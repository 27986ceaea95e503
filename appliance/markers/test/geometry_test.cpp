#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"
#include "appliance/markers/tag_family.hpp"

namespace arnav::markers {
namespace {

TEST(TagFamily, Tag36h11HasItsDocumentedLayout) {
  TagFamily fam("tag36h11");
  EXPECT_EQ(fam.code_count(), 587);
  EXPECT_EQ(fam.width_at_border(), 8);
  EXPECT_EQ(fam.total_width(), 10);
  const cv::Mat cells = fam.cells(0);
  ASSERT_EQ(cells.rows, 10);
  // White outer ring, black border ring just inside it.
  for (int k = 0; k < 10; ++k) {
    EXPECT_EQ(cells.at<uint8_t>(0, k), 255);
    EXPECT_EQ(cells.at<uint8_t>(9, k), 255);
  }
  for (int k = 1; k < 9; ++k) {
    EXPECT_EQ(cells.at<uint8_t>(1, k), 0);
    EXPECT_EQ(cells.at<uint8_t>(k, 8), 0);
  }
  EXPECT_NE(cv::norm(fam.cells(0), fam.cells(1), cv::NORM_L1), 0.0);
}

TEST(TagFamily, UnknownFamilyAndIdAreRejectedWithNames) {
  try {
    TagFamily fam("tag99h1");
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tag99h1"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("tagStandard41h12"), std::string::npos);
  }
  TagFamily fam("tagStandard41h12");
  EXPECT_THROW(fam.cells(fam.code_count()), std::out_of_range);
  EXPECT_THROW(fam.cells(-1), std::out_of_range);
}

TEST(TagBoard, CornersFollowDetectionOrderAndPlacement) {
  BoardTag tag{7, 40.0, Eigen::Isometry3d::Identity()};
  tag.X_BoardTag.translation() = Eigen::Vector3d(100, 50, 0);
  tag.X_BoardTag.linear() = Eigen::AngleAxisd(std::numbers::pi / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const auto c = tag_corners_in_board(tag);
  // Corner 0 is (-20,-20) in the tag; rotated +90 deg about z it becomes (20,-20).
  EXPECT_TRUE(c[0].isApprox(Eigen::Vector3d(120, 30, 0), 1e-12));
  EXPECT_TRUE(c[2].isApprox(Eigen::Vector3d(80, 70, 0), 1e-12));
}

TEST(TagBoard, ValidationNamesTheBoardAndTag) {
  TagBoard board = single_tag_board("marker", "tag36h11", 3, 30.0);
  EXPECT_NO_THROW(validate(board));
  board.tags.push_back(board.tags.front());
  EXPECT_THROW(validate(board), std::invalid_argument);
  board.tags.pop_back();
  board.tags[0].size_mm = 0;
  try {
    validate(board);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("marker"), std::string::npos);
  }
}

TEST(CameraModel, ProjectAndUndistortAreInverse) {
  CameraModel cam = pinhole_camera(1280, 720, 70.0);
  cam.distortion = {-0.28, 0.09, 0.0008, -0.0005, -0.01};
  std::vector<Eigen::Vector3d> pts;
  for (double x = -300; x <= 300; x += 150) {
    for (double y = -150; y <= 150; y += 75) pts.emplace_back(x, y, 500.0);
  }
  const auto px = cam.project(pts);
  const auto ray = cam.normalised(px);
  for (size_t i = 0; i < pts.size(); ++i) {
    EXPECT_NEAR(ray[i].x, pts[i].x() / pts[i].z(), 1e-9);
    EXPECT_NEAR(ray[i].y, pts[i].y() / pts[i].z(), 1e-9);
  }
  // The principal point does not move under distortion.
  const auto centre = cam.project({Eigen::Vector3d(0, 0, 100)});
  EXPECT_NEAR(centre[0].x, cam.K(0, 2), 1e-12);
}

TEST(CameraModel, InvalidModelsAreRejected) {
  CameraModel cam = pinhole_camera(640, 480, 60.0);
  EXPECT_NO_THROW(validate(cam));
  cam.distortion = {0.1, 0.2, 0.3};
  EXPECT_THROW(validate(cam), std::invalid_argument);
  cam.distortion.clear();
  cam.K(0, 0) = 0;
  EXPECT_THROW(validate(cam), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::markers
