// Detection + pose against the synthetic camera's ground truth, and the ambiguity,
// rejection and smoothing logic on exactly projected corners.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

#include "appliance/markers/board_pose.hpp"
#include "appliance/markers/board_tracker.hpp"
#include "appliance/markers/tag_detector.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace arnav::markers {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

Eigen::Isometry3d facing_pose(double x, double y, double z, double rx_deg, double ry_deg, double rz_deg) {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = (Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(rx_deg * kDeg, Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(ry_deg * kDeg, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(rz_deg * kDeg, Eigen::Vector3d::UnitZ()))
                   .toRotationMatrix();
  X.translation() = Eigen::Vector3d(x, y, z);
  return X;
}

TagBoard four_tag_board() {
  TagBoard board;
  board.name = "liver_marker";
  int id = 10;
  for (double y : {40.0, -40.0}) {
    for (double x : {-40.0, 40.0}) {
      BoardTag t{id++, 45.0, Eigen::Isometry3d::Identity()};
      t.X_BoardTag.translation() = Eigen::Vector3d(x, y, 0);
      board.tags.push_back(t);
    }
  }
  return board;
}

CameraModel distorted_camera() {
  CameraModel cam = pinhole_camera(1280, 720, 70.0);
  cam.distortion = {-0.22, 0.07, 0.0006, -0.0004, -0.008};
  return cam;
}

// Corners of the board's tags projected exactly (optionally with noise) as detections.
std::vector<TagDetection> project_board(const TagBoard& board, const CameraModel& cam, const Eigen::Isometry3d& X_CamBoard,
                                        double noise_px = 0.0, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> n(0.0, noise_px);
  std::vector<TagDetection> dets;
  for (const auto& tag : board.tags) {
    std::vector<Eigen::Vector3d> p;
    for (const auto& c : tag_corners_in_board(tag)) p.push_back(X_CamBoard * c);
    const auto px = cam.project(p);
    TagDetection d;
    d.id = tag.id;
    for (size_t k = 0; k < 4; ++k) d.corners_px[k] = px[k] + (noise_px > 0 ? cv::Point2d(n(rng), n(rng)) : cv::Point2d());
    dets.push_back(d);
  }
  return dets;
}

TEST(BoardPose, RenderedBoardThroughDistortedLensMatchesTruth) {
  const CameraModel cam = distorted_camera();
  const TagBoard board = four_tag_board();
  camera_sim::SyntheticRenderer renderer(cam);
  TagDetector detector(DetectorSettings{"tag36h11", 1.0, 1, 0.0, 0.25, true, 2});
  BoardPoseEstimator estimator(board, cam);
  for (const auto& truth : {facing_pose(0, 0, 450, 0, 0, 0), facing_pose(-180, 80, 500, 25, -20, 40),
                            facing_pose(150, -60, 650, -35, 10, -70)}) {
    const auto frame = renderer.render({{&board, truth}}, camera_sim::RenderOptions{});
    const auto dets = detector.detect(frame.image);
    ASSERT_EQ(dets.size(), 4u);
    const PoseOutcome out = estimator.estimate(dets);
    ASSERT_TRUE(out.pose) << out.reason;
    const double dt_mm = (out.pose->X_CamBoard.translation() - truth.translation()).norm();
    const double dr_deg = rotation_angle_between(out.pose->X_CamBoard, truth) / kDeg;
    EXPECT_LT(dt_mm, 1.5) << "at z " << truth.translation().z();
    EXPECT_LT(dr_deg, 0.5);
    EXPECT_LT(out.pose->reprojection_rms_px, 0.6);
    EXPECT_GT(out.pose->quality, 0.5);
    EXPECT_EQ(out.pose->tags_used, 4);
    EXPECT_FALSE(out.pose->ambiguous);
    // Solver summary: the LM refinement never makes the joint fit worse.
    EXPECT_EQ(out.pose->summary.method, "IPPE+LM");
    EXPECT_LE(out.pose->summary.final_rms_px, out.pose->summary.initial_rms_px + 1e-9);
    EXPECT_GT(out.pose->summary.wall_time_us, 0.0);
  }
}

TEST(BoardPose, IgnoringTheLensDistortionGivesAWorsePose) {
  const CameraModel cam = distorted_camera();
  CameraModel no_lens = cam;
  no_lens.distortion.clear();
  const TagBoard board = four_tag_board();
  const Eigen::Isometry3d truth = facing_pose(-260, 120, 550, 20, 25, 10);
  const auto dets = project_board(board, cam, truth);
  const auto good = BoardPoseEstimator(board, cam).estimate(dets);
  const auto bad = BoardPoseEstimator(board, no_lens, PoseSettings{1.5, 3.0, 100.0}).estimate(dets);
  ASSERT_TRUE(good.pose && bad.pose);
  const double good_mm = (good.pose->X_CamBoard.translation() - truth.translation()).norm();
  const double bad_mm = (bad.pose->X_CamBoard.translation() - truth.translation()).norm();
  EXPECT_LT(good_mm, 1e-6);
  EXPECT_GT(bad_mm, 20.0 * std::max(good_mm, 0.1));
  EXPECT_GT(bad.pose->reprojection_rms_px, 1.0);
}

TEST(BoardPose, SingleTagOfEachFamily) {
  const CameraModel cam = distorted_camera();
  camera_sim::SyntheticRenderer renderer(cam);
  for (const std::string family : {"tag36h11", "tagStandard41h12"}) {
    const TagBoard board = single_tag_board("pointer", family, 5, 50.0);
    const Eigen::Isometry3d truth = facing_pose(60, -40, 400, 30, 15, 20);
    const auto frame = renderer.render({{&board, truth}}, camera_sim::RenderOptions{});
    TagDetector detector(DetectorSettings{family, 2.0, 1, 0.0, 0.25, true, 1});
    const auto out = BoardPoseEstimator(board, cam).estimate(detector.detect(frame.image));
    ASSERT_TRUE(out.pose) << family << ": " << out.reason;
    EXPECT_LT((out.pose->X_CamBoard.translation() - truth.translation()).norm(), 2.0) << family;
    EXPECT_LT(rotation_angle_between(out.pose->X_CamBoard, truth) / kDeg, 1.5) << family;
  }
}

TEST(BoardPose, PlanarAmbiguityUsesThePriorAndReportsFlips) {
  const CameraModel cam = pinhole_camera(1280, 720, 70.0);
  // A small, far, slightly tilted tag: the classic two-solution case.
  const TagBoard board = single_tag_board("pointer", "tag36h11", 1, 20.0);
  const Eigen::Isometry3d truth = facing_pose(30, 10, 900, 12, 0, 0);
  const auto dets = project_board(board, cam, truth, 0.25, 7);
  BoardPoseEstimator estimator(board, cam, PoseSettings{3.0, 3.0, 3.0});
  const PoseOutcome none = estimator.estimate(dets);
  ASSERT_TRUE(none.pose);
  ASSERT_TRUE(none.pose->ambiguous) << "rms " << none.pose->reprojection_rms_px << " alt "
                                    << none.pose->alt_reprojection_rms_px;
  EXPECT_LT(none.pose->quality, 0.5);
  // With the truth as prior the estimator keeps the consistent solution...
  const PoseOutcome with_truth = estimator.estimate(dets, truth);
  ASSERT_TRUE(with_truth.pose);
  EXPECT_LT(rotation_angle_between(with_truth.pose->X_CamBoard, truth) / kDeg, 8.0);
  // ...and with the mirrored solution as prior it keeps that one and calls it a flip
  // relative to the truth only if it differs from the lowest-error choice.
  Eigen::Isometry3d mirrored = truth;
  mirrored.linear() = truth.linear() * Eigen::AngleAxisd(-24 * kDeg, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const PoseOutcome with_mirror = estimator.estimate(dets, mirrored);
  ASSERT_TRUE(with_mirror.pose);
  EXPECT_LT(rotation_angle_between(with_mirror.pose->X_CamBoard, mirrored) / kDeg,
            rotation_angle_between(with_mirror.pose->X_CamBoard, truth) / kDeg);
  EXPECT_TRUE(with_truth.pose->flipped != with_mirror.pose->flipped);
}

TEST(BoardPose, InconsistentCornersAreRejectedWithTheReason) {
  const CameraModel cam = pinhole_camera(1280, 720, 70.0);
  const TagBoard board = four_tag_board();
  auto dets = project_board(board, cam, facing_pose(0, 0, 500, 10, 0, 0));
  std::swap(dets[0].id, dets[3].id);  // board printed with another layout
  const PoseOutcome out = BoardPoseEstimator(board, cam).estimate(dets);
  EXPECT_FALSE(out.pose);
  EXPECT_NE(out.reason.find("reprojection error"), std::string::npos) << out.reason;
  const PoseOutcome nothing = BoardPoseEstimator(board, cam).estimate({});
  EXPECT_NE(nothing.reason.find("no tag of board 'liver_marker'"), std::string::npos);
}

TEST(BoardTracker, SmoothingLagMatchesTheReportedLatency) {
  const CameraModel cam = pinhole_camera(1280, 720, 70.0);
  const TagBoard board = four_tag_board();
  const double alpha = 0.25, dt_s = 1.0 / 30.0, v_mm_per_s = 60.0;
  BoardTracker tracker(BoardPoseEstimator(board, cam), TrackerSettings{0.5, alpha, 20.0, 15.0});
  std::optional<TrackedPose> last;
  Eigen::Isometry3d truth;
  for (int k = 0; k < 90; ++k) {
    truth = facing_pose(-100 + v_mm_per_s * k * dt_s, 0, 500, 5, 0, 0);
    last = tracker.update(project_board(board, cam, truth), static_cast<std::int64_t>(k * dt_s * 1e6));
    ASSERT_TRUE(last);
  }
  // Steady state: the smoothed pose trails the truth by v * added_latency.
  const double expected_latency_s = (1 - alpha) / alpha * dt_s;
  EXPECT_NEAR(last->added_latency_s, expected_latency_s, 1e-3);
  const double lag_mm = truth.translation().x() - last->estimate.X_CamBoard.translation().x();
  EXPECT_NEAR(lag_mm, v_mm_per_s * expected_latency_s, 0.05);
  // A jump restarts the filter instead of dragging the pose across.
  const Eigen::Isometry3d far = facing_pose(100, 50, 500, 5, 0, 0);
  const auto jumped = tracker.update(project_board(board, cam, far), static_cast<std::int64_t>(90 * dt_s * 1e6));
  ASSERT_TRUE(jumped);
  EXPECT_LT((jumped->estimate.X_CamBoard.translation() - far.translation()).norm(), 1e-6);
}

TEST(DetectorSettings, OutOfRangeValuesAreNamed) {
  DetectorSettings s;
  EXPECT_NO_THROW(validate(s));
  s.decimate = 0.5;
  EXPECT_THROW(validate(s), std::invalid_argument);
  s = DetectorSettings{};
  s.threads = 0;
  EXPECT_THROW(validate(s), std::invalid_argument);
  s = DetectorSettings{};
  s.family = "tag37h12";
  try {
    validate(s);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tag37h12"), std::string::npos);
  }
  EXPECT_THROW(validate(TrackerSettings{0.5, 0.0, 20, 15}), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::markers
