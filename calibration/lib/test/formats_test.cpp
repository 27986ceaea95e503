// File formats the appliance loads at start: round trips and rejection of bad files
// with the file and line named.
#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>

#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/pose_file.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "protocol/testing/error_of.hpp"

namespace fs = std::filesystem;
using namespace arnav::calib;

namespace {

using arnav::testing::error_of;

fs::path temp_dir() {
  fs::path dir = fs::temp_directory_path() /
                 ("arnav_calib_formats_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir;
}

void write_text(const fs::path& p, const std::string& text) {
  std::ofstream(p, std::ios::binary) << text;
}

CameraIntrinsics sample_intrinsics() {
  CameraIntrinsics in;
  in.camera_name = "bench";
  in.image_width = 1280;
  in.image_height = 720;
  in.camera_matrix = cv::Matx33d(900.5, 0, 641.25, 0, 901.75, 359.5, 0, 0, 1);
  in.distortion = {-0.12, 0.05, 0.001, -0.0007, 0.01};
  in.rms_reprojection_error_px = 0.2345;
  in.views_used = 17;
  in.calibration_date = "2026-11-21T10:00:00Z";
  return in;
}

}  // namespace

TEST(Intrinsics, RoundTripKeepsEveryField) {
  const fs::path p = temp_dir() / "cam.yaml";
  const CameraIntrinsics in = sample_intrinsics();
  write_intrinsics(p, in);
  const CameraIntrinsics out = read_intrinsics(p);
  EXPECT_EQ(out.camera_name, "bench");
  EXPECT_EQ(out.image_width, 1280);
  EXPECT_EQ(out.image_height, 720);
  for (int i = 0; i < 9; ++i) EXPECT_DOUBLE_EQ(out.camera_matrix.val[i], in.camera_matrix.val[i]);
  ASSERT_EQ(out.distortion.size(), 5u);
  for (std::size_t i = 0; i < 5; ++i) EXPECT_DOUBLE_EQ(out.distortion[i], in.distortion[i]);
  EXPECT_DOUBLE_EQ(out.rms_reprojection_error_px, 0.2345);
  EXPECT_EQ(out.views_used, 17);
  EXPECT_EQ(out.calibration_date, "2026-11-21T10:00:00Z");
}

TEST(Intrinsics, FileIsPlainOpenCvFileStorage) {
  const fs::path p = temp_dir() / "cam_cv.yaml";
  write_intrinsics(p, sample_intrinsics());
  cv::FileStorage f(p.string(), cv::FileStorage::READ);
  ASSERT_TRUE(f.isOpened());
  cv::Mat K;
  f["camera_matrix"] >> K;
  EXPECT_DOUBLE_EQ(K.at<double>(0, 0), 900.5);
  EXPECT_EQ(static_cast<int>(f["image_width"]), 1280);
}

TEST(Intrinsics, RejectsMissingKeyAndBadValuesNamingTheFile) {
  const fs::path p = temp_dir() / "cam_bad.yaml";
  write_intrinsics(p, sample_intrinsics());
  const std::string text = read_text_file(p, "test file");
  const std::string no_date = text.substr(0, text.find("calibration_date"));
  write_text(p, no_date);
  const std::string msg = error_of<CalibError>([&] { read_intrinsics(p); });
  EXPECT_NE(msg.find(p.string()), std::string::npos) << msg;
  EXPECT_NE(msg.find("calibration_date"), std::string::npos) << msg;

  EXPECT_NE(error_of<CalibError>([&] { read_intrinsics(temp_dir() / "does_not_exist.yaml"); }).find("cannot open"),
            std::string::npos);
  EXPECT_NE(error_of<CalibError>([] { parse_intrinsics("%YAML:1.0\n[unclosed", "mem"); }).find("mem"),
            std::string::npos);

  CameraIntrinsics bad = sample_intrinsics();
  bad.distortion = {1, 2, 3};
  EXPECT_NE(error_of<CalibError>([&] { write_intrinsics(p, bad); }).find("4, 5, 8, 12 or 14"), std::string::npos);
  bad = sample_intrinsics();
  bad.camera_matrix(0, 2) = 5000;
  EXPECT_NE(error_of<CalibError>([&] { write_intrinsics(p, bad); }).find("principal point"), std::string::npos);
}

TEST(Transform, RoundTripIsExactAndNamed) {
  RigidTransformRecord r;
  r.parent_frame = "Cam";
  r.child_frame = "Ndi";
  r.X_ParentChild = Eigen::Translation3d(10.5, -200.25, 1500.125) *
                    Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized());
  r.method = "hand-eye AX=ZB: test";
  r.date = "2026-11-21T10:00:00Z";
  r.residuals = {{"rms_mm", 0.31}, {"rms_deg", 0.05}};
  r.samples = 20;
  const fs::path p = temp_dir() / "X_CamNdi.yaml";
  write_transform(p, r);
  const RigidTransformRecord back = read_transform(p, "X_CamNdi");
  EXPECT_EQ(back.name(), "X_CamNdi");
  EXPECT_LT((back.X_ParentChild.matrix() - r.X_ParentChild.matrix()).norm(), 1e-12);
  EXPECT_EQ(back.method, r.method);
  EXPECT_EQ(back.date, r.date);
  EXPECT_EQ(back.samples, 20);
  EXPECT_DOUBLE_EQ(back.residuals.at("rms_mm"), 0.31);
  EXPECT_NE(error_of<CalibError>([&] { read_transform(p, "X_ToolTip"); }).find("X_ToolTip"), std::string::npos);
}

TEST(Transform, RejectsBadFilesWithLine) {
  const std::string good =
      "arnav_transform_version: 1\nname: X_CamNdi\nparent_frame: Cam\nchild_frame: Ndi\n"
      "units: mm\nmatrix_row_major: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n";
  EXPECT_NO_THROW(parse_transform(good, "t.yaml"));
  std::string msg = error_of<CalibError>([&] {
    parse_transform("arnav_transform_version: 1\nname: X_CamNdi\nparent_frame: Cam\n"
                    "child_frame: Ndi\nunits: mm\nmatrix_row_major: [2,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n",
                    "t.yaml");
  });
  EXPECT_NE(msg.find("t.yaml:6"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not a rotation"), std::string::npos) << msg;
  msg = error_of<CalibError>([&] {
    parse_transform("arnav_transform_version: 1\nname: X_NdiCam\nparent_frame: Cam\n"
                    "child_frame: Ndi\nunits: mm\nmatrix_row_major: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]\n",
                    "t.yaml");
  });
  EXPECT_NE(msg.find("t.yaml:2"), std::string::npos) << msg;
  msg = error_of<CalibError>([&] {
    parse_transform("arnav_transform_version: 1\nname: X_CamNdi\nparent_frame: Cam\n"
                    "child_frame: Ndi\nunits: m\nmatrix_row_major: [1,0,0,0]\n", "t.yaml");
  });
  EXPECT_NE(msg.find("units"), std::string::npos) << msg;
  msg = error_of<CalibError>([&] {
    parse_transform("arnav_transform_version: 1\nname: X_CamNdi\nparent_frame: Cam\n"
                    "child_frame: Ndi\nunits: mm\nmatrix_row_major: [1,0,0,0, 0,1,0,0]\n", "t.yaml");
  });
  EXPECT_NE(msg.find("16 numbers"), std::string::npos) << msg;
  EXPECT_NE(error_of<CalibError>([] { parse_transform("a: [", "t.yaml"); }).find("t.yaml:"), std::string::npos);
  EXPECT_FALSE(valid_frame_name("cam"));
  EXPECT_FALSE(valid_frame_name("Cam-1"));
  EXPECT_TRUE(valid_frame_name("Ref2"));
}

TEST(BoardLayout, GridGeometryAndRoundTrip) {
  const BoardLayout b = make_apriltag_grid("tag36h11", 5, 4, 30.0, 10.0, 0, 10.0);
  ASSERT_EQ(b.tags.size(), 20u);
  // Margin 10 mm + one white cell (30/8 mm), then the first tag's black border.
  const double border = 10.0 + 30.0 / 8.0;
  const double H = b.board_height_mm;
  const BoardTag* t0 = b.find_tag(0);  // printed top-left; y points up the sheet
  ASSERT_NE(t0, nullptr);
  EXPECT_NEAR(t0->p_BoardCorner_mm[3].x(), border, 1e-12);  // p3 top-left
  EXPECT_NEAR(t0->p_BoardCorner_mm[3].y(), H - border, 1e-12);
  EXPECT_NEAR(t0->p_BoardCorner_mm[0].y(), H - border - 30.0, 1e-12);  // p0 bottom-left
  EXPECT_NEAR(t0->p_BoardCorner_mm[1].x(), border + 30.0, 1e-12);  // p1 bottom-right
  EXPECT_NEAR(t0->p_BoardCorner_mm[1].y(), H - border - 30.0, 1e-12);
  const BoardTag* t6 = b.find_tag(6);  // second row, second column
  ASSERT_NE(t6, nullptr);
  EXPECT_NEAR(t6->p_BoardCorner_mm[3].x(), border + 40.0, 1e-12);
  EXPECT_NEAR(t6->p_BoardCorner_mm[3].y(), H - border - 40.0, 1e-12);
  EXPECT_NEAR(b.board_width_mm, 2 * border + 5 * 30 + 4 * 10, 1e-12);

  const fs::path p = temp_dir() / "grid.yaml";
  write_board_layout(p, b);
  const BoardLayout back = read_board_layout(p);
  EXPECT_EQ(back.name, b.name);
  EXPECT_EQ(back.type, BoardType::AprilTagGrid);
  EXPECT_EQ(back.tag_family, "tag36h11");
  ASSERT_EQ(back.tags.size(), 20u);
  for (std::size_t i = 0; i < b.tags.size(); ++i) {
    EXPECT_EQ(back.tags[i].id, b.tags[i].id);
    for (int k = 0; k < 4; ++k) {
      EXPECT_LT((back.tags[i].p_BoardCorner_mm[k] - b.tags[i].p_BoardCorner_mm[k]).norm(), 1e-9);
    }
  }
}

TEST(BoardLayout, ChessboardAndMarkerBoard) {
  const BoardLayout c = make_chessboard(9, 6, 25.0, 15.0);
  const auto pts = c.chessboard_corners_mm();
  ASSERT_EQ(pts.size(), 54u);
  EXPECT_NEAR(pts[0].x(), 40.0, 1e-12);
  EXPECT_NEAR(pts[9].y(), 65.0, 1e-12);  // second row, y up
  const fs::path p = temp_dir() / "chess.yaml";
  write_board_layout(p, c);
  const BoardLayout back = read_board_layout(p);
  ASSERT_TRUE(back.chessboard.has_value());
  EXPECT_EQ(back.chessboard->inner_corners_cols, 9);
  EXPECT_DOUBLE_EQ(back.chessboard->square_size_mm, 25.0);

  const BoardLayout m = make_marker_board("tag36h11", 40.0, 60.0, 100, 5.0);
  EXPECT_EQ(m.type, BoardType::MarkerBoard);
  EXPECT_EQ(m.tags.size(), 4u);
  EXPECT_NE(m.find_tag(103), nullptr);
}

TEST(BoardLayout, RejectsBadLayoutsWithLine) {
  const std::string head =
      "arnav_board_version: 1\nname: b\ntype: apriltag_grid\nunits: mm\nboard_width_mm: 100\n"
      "board_height_mm: 100\ntag_family: tag36h11\ntag_size_mm: 20\ntags:\n";
  const std::string tag0 = "  - id: 0\n    corners_mm: [[0,0,0],[20,0,0],[20,20,0],[0,20,0]]\n";
  EXPECT_NO_THROW(parse_board_layout(head + tag0, "b.yaml"));
  // Duplicate id.
  std::string msg = error_of<CalibError>([&] { parse_board_layout(head + tag0 + tag0, "b.yaml"); });
  EXPECT_NE(msg.find("twice"), std::string::npos) << msg;
  // Wrong size, reported at the tag's line (line 10).
  msg = error_of<CalibError>([&] {
    parse_board_layout(head + "  - id: 1\n    corners_mm: [[0,0,0],[25,0,0],[25,25,0],[0,25,0]]\n",
                       "b.yaml");
  });
  EXPECT_NE(msg.find("b.yaml:10"), std::string::npos) << msg;
  // Mirrored corner order.
  msg = error_of<CalibError>([&] {
    parse_board_layout(head + "  - id: 1\n    corners_mm: [[0,20,0],[20,20,0],[20,0,0],[0,0,0]]\n",
                       "b.yaml");
  });
  EXPECT_NE(msg.find("mirrored"), std::string::npos) << msg;
  // Three corners only.
  msg = error_of<CalibError>([&] {
    parse_board_layout(head + "  - id: 1\n    corners_mm: [[0,0,0],[20,0,0],[20,20,0]]\n", "b.yaml");
  });
  EXPECT_NE(msg.find("4 corners"), std::string::npos) << msg;
  // Unknown family, id out of range.
  msg = error_of<CalibError>([&] {
    parse_board_layout(std::string(head).replace(head.find("tag36h11"), 8, "tag99h9") + tag0, "b.yaml");
  });
  EXPECT_NE(msg.find("not supported"), std::string::npos) << msg;
  msg = error_of<CalibError>([&] {
    parse_board_layout(head + "  - id: 600\n    corners_mm: [[0,0,0],[20,0,0],[20,20,0],[0,20,0]]\n",
                       "b.yaml");
  });
  EXPECT_NE(msg.find("outside"), std::string::npos) << msg;
  EXPECT_THROW(make_chessboard(6, 6, 20, 10), CalibError);  // square: ambiguous
  EXPECT_THROW(make_apriltag_grid("tag36h11", 3, 3, 30, 1.0, 0, 5), CalibError);  // no white gap
}

TEST(PoseFile, ParsesCommentsSeparatorsAndRejectsBadLines) {
  const std::string text =
      "# X_NdiTool\n\n1 0 0 10  0 1 0 20  0 0 1 30  0 0 0 1\n"
      "1,0,0,1,0,0,-1,2,0,1,0,3,0,0,0,1\n";
  const auto poses = parse_pose_list(text, "poses.txt");
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[0].line, 3);
  EXPECT_EQ(poses[1].line, 4);
  EXPECT_NEAR(poses[0].X_ParentChild.translation().y(), 20.0, 1e-12);
  EXPECT_NEAR(poses[1].X_ParentChild.linear()(1, 2), -1.0, 1e-12);

  std::string msg = error_of<CalibError>([] { parse_pose_list("1 0 0 0\n1 0 0 10 0 1 0 20 0 0 1 30 0 0 0\n", "p.txt"); });
  EXPECT_NE(msg.find("p.txt:1: expected 16 numbers"), std::string::npos) << msg;
  EXPECT_NE(msg.find("found 4"), std::string::npos) << msg;
  msg = error_of<CalibError>([] { parse_pose_list("# c\n1 0 0 10 0 1 0 20 0 0 1 30 0 0 0\n", "p.txt"); });
  EXPECT_NE(msg.find("p.txt:2:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("found 15"), std::string::npos) << msg;
  msg = error_of<CalibError>([] { parse_pose_list("1 0 0 x 0 1 0 20 0 0 1 30 0 0 0 1\n", "p.txt"); });
  EXPECT_NE(msg.find("'x' is not a finite number"), std::string::npos) << msg;
  msg = error_of<CalibError>([] { parse_pose_list("1 0 0 1 0 1 0 20 0 0 1 30 1 2 3 1\n", "p.txt"); });
  EXPECT_NE(msg.find("last row"), std::string::npos) << msg;
  msg = error_of<CalibError>([] { parse_pose_list("2 0 0 1 0 1 0 20 0 0 1 30 0 0 0 1\n", "p.txt"); });
  EXPECT_NE(msg.find("not a rotation"), std::string::npos) << msg;
  msg = error_of<CalibError>([] { parse_pose_list("nan 0 0 1 0 1 0 20 0 0 1 30 0 0 0 1\n", "p.txt"); });
  EXPECT_NE(msg.find("finite"), std::string::npos) << msg;

  const fs::path p = temp_dir() / "poses.txt";
  write_pose_list(p, {poses[0].X_ParentChild, poses[1].X_ParentChild}, "two poses\nX_NdiTool");
  const auto back = read_pose_list(p);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].line, 3);
  EXPECT_LT((back[1].X_ParentChild.matrix() - poses[1].X_ParentChild.matrix()).norm(), 1e-15);
}

TEST(PointFile, ParsesAndNamesBadLines) {
  const auto pts = parse_point_list("# fiducials\n1 2 3\n4,5,6\n", "f.txt");
  ASSERT_EQ(pts.size(), 2u);
  EXPECT_DOUBLE_EQ(pts[1].z(), 6.0);
  const std::string msg = error_of<CalibError>([] { parse_point_list("1 2 3\n\n1 2\n", "f.txt"); });
  EXPECT_NE(msg.find("f.txt:3: expected 3 numbers"), std::string::npos) << msg;
}
