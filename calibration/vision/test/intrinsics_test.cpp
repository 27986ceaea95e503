// Intrinsics from images: AprilTag grids rendered by the synthetic camera
// (appliance/synthetic_camera) through a distorted camera, chessboards from the printed board
// image warped into a pinhole view; known answers within tolerance, outlier views
// rejected with the reason, too few views rejected.
#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calibration/lib/board_render.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/intrinsics_calibration.hpp"
#include "calibration/vision/target_detection.hpp"
#include "calibration/vision/test/sim_board.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

using namespace arnav::calib;
using arnav::calib::test::board_facing_camera;
using arnav::calib::test::to_tag_board;

namespace {

arnav::markers::CameraModel true_camera() {
  arnav::markers::CameraModel cam;
  cam.width = 800;
  cam.height = 600;
  cam.K = cv::Matx33d(700, 0, 405, 0, 702, 296, 0, 0, 1);
  cam.distortion = {-0.18, 0.06, 0.0008, -0.0005, 0.0};
  return cam;
}

// 14 board poses spread over the image with tilts up to 35 degrees.
std::vector<Eigen::Isometry3d> view_poses(const BoardLayout& layout) {
  std::vector<Eigen::Isometry3d> poses;
  const double tilts[][3] = {{0, 0, 0},  {30, 0, 5},  {-30, 0, -5}, {0, 30, 10}, {0, -30, 0},
                             {25, 25, 0}, {-25, 25, 15}, {25, -25, -10}, {-25, -25, 0}, {35, 10, 0},
                             {10, -35, 5}, {-35, -10, 0}, {15, 15, 30}, {-15, -20, -30}};
  const double offsets[][2] = {{0, 0}, {-90, -60}, {90, 60}, {-90, 60}, {90, -60}, {0, -80}, {0, 80},
                               {-110, 0}, {110, 0}, {-60, -60}, {60, 60}, {60, -60}, {-60, 60}, {0, 0}};
  for (int i = 0; i < 14; ++i) {
    poses.push_back(board_facing_camera(layout, 480 + 15 * (i % 4), tilts[i][0], tilts[i][1], tilts[i][2],
                                        Eigen::Vector2d(offsets[i][0], offsets[i][1])));
  }
  return poses;
}

}  // namespace

TEST(Intrinsics, AprilTagGridFromSyntheticCameraImages) {
  const BoardLayout layout = make_apriltag_grid("tag36h11", 6, 5, 28.0, 7.0, 0, 8.0);
  const auto board = to_tag_board(layout);
  const auto cam = true_camera();
  arnav::camera_sim::SyntheticRenderer renderer(cam);
  arnav::camera_sim::RenderOptions ro;
  ro.noise_sigma = 2.0;
  ro.blur_sigma_px = 0.6;
  std::vector<CalibrationView> views;
  int k = 0;
  for (const auto& X_CamBoard : view_poses(layout)) {
    ro.noise_seed = static_cast<std::uint64_t>(++k);
    const auto frame = renderer.render({{&board, X_CamBoard}}, ro);
    const BoardObservation obs = detect_board(frame.image, layout);
    ASSERT_TRUE(obs.found) << "view " << k << ": " << obs.reason;
    views.push_back({std::string("view").append(std::to_string(k)), obs.image_px, obs.board_mm});
  }
  const IntrinsicsResult r = calibrate_intrinsics(views, cv::Size(cam.width, cam.height));
  const auto& K = r.intrinsics.camera_matrix;
  EXPECT_NEAR(K(0, 0), 700, 3.5);
  EXPECT_NEAR(K(1, 1), 702, 3.5);
  EXPECT_NEAR(K(0, 2), 405, 3.0);
  EXPECT_NEAR(K(1, 2), 296, 3.0);
  EXPECT_NEAR(r.intrinsics.distortion[0], -0.18, 0.02);
  EXPECT_LT(r.intrinsics.rms_reprojection_error_px, 0.3);
  EXPECT_EQ(r.intrinsics.views_used, 14);
  EXPECT_GT(r.coverage, 0.6);
  // Undistortion agrees with the true camera across the image to a fraction of a pixel.
  // Probes inside the region the board views covered (extrapolation is not checked).
  std::vector<cv::Point2d> probe = {{100, 80}, {700, 520}, {400, 300}, {120, 500}};
  std::vector<cv::Point2d> und_true, und_est;
  cv::undistortPoints(probe, und_true, cam.K, cam.distortion);
  cv::undistortPoints(probe, und_est, K, r.intrinsics.distortion_mat());
  for (std::size_t i = 0; i < probe.size(); ++i) {
    EXPECT_LT(cv::norm(und_true[i] - und_est[i]) * 700.0, 1.0) << "probe " << i;
  }
}

TEST(Intrinsics, ChessboardFromPrintedBoardImage) {
  // Pinhole view of the printed page = homography; warp the 150 dpi page into each view.
  const BoardLayout layout = make_chessboard(9, 6, 25.0, 10.0);
  const double dpi = 150.0;
  const cv::Mat page = render_board_png(layout, dpi);
  const cv::Matx33d K(650, 0, 322, 0, 650, 238, 0, 0, 1);
  const double mm_per_px = 25.4 / dpi;
  // Page pixel (u, v) -> Board mm: x = (u + 0.5) mm_per_px, y = H - (v + 0.5) mm_per_px.
  const cv::Matx33d page_to_board(mm_per_px, 0, 0.5 * mm_per_px, 0, -mm_per_px, layout.board_height_mm - 0.5 * mm_per_px,
                                  0, 0, 1);
  std::vector<CalibrationView> views;
  const double tilts[][2] = {{0, 0}, {25, 0}, {-25, 0}, {0, 25}, {0, -25}, {20, 20}, {-20, 20}, {20, -20}, {-20, -20}, {30, 10}};
  for (int i = 0; i < 10; ++i) {
    const Eigen::Isometry3d X = board_facing_camera(layout, 480, tilts[i][0], tilts[i][1], 8.0 * i - 40,
                                                    Eigen::Vector2d(10.0 * (i % 3) - 10, 8.0 * (i % 2)));
    const Eigen::Matrix3d R = X.linear();
    const Eigen::Vector3d t = X.translation();
    const cv::Matx33d Rt(R(0, 0), R(0, 1), t(0), R(1, 0), R(1, 1), t(1), R(2, 0), R(2, 1), t(2));
    const cv::Matx33d H = K * Rt * page_to_board;
    cv::Mat image;
    cv::warpPerspective(page, image, cv::Mat(H), cv::Size(640, 480), cv::INTER_AREA, cv::BORDER_CONSTANT, cv::Scalar(90));
    const BoardObservation obs = detect_board(image, layout);
    ASSERT_TRUE(obs.found) << "view " << i << ": " << obs.reason;
    views.push_back({std::string("chess").append(std::to_string(i)), obs.image_px, obs.board_mm});
  }
  IntrinsicsOptions o;
  o.fix_k3 = true;
  const IntrinsicsResult r = calibrate_intrinsics(views, cv::Size(640, 480), o);
  EXPECT_NEAR(r.intrinsics.camera_matrix(0, 0), 650, 4.0);
  EXPECT_NEAR(r.intrinsics.camera_matrix(0, 2), 322, 4.0);
  EXPECT_NEAR(r.intrinsics.camera_matrix(1, 2), 238, 4.0);
  EXPECT_LT(r.intrinsics.rms_reprojection_error_px, 0.3);
}

TEST(Intrinsics, OutlierViewRejectedWithReasonAndTooFewViewsRejected) {
  // Exact projections of a 7x5 grid through a known camera, one view corrupted.
  const cv::Matx33d K(800, 0, 320, 0, 800, 240, 0, 0, 1);
  std::vector<cv::Point3f> grid;
  for (int r = 0; r < 5; ++r) for (int c = 0; c < 7; ++c) grid.emplace_back(40.0f * c, 40.0f * r, 0.0f);
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.0f, 0.1f);
  std::vector<CalibrationView> views;
  for (int i = 0; i < 10; ++i) {
    const cv::Vec3d rvec(0.5 * std::sin(i), 0.5 * std::cos(i), 0.1 * i);
    const cv::Vec3d tvec(-120 + 5 * i, -80, 550 + 10 * i);
    std::vector<cv::Point2f> px;
    cv::projectPoints(grid, rvec, tvec, K, cv::noArray(), px);
    for (auto& p : px) p += cv::Point2f(noise(rng), noise(rng));
    if (i == 4) {
      for (std::size_t k = 0; k < px.size(); k += 3) px[k] += cv::Point2f(6.0f, -5.0f);  // mis-detection
    }
    views.push_back({std::string("v").append(std::to_string(i)), px, grid});
  }
  views.push_back({"sparse", {{1, 1}, {2, 2}}, {{0, 0, 0}, {1, 0, 0}}});
  IntrinsicsOptions o;
  o.fix_k3 = true;
  const IntrinsicsResult r = calibrate_intrinsics(views, cv::Size(640, 480), o);
  EXPECT_FALSE(r.views[4].used);
  EXPECT_NE(r.views[4].reason.find("outlier"), std::string::npos) << r.views[4].reason;
  EXPECT_FALSE(r.views[10].used);
  EXPECT_NE(r.views[10].reason.find("corners"), std::string::npos);
  EXPECT_EQ(r.intrinsics.views_used, 9);
  EXPECT_NEAR(r.intrinsics.camera_matrix(0, 0), 800, 5.0);
  EXPECT_LT(r.intrinsics.rms_reprojection_error_px, 0.2);

  views.resize(3);
  try {
    calibrate_intrinsics(views, cv::Size(640, 480), o);
    FAIL() << "3 views accepted";
  } catch (const DegenerateInput& e) {
    EXPECT_NE(std::string(e.what()).find("3 usable views"), std::string::npos) << e.what();
  }
}

TEST(BoardRender, PrintedTagsAreDetectedWhereTheLayoutSays) {
  // The printed page is a fronto-parallel image: detect the tags in it and map the
  // corners back to Board millimetres; they must land on the layout's corners.
  const BoardLayout layout = make_apriltag_grid("tag36h11", 4, 3, 30.0, 8.0, 10, 10.0);
  const double dpi = 200.0;
  const cv::Mat page = render_board_png(layout, dpi);
  EXPECT_NEAR(page.cols, layout.board_width_mm / 25.4 * dpi, 1.0);
  const BoardObservation obs = detect_board(page, layout);
  ASSERT_TRUE(obs.found) << obs.reason;
  EXPECT_EQ(obs.tag_ids.size(), 12u);
  const double mm_per_px = 25.4 / dpi;
  for (std::size_t i = 0; i < obs.image_px.size(); ++i) {
    const double x = (static_cast<double>(obs.image_px[i].x) + 0.5) * mm_per_px;
    const double y = layout.board_height_mm - (static_cast<double>(obs.image_px[i].y) + 0.5) * mm_per_px;
    EXPECT_NEAR(x, obs.board_mm[i].x, 0.25) << "corner " << i;
    EXPECT_NEAR(y, obs.board_mm[i].y, 0.25) << "corner " << i;
  }
  const std::string svg = render_board_svg(layout);
  EXPECT_NE(svg.find("mm\" height=\""), std::string::npos);
  EXPECT_NE(svg.find("print at 100%"), std::string::npos);
}

TEST(Detection, BoardNotFoundGivesAReason) {
  const BoardLayout layout = make_apriltag_grid("tag36h11", 4, 3, 30.0, 8.0, 0, 10.0);
  cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(128));
  BoardObservation obs = detect_board(blank, layout);
  EXPECT_FALSE(obs.found);
  EXPECT_NE(obs.reason.find("0 tags"), std::string::npos) << obs.reason;
  obs = detect_board(blank, make_chessboard(9, 6, 25, 10));
  EXPECT_FALSE(obs.found);
  EXPECT_NE(obs.reason.find("not found"), std::string::npos);
  // Another board's tags: ids not on this board.
  const BoardLayout other = make_apriltag_grid("tag36h11", 4, 3, 30.0, 8.0, 100, 10.0);
  obs = detect_board(render_board_png(other, 150), layout);
  EXPECT_FALSE(obs.found);
  EXPECT_NE(obs.reason.find("ids not on this board"), std::string::npos) << obs.reason;
}
