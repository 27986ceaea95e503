// arnav-calib end to end on temporary files: every command's outputs, exit codes
// (0 done, 2 bad input/usage, 3 calibration rejected) and error messages naming
// file and line.
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/pose_file.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "calibration/vision/test/sim_board.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace fs = std::filesystem;
using namespace arnav::calib;

namespace {

// Removed when the test program exits (set ARNAV_KEEP_TEST_FILES=1 to inspect them).
struct TempDir {
  fs::path path;
  ~TempDir() {
    if (!std::getenv("ARNAV_KEEP_TEST_FILES")) {
      std::error_code ec;
      fs::remove_all(path, ec);
    }
  }
};

fs::path work_dir() {
  static const TempDir dir{[] {
    fs::path d = fs::temp_directory_path() / ("arnav_calib_cli_" + std::to_string(::getpid()));
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
  }()};
  return dir.path;
}

struct Result {
  int code;
  std::string out;
  std::string err;
};

Result run(const std::string& args) {
  const fs::path out = work_dir() / "stdout.txt";
  const fs::path err = work_dir() / "stderr.txt";
  const std::string cmd = std::string(ARNAV_CALIB_EXE) + " " + args + " >" + out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, read_text_file(out, "stdout"), read_text_file(err, "stderr")};
}

std::vector<Eigen::Isometry3d> pivot_poses(const Eigen::Vector3d& tip, const Eigen::Vector3d& pivot, int n, double max_deg) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> a(-max_deg * M_PI / 180, max_deg * M_PI / 180);
  std::normal_distribution<double> g(0, 0.1);
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < n; ++i) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = (Eigen::AngleAxisd(a(rng), Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(a(rng), Eigen::Vector3d::UnitY()))
                     .toRotationMatrix();
    X.translation() = pivot - X.linear() * tip + Eigen::Vector3d(g(rng), g(rng), g(rng));
    poses.push_back(X);
  }
  return poses;
}

}  // namespace

TEST(Cli, HelpAndUsageErrors) {
  EXPECT_EQ(run("--help").code, 0);
  EXPECT_EQ(run("pivot --help").code, 0);
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run("pivot --no-such-option").code, 2);
  EXPECT_EQ(run("board --type hexagon").code, 2);
}

TEST(Cli, BoardWritesPrintFilesAndLayout) {
  const fs::path out = work_dir() / "board";
  const Result r = run("board --type grid --cols 4 --rows 3 --tag-size 25 --spacing 6 --dpi 150 --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const BoardLayout b = read_board_layout(out / "grid_4x3_tag36h11_25mm.yaml");
  EXPECT_EQ(b.tags.size(), 12u);
  const cv::Mat png = cv::imread((out / "grid_4x3_tag36h11_25mm.png").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(png.empty());
  EXPECT_NEAR(png.cols, b.board_width_mm / 25.4 * 150, 1.0);
  EXPECT_TRUE(fs::exists(out / "grid_4x3_tag36h11_25mm.svg"));
  EXPECT_NE(read_text_file(out / "report.txt", "report").find("PRINT AT 100%"), std::string::npos);
  ASSERT_EQ(run("board --type chessboard --cols 9 --rows 6 --square 20 --out " + out.string()).code, 0);
  ASSERT_EQ(run("board --type marker --tag-size 40 --first-id 100 --out " + out.string()).code, 0);
}

TEST(Cli, PivotEndToEndAndBadInput) {
  const Eigen::Vector3d tip(3, -2, 150), pivot(10, 20, -1000);
  const fs::path poses = work_dir() / "pivot_poses.txt";
  write_pose_list(poses, pivot_poses(tip, pivot, 60, 30), "X_NdiTool");
  const fs::path out = work_dir() / "pivot";
  Result r = run("pivot --poses " + poses.string() + " --method ransac --tool Pointer --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(read_text_file(out / "pivot.json", "json"));
  EXPECT_NEAR(j["p_ToolTip_mm"][2].get<double>(), 150.0, 0.3);
  EXPECT_NEAR(j["p_NdiPivot_mm"][0].get<double>(), 10.0, 0.3);
  EXPECT_EQ(j["method"], "ransac");
  EXPECT_GT(j["rms_residual_mm"].get<double>(), 0.0);
  const auto X = read_transform(out / "X_PointerTip.yaml", "X_PointerTip");
  EXPECT_NEAR(X.X_ParentChild.translation().z(), 150.0, 0.3);
  EXPECT_TRUE(fs::exists(out / "pivot_residuals.png"));

  // Wrong column count: exit 2 naming file and line.
  const fs::path bad = work_dir() / "bad_poses.txt";
  std::ofstream(bad) << "# poses\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n1 0 0 0 0 1 0 0 0 0 1 0 0 0 0\n";
  r = run("pivot --poses " + bad.string() + " --out " + out.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find(bad.string() + ":3: expected 16 numbers"), std::string::npos) << r.err;
  r = run("pivot --poses " + (work_dir() / "missing.txt").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("missing.txt: cannot open"), std::string::npos) << r.err;
  // Degenerate: too little rotation -> 3 with advice.
  const fs::path flat = work_dir() / "flat_poses.txt";
  write_pose_list(flat, pivot_poses(tip, pivot, 40, 2), "");
  r = run("pivot --poses " + flat.string() + " --out " + out.string());
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("Tilt the tool"), std::string::npos) << r.err;
}

TEST(Cli, RegisterWritesTransformWithFreAndTre) {
  const std::vector<Eigen::Vector3d> model = {{0, 0, 0}, {80, 0, 5}, {0, 90, -5}, {70, 60, 40}, {30, 20, 70}};
  Eigen::Isometry3d X = Eigen::Translation3d(5, -10, 300) * Eigen::AngleAxisd(0.6, Eigen::Vector3d::UnitZ());
  std::ofstream fixed(work_dir() / "fixed.txt"), moving(work_dir() / "moving.txt");
  for (const auto& p : model) {
    const Eigen::Vector3d q = X * p + Eigen::Vector3d(0.1, -0.05, 0.08);
    fixed << q.x() << " " << q.y() << " " << q.z() << "\n";
    moving << p.x() << "," << p.y() << "," << p.z() << "\n";
  }
  fixed.close();
  moving.close();
  const fs::path out = work_dir() / "register";
  const Result r = run("register --fixed " + (work_dir() / "fixed.txt").string() + " --moving " +
                       (work_dir() / "moving.txt").string() + " --target 40 40 120 --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rec = read_transform(out / "X_RefModel.yaml", "X_RefModel");
  EXPECT_LT((rec.X_ParentChild.translation() - X.translation()).norm(), 0.5);
  EXPECT_NE(r.out.find("predicted TRE at target"), std::string::npos);
  EXPECT_NE(r.out.find("FRE"), std::string::npos);
}

TEST(Cli, HandEyeFromPoseFiles) {
  const Eigen::Isometry3d X_CamNdi = Eigen::Translation3d(300, -200, -100) * Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.2, 1, 0.3).normalized());
  const Eigen::Isometry3d X_ToolBoard = Eigen::Translation3d(-50, -120, 10) * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX());
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  std::vector<Eigen::Isometry3d> ndi, cam;
  for (int i = 0; i < 15; ++i) {
    Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
    X_CamBoard.linear() = (Eigen::AngleAxisd(M_PI + u(rng), Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitY())).toRotationMatrix();
    X_CamBoard.translation() = Eigen::Vector3d(100 * u(rng), 100 * u(rng), 550 + 100 * u(rng));
    cam.push_back(X_CamBoard);
    ndi.push_back(X_CamNdi.inverse() * X_CamBoard * X_ToolBoard.inverse());
  }
  write_pose_list(work_dir() / "he_ndi.txt", ndi, "X_NdiTool");
  write_pose_list(work_dir() / "he_cam.txt", cam, "X_CamBoard");
  const fs::path out = work_dir() / "handeye";
  Result r = run("handeye --ndi-poses " + (work_dir() / "he_ndi.txt").string() + " --cam-poses " +
                 (work_dir() / "he_cam.txt").string() + " --tool Ref --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto cam_ndi = read_transform(out / "X_CamNdi.yaml", "X_CamNdi");
  EXPECT_LT((cam_ndi.X_ParentChild.translation() - X_CamNdi.translation()).norm(), 1e-3);
  const auto ref_board = read_transform(out / "X_RefBoard.yaml", "X_RefBoard");
  EXPECT_LT((ref_board.X_ParentChild.translation() - X_ToolBoard.translation()).norm(), 1e-3);
  EXPECT_NE(r.out.find("axxb-park"), std::string::npos);  // all formulations reported
  // Unpaired files.
  ndi.pop_back();
  write_pose_list(work_dir() / "he_ndi_short.txt", ndi, "");
  r = run("handeye --ndi-poses " + (work_dir() / "he_ndi_short.txt").string() + " --cam-poses " +
          (work_dir() / "he_cam.txt").string() + " --out " + out.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("paired line by line"), std::string::npos) << r.err;
}

TEST(Cli, IntrinsicsFromImageFolderSkipsBadImagesWithReason) {
  const BoardLayout layout = make_apriltag_grid("tag36h11", 6, 5, 28.0, 7.0, 0, 8.0);
  write_board_layout(work_dir() / "grid.yaml", layout);
  const auto board = arnav::calib::test::to_tag_board(layout);
  arnav::markers::CameraModel cam;
  cam.width = 640;
  cam.height = 480;
  cam.K = cv::Matx33d(560, 0, 322, 0, 560, 243, 0, 0, 1);
  cam.distortion = {-0.1, 0.02, 0, 0, 0};
  arnav::camera_sim::SyntheticRenderer renderer(cam);
  arnav::camera_sim::RenderOptions ro;
  ro.noise_sigma = 1.5;
  const fs::path images = work_dir() / "images";
  fs::create_directories(images);
  const double tilts[][2] = {{0, 0}, {28, 0}, {-28, 0}, {0, 28}, {0, -28}, {20, 20}, {-20, -20}, {20, -20}};
  const double offs[][2] = {{0, 0}, {-50, -40}, {50, 40}, {-50, 40}, {50, -40}, {30, 0}, {-30, 0}, {0, 30}};
  for (int i = 0; i < 8; ++i) {
    const auto X = arnav::calib::test::board_facing_camera(layout, 420, tilts[i][0], tilts[i][1], 5.0 * i,
                                                           Eigen::Vector2d(offs[i][0], offs[i][1]));
    const auto frame = renderer.render({{&board, X}}, ro);
    cv::imwrite((images / ("view" + std::to_string(i) + ".png")).string(), frame.image);
  }
  std::ofstream(images / "corrupt.png") << "this is not a PNG";
  cv::imwrite((images / "empty_view.png").string(), cv::Mat(480, 640, CV_8UC1, cv::Scalar(120)));
  const fs::path out = work_dir() / "intrinsics";
  Result r = run("intrinsics --board " + (work_dir() / "grid.yaml").string() + " --images " + images.string() +
                 " --fix-k3 --name bench --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("corrupt.png: unreadable image"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("empty_view.png: 0 tags"), std::string::npos) << r.out;
  const CameraIntrinsics in = read_intrinsics(out / "camera.yaml");
  EXPECT_NEAR(in.camera_matrix(0, 0), 560, 6.0);
  EXPECT_EQ(in.views_used, 8);
  EXPECT_EQ(in.camera_name, "bench");
  EXPECT_TRUE(fs::exists(out / "per_view_error.png"));
  EXPECT_TRUE(fs::exists(out / "coverage.png"));

  // Too few views: exit 3, listing the skipped images.
  const fs::path few = work_dir() / "few";
  fs::create_directories(few);
  fs::copy_file(images / "view0.png", few / "view0.png");
  fs::copy_file(images / "corrupt.png", few / "corrupt.png");
  r = run("intrinsics --board " + (work_dir() / "grid.yaml").string() + " --images " + few.string() + " --out " + out.string());
  EXPECT_EQ(r.code, 3);
  EXPECT_NE(r.err.find("1 usable views"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("corrupt.png"), std::string::npos) << r.err;
  // Unreadable layout names file and line.
  std::ofstream(work_dir() / "bad_layout.yaml") << "arnav_board_version: 1\nname: x\ntype: grid\n";
  r = run("intrinsics --board " + (work_dir() / "bad_layout.yaml").string() + " --images " + few.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("bad_layout.yaml:3"), std::string::npos) << r.err;
}

TEST(Cli, ArAccuracySimulationAndMeasurements) {
  const fs::path out = work_dir() / "ar";
  Result r = run("ar-accuracy --simulate --runs 1 --trials 3 --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(read_text_file(out / "ar_summary.json", "json"));
  EXPECT_EQ(j["per_angle"].size(), 4u);
  EXPECT_EQ(j["all"]["n"], 12);
  EXPECT_TRUE(fs::exists(out / "ar_accuracy.png"));
  EXPECT_TRUE(fs::exists(out / "ar_trials.csv"));
  std::ofstream(work_dir() / "meas.csv") << "angle,xv,yv,zv,xr,yr,zr\n0,1,2,3,1,2,4\n0,1,2,3,1,2,5\n30,0,0,0,3,4,0\n";
  r = run("ar-accuracy --measurements " + (work_dir() / "meas.csv").string() + " --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("0 deg: 1.500 +- 0.707 mm"), std::string::npos) << r.out;
  std::ofstream(work_dir() / "meas_bad.csv") << "0,1,2,3,1,2,4\n0,1,2,3,1,2\n";
  r = run("ar-accuracy --measurements " + (work_dir() / "meas_bad.csv").string() + " --out " + out.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("meas_bad.csv:2: expected 7 columns"), std::string::npos) << r.err;
}

TEST(Cli, HandEyeFromRenderedImages) {
  // The hybrid target rendered by the synthetic camera at 10 poses (one image without the
  // board: its pose pair is skipped with the reason and the pose file line).
  const BoardLayout layout = make_marker_board("tag36h11", 40.0, 50.0, 100, 5.0);
  write_board_layout(work_dir() / "marker.yaml", layout);
  const auto board = arnav::calib::test::to_tag_board(layout);
  arnav::markers::CameraModel cam;
  cam.width = 800;
  cam.height = 600;
  cam.K = cv::Matx33d(700, 0, 401, 0, 700, 297, 0, 0, 1);
  cam.distortion = {-0.05, 0.01, 0, 0, 0};
  CameraIntrinsics in;
  in.image_width = 800;
  in.image_height = 600;
  in.camera_matrix = cam.K;
  in.distortion = cam.distortion;
  in.calibration_date = "test";
  write_intrinsics(work_dir() / "he_camera.yaml", in);
  const Eigen::Isometry3d X_CamNdi = Eigen::Translation3d(600, -300, -250) * Eigen::AngleAxisd(2.2, Eigen::Vector3d(0.3, 1, 0.2).normalized());
  const Eigen::Isometry3d X_ToolBoard = Eigen::Translation3d(-60, -150, 10) * Eigen::AngleAxisd(0.15, Eigen::Vector3d::UnitY());
  arnav::camera_sim::SyntheticRenderer renderer(cam);
  arnav::camera_sim::RenderOptions ro;
  ro.noise_sigma = 1.0;
  const fs::path images = work_dir() / "he_images";
  fs::create_directories(images);
  const double tilts[][2] = {{0, 0}, {30, 0}, {-30, 0}, {0, 30}, {0, -30}, {25, 25}, {-25, 25}, {25, -25}, {-25, -25}, {0, 0}};
  std::vector<Eigen::Isometry3d> ndi;
  for (int i = 0; i < 10; ++i) {
    const auto X_CamBoard = arnav::calib::test::board_facing_camera(layout, 450 + 10 * i, tilts[i][0], tilts[i][1], 10.0 * i,
                                                                    Eigen::Vector2d(10.0 * (i % 3), -8.0 * (i % 2)));
    ndi.push_back(X_CamNdi.inverse() * X_CamBoard * X_ToolBoard.inverse());
    cv::Mat image = renderer.render({{&board, X_CamBoard}}, ro).image;
    if (i == 9) image.setTo(cv::Scalar(100));  // the target left the view
    cv::imwrite((images / ("he" + std::to_string(i) + ".png")).string(), image);
  }
  write_pose_list(work_dir() / "he_img_ndi.txt", ndi, "X_NdiTool of the hybrid target");
  const fs::path out = work_dir() / "handeye_images";
  const Result r = run("handeye --ndi-poses " + (work_dir() / "he_img_ndi.txt").string() + " --images " + images.string() +
                       " --intrinsics " + (work_dir() / "he_camera.yaml").string() + " --board " +
                       (work_dir() / "marker.yaml").string() + " --tool Ref --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("he9.png: 0 tags"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("he_img_ndi.txt:11 skipped"), std::string::npos) << r.out;  // header comment is line 1
  const auto cam_ndi = read_transform(out / "X_CamNdi.yaml", "X_CamNdi");
  // Only the camera's corner error remains: the hand-eye must be close to the truth.
  EXPECT_LT((cam_ndi.X_ParentChild.translation() - X_CamNdi.translation()).norm(), 3.0);
  EXPECT_LT(Eigen::AngleAxisd(cam_ndi.X_ParentChild.linear().transpose() * X_CamNdi.linear()).angle() * 180 / M_PI, 0.3);
  const auto ref_board = read_transform(out / "X_RefBoard.yaml", "X_RefBoard");
  EXPECT_LT((ref_board.X_ParentChild.translation() - X_ToolBoard.translation()).norm(), 3.0);
}
