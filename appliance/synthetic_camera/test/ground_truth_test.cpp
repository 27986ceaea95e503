#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "appliance/synthetic_camera/trajectory.hpp"

namespace arnav::camera_sim {
namespace {

const std::string kHead =
    "# arnav camera ground truth 1\nsequence,time_s,board,x_mm,y_mm,z_mm,qw,qx,qy,qz,tags_visible,frame_file\n";

TEST(GroundTruth, WriteThenReadRoundTrips) {
  const auto path = std::filesystem::temp_directory_path() / ("arnav_gt_" + std::to_string(::getpid()) + ".csv");
  Trajectory tr;
  {
    GroundTruthWriter w(path);
    for (int k = 0; k < 5; ++k) w.write({k, k / 30.0, "board", tr.X_CamBoard(k / 30.0, {50, 40}), 4, ""});
  }
  const auto rows = read_ground_truth(path);
  ASSERT_EQ(rows.size(), 5u);
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(rows[static_cast<size_t>(k)].sequence, k);
    EXPECT_TRUE(rows[static_cast<size_t>(k)].X_CamBoard.isApprox(tr.X_CamBoard(k / 30.0, {50, 40}), 1e-6));
  }
  std::filesystem::remove(path);
}

TEST(GroundTruth, BadRowsNameTheLine) {
  auto expect_error = [](const std::string& text, const std::string& needle) {
    try {
      parse_ground_truth(text, "gt.csv");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const GroundTruthError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error("sequence,time_s\n", "gt.csv:1:");
  expect_error(kHead + "0,0,b,1,2,3,1,0,0,0,4\n", "gt.csv:3: 11 columns");
  expect_error(kHead + "0,0,b,1,2,x,1,0,0,0,4,\n", "gt.csv:3: column z_mm");
  expect_error(kHead + "0,0,b,1,2,3,1,1,0,0,4,\n", "quaternion norm");
  expect_error(kHead + "0,0,,1,2,3,1,0,0,0,4,\n", "board is empty");
  expect_error("", "header or column line missing");
  EXPECT_EQ(parse_ground_truth(kHead, "gt.csv").size(), 0u);
}

TEST(GroundTruth, Version2CarriesTargetPixels) {
  const auto path = std::filesystem::temp_directory_path() / ("arnav_gt2_" + std::to_string(::getpid()) + ".csv");
  {
    GroundTruthWriter w(path, 2);
    Trajectory tr;
    w.write({0, 0.0, "board", tr.X_CamBoard(0.0, {50, 40}), 4, ""});
    GroundTruthRow t;
    t.board = "target:tumour_centroid";
    t.X_CamBoard.translation() = Eigen::Vector3d(-120, 30, 550);
    t.tags_visible = 1;
    t.has_px = true;
    t.u_px = 410.25;
    t.v_px = 417.5;
    w.write(t);
  }
  const auto rows = read_ground_truth(path);
  std::filesystem::remove(path);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_FALSE(rows[0].has_px);
  EXPECT_FALSE(rows[0].is_target());
  EXPECT_TRUE(rows[1].is_target());
  ASSERT_TRUE(rows[1].has_px);
  EXPECT_DOUBLE_EQ(rows[1].u_px, 410.25);
  EXPECT_DOUBLE_EQ(rows[1].v_px, 417.5);
  EXPECT_TRUE(rows[1].X_CamBoard.translation().isApprox(Eigen::Vector3d(-120, 30, 550)));

  const std::string head2 =
      "# arnav camera ground truth 2\nsequence,time_s,board,x_mm,y_mm,z_mm,qw,qx,qy,qz,tags_visible,frame_file,u_px,v_px\n";
  const auto expect_error = [](const std::string& text, const std::string& needle) {
    try {
      parse_ground_truth(text, "gt.csv");
      FAIL() << "accepted: " << text;
    } catch (const GroundTruthError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error(head2 + "0,0,b,1,2,3,1,0,0,0,4,\n", "gt.csv:3: 12 columns, expected 14");
  expect_error(head2 + "0,0,target:t,1,2,3,1,0,0,0,1,,,\n", "gt.csv:3: target row without u_px,v_px");
  expect_error(head2 + "0,0,target:t,1,2,3,1,0,0,0,1,,5,\n", "gt.csv:3: u_px and v_px must both");
  expect_error(head2 + "0,0,target:t,1,2,3,1,0,0,0,1,,5,x\n", "gt.csv:3: column v_px");
  expect_error(kHead + "0,0,target:t,1,2,3,1,0,0,0,1,\n", "gt.csv:3: target rows need the version 2 header");
  GroundTruthWriter v1(std::filesystem::temp_directory_path() / ("arnav_gt1_" + std::to_string(::getpid()) + ".csv"));
  GroundTruthRow t;
  t.board = "target:x";
  EXPECT_THROW(v1.write(t), GroundTruthError);
  std::filesystem::remove(std::filesystem::temp_directory_path() / ("arnav_gt1_" + std::to_string(::getpid()) + ".csv"));
}

TEST(Trajectory, FacesTheCameraAndStaysInFront) {
  Trajectory tr;
  for (double t = 0; t < tr.period_s; t += 0.1) {
    const Eigen::Isometry3d X = tr.X_CamBoard(t, {60, 40});
    const Eigen::Vector3d centre = X * Eigen::Vector3d(60, 40, 0);
    EXPECT_GT(centre.z(), tr.distance_mm - tr.amplitude_mm.z() - 1e-9);
    // Board normal towards the camera, within the tilt.
    const double cos_angle = X.linear().col(2).dot(-centre.normalized());
    EXPECT_GT(cos_angle, std::cos((tr.tilt_deg * std::sqrt(2.0) + 20.0) * std::numbers::pi / 180.0));
  }
  Trajectory bad;
  bad.amplitude_mm.z() = 600;
  EXPECT_THROW(validate(bad), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::camera_sim
