// The renderer is checked against AprilTag itself: a rendered tag must be detected with
// the right id and its corners where the ground truth projects them.
#include <apriltag/apriltag.h>
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "appliance/markers/tag_family.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace arnav::camera_sim {
namespace {

struct Detection {
  int id;
  std::array<cv::Point2d, 4> corners;
};

std::vector<Detection> detect(const cv::Mat& gray, const std::string& family_name) {
  markers::TagFamily family(family_name);
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family(td, family.get());
  td->nthreads = 1;
  td->quad_decimate = 1.0f;
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step), const_cast<uint8_t*>(gray.ptr<uint8_t>())};
  zarray_t* dets = apriltag_detector_detect(td, &im);
  std::vector<Detection> out;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    Detection det{d->id, {}};
    // AprilTag puts pixel centres at +0.5 (a pixel spans [i, i+1]); OpenCV at integers.
    for (int k = 0; k < 4; ++k) det.corners[static_cast<size_t>(k)] = cv::Point2d(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    out.push_back(det);
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(td);
  return out;
}

Eigen::Isometry3d pose(double x, double y, double z, double rx_deg, double ry_deg, double rz_deg) {
  const double d = std::numbers::pi / 180.0;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  // Board facing the camera: its z axis points back at the camera (rotate pi about x).
  X.linear() = (Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(rx_deg * d, Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(ry_deg * d, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rz_deg * d, Eigen::Vector3d::UnitZ()))
                   .toRotationMatrix();
  X.translation() = Eigen::Vector3d(x, y, z);
  return X;
}

markers::TagBoard four_tag_board(const std::string& family) {
  markers::TagBoard board;
  board.name = "board";
  board.family = family;
  const double s = 40.0;
  int id = 0;
  for (double y : {45.0, -45.0}) {
    for (double x : {-45.0, 45.0}) {
      markers::BoardTag t{id++, s, Eigen::Isometry3d::Identity()};
      t.X_BoardTag.translation() = Eigen::Vector3d(x, y, 0);
      board.tags.push_back(t);
    }
  }
  return board;
}

void expect_corners_match(const RenderResult& r, const std::vector<Detection>& dets, double tol_px) {
  for (const auto& truth : r.tags) {
    if (!truth.in_image || !truth.facing) continue;
    const Detection* found = nullptr;
    for (const auto& d : dets) {
      if (d.id == truth.id) found = &d;
    }
    ASSERT_NE(found, nullptr) << "tag " << truth.id << " not detected";
    for (size_t k = 0; k < 4; ++k) {
      EXPECT_NEAR(found->corners[k].x, truth.corners_px[k].x, tol_px) << "tag " << truth.id << " corner " << k;
      EXPECT_NEAR(found->corners[k].y, truth.corners_px[k].y, tol_px) << "tag " << truth.id << " corner " << k;
    }
  }
}

TEST(SyntheticRenderer, SingleTagIsDetectedWhereTruthProjectsIt) {
  SyntheticRenderer renderer(markers::pinhole_camera(640, 480, 60.0));
  const markers::TagBoard board = markers::single_tag_board("tag", "tag36h11", 42, 60.0);
  const RenderResult r = renderer.render({{&board, pose(10, -5, 400, 20, -15, 30)}}, RenderOptions{});
  ASSERT_EQ(r.image.type(), CV_8UC1);
  ASSERT_EQ(r.tags.size(), 1u);
  EXPECT_TRUE(r.tags[0].in_image);
  EXPECT_GT(r.tags[0].area_px, 1000.0);
  const auto dets = detect(r.image, "tag36h11");
  ASSERT_EQ(dets.size(), 1u);
  EXPECT_EQ(dets[0].id, 42);
  expect_corners_match(r, dets, 0.3);
}

TEST(SyntheticRenderer, BoardThroughDistortedLensMatchesTruth) {
  markers::CameraModel cam = markers::pinhole_camera(1280, 720, 75.0);
  cam.distortion = {-0.25, 0.08, 0.0005, -0.0003, -0.01};
  cam.K(0, 2) += 7.5;
  SyntheticRenderer renderer(cam);
  for (const std::string family : {"tag36h11", "tagStandard41h12"}) {
    const markers::TagBoard board = four_tag_board(family);
    // Off-centre, where the distortion is strong.
    const RenderResult r = renderer.render({{&board, pose(-220, 90, 450, -25, 20, 10)}}, RenderOptions{});
    const auto dets = detect(r.image, family);
    EXPECT_EQ(dets.size(), 4u) << family;
    // AprilTag fits straight lines to edges that the lens bends: a few tenths of a pixel.
    expect_corners_match(r, dets, 0.6);
  }
}

TEST(SyntheticRenderer, NoiseBlurAndLightingKeepTagsDetectableAndAreSeeded) {
  SyntheticRenderer renderer(markers::pinhole_camera(640, 480, 60.0));
  const markers::TagBoard board = four_tag_board("tag36h11");
  RenderOptions opt;
  opt.noise_sigma = 6.0;
  opt.blur_sigma_px = 1.2;
  opt.lighting.gain = 0.6;
  opt.lighting.gradient_per_px = Eigen::Vector2d(0.0012, 0.0);
  opt.lighting.vignetting = 0.3;
  const RenderResult a = renderer.render({{&board, pose(0, 0, 500, 10, 10, 0)}}, opt);
  const RenderResult b = renderer.render({{&board, pose(0, 0, 500, 10, 10, 0)}}, opt);
  EXPECT_EQ(cv::norm(a.image, b.image, cv::NORM_L1), 0.0);
  opt.noise_seed = 2;
  const RenderResult c = renderer.render({{&board, pose(0, 0, 500, 10, 10, 0)}}, opt);
  EXPECT_GT(cv::norm(a.image, c.image, cv::NORM_L1), 0.0);
  const auto dets = detect(a.image, "tag36h11");
  EXPECT_EQ(dets.size(), 4u);
  expect_corners_match(a, dets, 0.6);
  // The gradient brightens the right side of the image.
  EXPECT_GT(cv::mean(a.image.colRange(560, 640))[0], cv::mean(a.image.colRange(0, 80))[0]);
}

TEST(SyntheticRenderer, OccluderHidesATagAndIsReportedInTruth) {
  SyntheticRenderer renderer(markers::pinhole_camera(640, 480, 60.0));
  const markers::TagBoard board = four_tag_board("tag36h11");
  const Eigen::Isometry3d X_CamBoard = pose(0, 0, 450, 0, 0, 0);
  RenderOptions opt;
  const RenderResult clear = renderer.render({{&board, X_CamBoard}}, opt);
  // Cover tag 0 (top-left as seen) completely with an instrument-like polygon.
  const auto& t0 = clear.tags[0];
  std::vector<cv::Point2d> poly;
  const cv::Point2d centre = 0.25 * (t0.corners_px[0] + t0.corners_px[1] + t0.corners_px[2] + t0.corners_px[3]);
  for (const auto& c : t0.corners_px) poly.push_back(centre + 1.3 * (c - centre));
  opt.occluders.push_back(Occluder{poly, 0.1});
  const RenderResult hidden = renderer.render({{&board, X_CamBoard}}, opt);
  EXPECT_GT(hidden.tags[0].occluded_fraction, 0.99);
  EXPECT_LT(hidden.tags[1].occluded_fraction, 0.01);
  const auto dets = detect(hidden.image, "tag36h11");
  EXPECT_EQ(dets.size(), 3u);
  for (const auto& d : dets) EXPECT_NE(d.id, t0.id);
}

TEST(SyntheticRenderer, BoardBehindOrFacingAwayShowsNoTags) {
  SyntheticRenderer renderer(markers::pinhole_camera(640, 480, 60.0));
  const markers::TagBoard board = four_tag_board("tag36h11");
  const RenderResult behind = renderer.render({{&board, pose(0, 0, -400, 0, 0, 0)}}, RenderOptions{});
  EXPECT_TRUE(behind.tags.empty());
  EXPECT_EQ(cv::countNonZero(behind.image != behind.image.at<uint8_t>(0, 0)), 0);
  const RenderResult away = renderer.render({{&board, pose(0, 0, 400, 0, 180, 0)}}, RenderOptions{});
  ASSERT_EQ(away.tags.size(), 4u);
  EXPECT_FALSE(away.tags[0].facing);
  EXPECT_TRUE(detect(away.image, "tag36h11").empty());
}

TEST(SyntheticRenderer, NonPlanarBoardIsRejected) {
  SyntheticRenderer renderer(markers::pinhole_camera(320, 240, 60.0));
  markers::TagBoard board = four_tag_board("tag36h11");
  board.tags[1].X_BoardTag.translation().z() = 5.0;
  EXPECT_THROW(renderer.render({{&board, pose(0, 0, 400, 0, 0, 0)}}, RenderOptions{}), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::camera_sim
