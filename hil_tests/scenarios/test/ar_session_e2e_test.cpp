// The AR navigation session end to end on the bench, headless: arnav-appliance with the
// synthetic camera (1280x720, a barrel lens, the liver reference board moving in and out
// of view) publishes board poses and JPEG frames over LCM udpm in a private network
// namespace; lcm-logger records the bus; arnav-host SESSION.yaml runs the model and the
// overlay and records overlay.csv + video + contact sheet. Checked: the tumour drawn where
// the ground truth projects it (AR error targets), a "tracking lost" banner on every frame
// without the board and none frozen, recovery, the CSV complete (every frame the camera
// made), no frame dropped by the host; then --replay of the log gives the same overlay;
// a bad session file exits 2 naming file:line.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "calibration/lib/board_layout.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/bench/namespaces.hpp"
#include "hil_tests/scenarios/ar_error.hpp"
#include "protocol/testing/child_process.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

const char* kUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";

std::string bin(const std::string& rel) { return arnav::testing::binary_path(rel); }
std::string data(const std::string& rel) { return arnav::testing::data_dir() + "/" + rel; }
std::string slurp(const std::filesystem::path& p) { return arnav::testing::read_text(p); }

struct Bench {
  std::filesystem::path dir;
  Bench() {
    dir = make_temp_dir("arnav-ar-e2e");
    const calib::BoardLayout board = calib::make_marker_board("tag36h11", 40.0, 30.0, 10, 8.0);
    calib::write_board_layout(dir / "marker_board.yaml", board);
    calib::CameraIntrinsics cam;
    cam.camera_name = "bench";
    cam.image_width = 1280;
    cam.image_height = 720;
    cam.camera_matrix = cv::Matx33d(1050, 0, 639.5, 0, 1050, 359.5, 0, 0, 1);
    cam.distortion = {-0.08, 0.02, 0, 0, 0};
    cam.calibration_date = "2026-11-25T00:00:00Z";
    calib::write_intrinsics(dir / "camera.yaml", cam);
    // The liver's tumour 40 mm behind the board's centre (arnav-calib boards: z into the sheet).
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    int n = 0;
    for (const auto& t : board.tags)
      for (const auto& c : t.p_BoardCorner_mm) {
        centre += c;
        ++n;
      }
    centre /= n;
    calib::RigidTransformRecord reg;
    reg.parent_frame = "Ref";
    reg.child_frame = "Model";
    reg.X_ParentChild.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();  // Model +z (up) out of the sheet
    reg.X_ParentChild.translation() = centre + Eigen::Vector3d(0, 0, 40) - reg.X_ParentChild.linear() * Eigen::Vector3d(70, 160, 140);
    reg.method = "bench: the phantom is fixed to its board";
    reg.date = "2026-11-25T00:00:00Z";
    calib::write_transform(dir / "X_RefModel.yaml", reg);
  }
  std::string appliance(int fps, int frames) const {
    const auto p = dir / "appliance.yaml";
    std::ofstream(p) << "lcm_url: \"" << kUrl << "\"\nsecurity: off\n"
                     << "camera:\n  name: bench\n  source: synthetic\n  fps: " << fps << "\n  intrinsics: camera.yaml\n"
                     << "  detector: {family: tag36h11, decimate: 2, threads: 1}\n"
                     << "  publish_frames: {every: 1, jpeg_quality: 80}\n"
                     << "  tools:\n    - name: liver_marker\n      board: marker_board.yaml\n"
                     << "  synthetic:\n    frames: " << frames << "\n    ground_truth: ground_truth.csv\n    noise_sigma: 1.5\n"
                     << "    blur_sigma_px: 0.5\n    boards:\n      - tool: liver_marker\n"
                     // x swings past the image edge once per period: the board leaves the view and comes back.
                     << "        trajectory: {distance_mm: 450, amplitude_mm: [330, 40, 40], offset_mm: [0, 0], period_s: 4, tilt_deg: 15, spin_deg: 10}\n";
    return p.string();
  }
  std::string session() const {
    const auto p = dir / "session.yaml";
    std::ofstream(p) << "arnav_session_version: 1\nlcm_url: \"" << kUrl << "\"\nsecurity: off\n"
                     << "scene: " << data("liver/liver_coarse.scene.yaml") << "\n"
                     << "registration: X_RefModel.yaml\n"
                     << "tools:\n  reference: {name: liver_marker, stale_after_ms: 150}\n"
                     << "camera:\n  name: bench\n  intrinsics: camera.yaml\n  pose_from: reference\n"
                     << "model: {rate_hz: 30, gravity: false}\n"
                     << "surfaces: {publish_rate_hz: 0}\n";  // nothing here reads the model's surfaces
    return p.string();
  }
};

TEST(ArSessionEndToEnd, OverlayMatchesGroundTruthBannersRecordingAndReplay) {
  const std::string why = enter_bench_namespaces();
  ARNAV_BENCH_OR_SKIP(why);
  ARNAV_BENCH_OR_SKIP(std::filesystem::exists(bin("host/app/arnav-host")) ? "" : "arnav-host not built");
  Bench b;
  const std::string session = b.session();
  const auto rec = b.dir / "rec";
  ChildProcess logger({"/usr/bin/lcm-logger", std::string("--lcm-url=") + kUrl, "-f", (b.dir / "session.lcmlog").string()}, {},
                      (b.dir / "logger.log").string());
  ChildProcess host({bin("host/app/arnav-host"), session, "--record", rec.string(), "--quiet", "--summary", "--summary-json",
                     (b.dir / "host.json").string()},
                    {}, (b.dir / "host.log").string(), true);
  bool ready = false;
  for (int i = 0; i < 200 && !ready; ++i) {
    const auto line = host.read_line(1.0);
    if (line && line->find("session ready") != std::string::npos) ready = true;
    if (!host.running()) break;
  }
  ASSERT_TRUE(ready) << host.log_tail();
  const int frames = 120;  // 8 s at 15 Hz: two board excursions out of view
  ChildProcess appliance({bin("appliance/app/arnav-appliance"), b.appliance(15, frames)}, {}, (b.dir / "appliance.log").string());
  const auto rc = appliance.wait(120.0);
  ASSERT_TRUE(rc.has_value()) << "appliance did not finish";
  EXPECT_EQ(*rc, 0) << slurp(b.dir / "appliance.log");
  std::this_thread::sleep_for(std::chrono::milliseconds(800));  // last frames rendered and recorded
  EXPECT_EQ(host.stop(), 0) << host.log_tail();
  logger.stop(2);

  const ArErrorReport live = evaluate_ar_error(session, (b.dir / "ground_truth.csv").string(), (rec / "overlay.csv").string());
  const nlohmann::json s = live.summary();
  std::cout << "AR session summary: " << s.dump() << std::endl;
  RecordProperty("ar_error_mm_mean_x1000", static_cast<int>(1000 * s["ar_error_mm"]["mean"].get<double>()));
  // Every frame the camera made was displayed and recorded; none dropped by the host. (The
  // synthetic camera skips the frames it renders too late on a loaded machine, as a real
  // driver overwrites buffers: the ground truth lists the frames it made.)
  EXPECT_GT(live.truth_frames, 20);
  // A frame is only ever missing from the recording when the host counted it as dropped
  // (its renderer still busy with the previous one); on this shared 2-core machine that
  // happens under load, so the count is checked here and the rate is a benchmark
  // (arnav-host-latency-bench, docs/benchmarks.md).
  const nlohmann::json host_summary = nlohmann::json::parse(slurp(b.dir / "host.json"));
  EXPECT_EQ(host_summary["navigation"]["frames_dropped"].get<std::int64_t>(), live.missing_in_csv);
  EXPECT_LE(live.missing_in_csv, live.truth_frames / 10);
  EXPECT_EQ(host_summary["navigation"]["decode_failures"], 0);
  // Targets of issue 12 (bench, rigid phantom): mean <= 1 mm, p95 <= 2 mm at the organ.
  EXPECT_GT(s["frames_evaluated"].get<std::int64_t>(), live.truth_frames / 3);
  EXPECT_LE(s["ar_error_mm"]["mean"].get<double>(), 1.0);
  EXPECT_LE(s["ar_error_mm"]["p95"].get<double>(), 2.0);
  // Never a frozen overlay: every tumour drawn with the board pose of its own frame; a
  // banner flag on every frame without overlay; the overlay back on clear views.
  int banner_frames = 0, recoveries = 0;
  bool was_lost = false;
  for (const auto& f : live.frames) {
    const bool lost = f.flags.find("reference_") != std::string::npos;
    if (f.drawn) {
      EXPECT_TRUE(f.own_pose) << "frame " << f.sequence << " drawn with an older pose";
    } else {
      EXPECT_TRUE(lost) << "frame " << f.sequence << " has no overlay and no banner";
    }
    banner_frames += lost ? 1 : 0;
    if (was_lost && f.drawn) ++recoveries;
    was_lost = lost;
  }
  EXPECT_GT(banner_frames, 5) << "the board should have left the view";
  EXPECT_GE(recoveries, 1);
  EXPECT_LE(live.visible_without_overlay, 2) << "clear views must show the overlay";
  EXPECT_TRUE(std::filesystem::file_size(rec / "overlay.avi") > 10000);
  EXPECT_TRUE(std::filesystem::exists(rec / "contact_sheet.png"));

  // Replay of the log, as fast as possible: the same overlay, frame by frame.
  const auto rec2 = b.dir / "replay";
  ChildProcess replay({bin("host/app/arnav-host"), session, "--replay", (b.dir / "session.lcmlog").string(), "--replay-speed", "0",
                       "--record", rec2.string(), "--quiet"},
                      {}, (b.dir / "replay.log").string());
  const auto rrc = replay.wait(300.0);
  ASSERT_TRUE(rrc.has_value());
  ASSERT_EQ(*rrc, 0) << slurp(b.dir / "replay.log");
  const ArErrorReport again = evaluate_ar_error(session, (b.dir / "ground_truth.csv").string(), (rec2 / "overlay.csv").string());
  // Replay renders every logged frame (nothing to drop offline): all the camera made.
  EXPECT_EQ(again.missing_in_csv, 0);
  std::map<std::int64_t, ArFrame> replayed;
  for (const auto& f : again.frames) replayed[f.sequence] = f;
  for (const auto& f : live.frames) {
    ASSERT_TRUE(replayed.count(f.sequence)) << "frame " << f.sequence;
    EXPECT_EQ(replayed[f.sequence].drawn, f.drawn) << "frame " << f.sequence;
    EXPECT_NEAR(replayed[f.sequence].error_px, f.error_px, 1e-3) << "frame " << f.sequence;
  }

  // A bad session file: exit 2 naming file and line.
  std::ofstream(b.dir / "bad.yaml") << "arnav_session_version: 1\ncamera:\n  name: bench\n  intrinsic: camera.yaml\n";
  ChildProcess bad({bin("host/app/arnav-host"), (b.dir / "bad.yaml").string()}, {}, (b.dir / "bad.log").string());
  EXPECT_EQ(bad.wait(30.0).value_or(-1), 2);
  EXPECT_NE(slurp(b.dir / "bad.log").find("bad.yaml:4: key 'camera.intrinsic': unknown key"), std::string::npos)
      << slurp(b.dir / "bad.log");
  if (!std::getenv("ARNAV_HIL_KEEP")) std::filesystem::remove_all(b.dir);
}

}  // namespace
}  // namespace arnav::hil
