// The deforming phantom end to end on the bench (short): ar_phantom_session.sh runs
// arnav-phantom-record (the reference deformation), then arnav-appliance with the synthetic
// camera filming the phantom and the simulated Polaris moving the tool along the recorded
// path, arnav-host and arnav-ar-error, in a private network namespace. Checked: the camera
// published frames the host displayed, the ground truth holds the deformed tumour centroid
// of every frame (in Cam, and in px exactly where cv::projectPoints puts it), the phantom
// moved the tumour, and arnav-ar-error scored the overlay against the deformed truth with
// the rigid-overlay comparison; the host couples the tracked grasper to its model
// (tools.grasper), so its overlay is clearly better than a rigid overlay (this fails when
// the coupling is removed: the host's error then equals the rigid one).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "appliance/synthetic_camera/ground_truth.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

std::string env(const char* name, const char* fallback) {
  const char* v = std::getenv(name);
  return v ? v : fallback;
}

TEST(ArPhantomSession, CameraPublishesTheDeformingPhantomWithGroundTruth) {
  ARNAV_BENCH_OR_SKIP(::geteuid() != 0 ? "needs root for a private network namespace (unshare --net)" : "");
  const std::filesystem::path out = std::filesystem::temp_directory_path() / ("arnav-ar-phantom-" + std::to_string(::getpid()));
  std::filesystem::remove_all(out);
  const std::string script = env("ARNAV_SOURCE_DIR", ".") + std::string("/hil_tests/scenarios/ar_phantom_session.sh");
  const std::string cmd = script + " " + env("ARNAV_BINARY_DIR", ".") + " " + out.string() + " 90 >" + (out.string() + ".log") + " 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream log_in(out.string() + ".log");
  std::stringstream log;
  log << log_in.rdbuf();
  ASSERT_EQ(rc, 0) << log.str();

  // Ground truth: version 2, per frame the board and the deformed targets.
  const auto rows = camera_sim::read_ground_truth(out / "ground_truth.csv");
  std::map<std::int64_t, int> boards, targets;
  const calib::CameraIntrinsics cam = calib::read_intrinsics(out / "camera.yaml");
  double max_move_px = 0.0;
  std::map<std::int64_t, cv::Point2d> first_px;
  for (const auto& r : rows) {
    if (r.board == "liver_marker") ++boards[r.sequence];
    if (r.board != "target:tumour_centroid") continue;
    ++targets[r.sequence];
    ASSERT_TRUE(r.has_px);
    const Eigen::Vector3d p = r.X_CamBoard.translation();
    std::vector<cv::Point2d> px;
    cv::projectPoints(std::vector<cv::Point3d>{{p.x(), p.y(), p.z()}}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                      cv::Mat(cam.camera_matrix), cv::Mat(cam.distortion), px);
    EXPECT_NEAR(r.u_px, px[0].x, 1e-3);
    EXPECT_NEAR(r.v_px, px[0].y, 1e-3);
    EXPECT_EQ(r.tags_visible, 1);  // the tumour is in the image
    if (first_px.empty()) first_px[0] = {r.u_px, r.v_px};
    max_move_px = std::max(max_move_px, cv::norm(cv::Point2d(r.u_px, r.v_px) - first_px[0]));
  }
  ASSERT_GE(boards.size(), 10u) << log.str();
  EXPECT_EQ(targets.size(), boards.size());
  EXPECT_GT(max_move_px, 2.0) << "the phantom should move the tumour in the image";

  // The host received and displayed the camera's frames.
  std::ifstream csv(out / "recording" / "overlay.csv");
  std::string line;
  int csv_rows = -1;
  while (std::getline(csv, line)) ++csv_rows;
  EXPECT_GE(csv_rows, 10) << log.str();

  // arnav-ar-error against the deformed truth, with the rigid comparison.
  std::ifstream j_in(out / "ar_error.json");
  const nlohmann::json j = nlohmann::json::parse(j_in);
  EXPECT_NE(j["truth"].get<std::string>().find("deforming phantom"), std::string::npos);
  EXPECT_GE(j["frames_evaluated"].get<int>(), 10);
  ASSERT_TRUE(j.contains("rigid_overlay"));
  EXPECT_GT(j["tumour_displacement_mm"]["max"].get<double>(), 1.0);
  EXPECT_GT(j["rigid_overlay"]["ar_error_px"]["max"].get<double>(), 1.0);
  // The grasp: the host grasped once (the grasper rests on the tissue before it pulls) and
  // its overlay follows the deformation: mean and p95 clearly below the rigid overlay's.
  std::ifstream h_in(out / "host.json");
  const nlohmann::json h = nlohmann::json::parse(h_in);
  ASSERT_TRUE(h.contains("navigation") && h["navigation"].contains("grasper")) << log.str();
  const nlohmann::json& g = h["navigation"]["grasper"];
  EXPECT_GE(g["grasps"].get<int>(), 1);
  EXPECT_GT(g["max_tip_travel_mm"].get<double>(), 5.0);
  const double host_mean = j["ar_error_mm"]["mean"].get<double>(), rigid_mean = j["rigid_overlay"]["ar_error_mm"]["mean"].get<double>();
  const double host_p95 = j["ar_error_mm"]["p95"].get<double>(), rigid_p95 = j["rigid_overlay"]["ar_error_mm"]["p95"].get<double>();
  EXPECT_GT(rigid_mean, 1.0) << "the phantom must deform enough for the comparison to mean something";
  EXPECT_LT(host_mean, 0.6 * rigid_mean) << log.str();
  EXPECT_LT(host_p95, 0.75 * rigid_p95) << log.str();
  std::filesystem::remove_all(out);
  std::filesystem::remove(out.string() + ".log");
}

}  // namespace
}  // namespace arnav::hil
