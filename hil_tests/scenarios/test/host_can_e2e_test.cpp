// arnav-host on the CAN bench: the real foot pedal path (arnav-can-sim -> SocketCAN through
// the test-only can_shim -> arnav-appliance -> ARNAV_INPUT / ARNAV_INPUT_STATE over LCM udpm
// in the bench's private network namespace) arms cutting in a navigation session. The test
// publishes the scalpel's poses (in Ref, as the appliance's tracker path does) moving through
// the coarse liver; the session (no camera: the scalpel poses drive the cut stage) cuts only
// while the pedal is held. Checked from the session's --summary-json: one press seen, the
// snapshots arriving, cutting steps made only in the pressed window, cut faces, the cut-path
// error within the cutter's snapping bound. Then live registration: the test's pointer
// holds still on each model landmark (Ref = a known X_RefModel applied to it) and the
// pedal's accept switch is pressed on the bus: the session takes every landmark, solves
// the registration and reports FRE/TRE; X_RefModel is recovered.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <thread>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>

#include "arnav/tool_pose_t.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "hil_tests/bench/child_process.hpp"
#include "hil_tests/scenarios/can_run.hpp"
#include "hil_tests/scenarios/host_run.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"
#include "protocol/testing/child_process.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

std::string data(const std::string& rel) { return arnav::testing::data_dir() + "/" + rel; }

// A valid pose of `tool` in Ref as the appliance's NDI path publishes it (device frame k).
tool_pose_t ref_pose_msg(const std::string& tool, const Eigen::Isometry3d& X_RefTool, std::int64_t k) {
  tool_pose_t m{};
  m.tool_name = tool;
  m.source = tool_pose_t::SOURCE_NDI;
  m.frame_parent = "Ref";
  m.frame_child = "Tool";
  set_pose(m, X_RefTool);
  m.status = tool_pose_t::STATUS_VALID;
  m.device_frame_number = k;
  m.receive_time_mono_us = m.publish_time_mono_us = monotonic_us();
  m.sequence = k;
  return m;
}

TEST(HostCanE2e, ThePedalHeldOnTheCanBusArmsCuttingInTheSession) {
  CanRun run;
  CanRunOptions o;
  o.path = CanPath::SocketCan;
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_ALIVE") >= 1; }, 30.0))
      << run.lcm().event_log() << run.logs();
  const std::filesystem::path dir = run.dir();
  calib::RigidTransformRecord reg;
  reg.parent_frame = "Ref";
  reg.child_frame = "Model";
  reg.X_ParentChild = Eigen::Isometry3d::Identity();
  reg.method = "test";
  reg.date = "2026-11-25T00:00:00Z";
  calib::write_transform(dir / "X_RefModel.yaml", reg);
  {
    std::ofstream s(dir / "session.yaml");
    s << "arnav_session_version: 1\nlcm_url: \"" << CanRun::kLcmUrl << "\"\nsecurity: off\n"
      << "scene: " << data("liver/liver_coarse_cut.scene.yaml") << "\nregistration: X_RefModel.yaml\n"
      << "tools:\n  reference: {name: liver_marker}\n  scalpel: {name: scalpel, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 60]}}\n"
      << "inputs: {cut_enable: {input: pedal_cut, state_stale_after_ms: 1500}}\nmodel: {rate_hz: 60, gravity: false}\n";
  }
  const std::string summary = (dir / "host.json").string();
  std::unique_ptr<ChildProcess> host;
  ASSERT_TRUE(start_host(dir, host)) << host->log_tail();
  // The scalpel: upright blade, tip 18 mm above the tumour's centre height, 20 mm beside it,
  // sweeping 50 mm back and forth through the liver at 60 Hz.
  lcm::LCM bus(CanRun::kLcmUrl);
  ASSERT_TRUE(bus.good());
  std::atomic<bool> stop{false};
  std::atomic<int> sent{0};
  std::thread tracker([&] {
    const std::int64_t t0 = monotonic_us();
    for (std::int64_t k = 0; !stop.load(); ++k) {
      const double t = static_cast<double>(monotonic_us() - t0) * 1e-6;
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.translation() = Eigen::Vector3d(70 + 25 * std::sin(2 * M_PI * t / 4.0), 140, 158);
      const tool_pose_t m = ref_pose_msg("scalpel", X, k);
      bus.publish(channels::pose("scalpel"), &m);
      ++sent;
      std::this_thread::sleep_for(std::chrono::microseconds(16'667));
    }
  });
  std::this_thread::sleep_for(std::chrono::seconds(2));  // pedal up: the blade only pushes
  const int before = sent.load();
  ASSERT_EQ(run.inject("press pedal_cut"), "OK");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_inputs("pedal_cut", input_event_t::STATE_PRESSED) >= 1; }, 5.0))
      << run.lcm().event_log();
  std::this_thread::sleep_for(std::chrono::seconds(3));
  ASSERT_EQ(run.inject("release pedal_cut"), "OK");
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_inputs("pedal_cut", input_event_t::STATE_RELEASED) >= 1; }, 5.0));
  const int during = sent.load() - before;
  std::this_thread::sleep_for(std::chrono::seconds(1));
  stop = true;
  tracker.join();
  ASSERT_EQ(host->stop(15, 30.0), 0) << host->log_tail();
  std::ifstream in(summary);
  ASSERT_TRUE(in) << host->log_tail();
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_TRUE(j.contains("navigation")) << j.dump(1);
  const auto& nav = j["navigation"];
  std::printf("[ host-can ] %s\n", nav["cutting"].dump().c_str());
  EXPECT_EQ(nav["inputs"]["by_input"]["pedal_cut"]["presses"].get<int>(), 1);
  EXPECT_GT(nav["inputs"]["messages"].get<int>(), 4) << "changes and ARNAV_INPUT_STATE snapshots";
  const auto& cut = nav["cutting"];
  // Cutting only while the pedal was held (about 3 s of 6 s of poses; the press and
  // release take a debounce and a bus hop).
  EXPECT_GT(cut["frames_cutting"].get<int>(), during / 2);
  EXPECT_LE(cut["frames_cutting"].get<int>(), during + 30);
  EXPECT_GT(cut["cut_steps"].get<int>(), 0);
  EXPECT_GT(cut["cut_faces"].get<int>(), 0);
  EXPECT_GT(cut["cut_area_mm2"].get<double>(), 100.0);
  EXPECT_EQ(cut["disarmed_by_stale_input"]["episodes"].get<int>(), 0) << "snapshots keep the state fresh";
  EXPECT_LT(cut["path_error_mm"]["p95"].get<double>(), 5.0);
}

TEST(HostCanE2e, LiveLandmarkRegistrationAcceptedByTheCanPedal) {
  CanRun run;
  CanRunOptions o;
  o.path = CanPath::SocketCan;
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.lcm().wait_for([](const CanCapture& c) { return c.count_events("CAN_DEVICE_ALIVE") >= 1; }, 30.0))
      << run.lcm().event_log() << run.logs();
  const std::filesystem::path dir = run.dir();
  const std::vector<Eigen::Vector3d> landmarks = {{40, 130, 120}, {110, 190, 185}, {20, 210, 150}, {95, 120, 160}};
  {
    std::ofstream lm(dir / "landmarks.csv");
    lm << "name,x_mm,y_mm,z_mm\n";
    for (std::size_t i = 0; i < landmarks.size(); ++i)
      lm << "L" << i << ',' << landmarks[i].x() << ',' << landmarks[i].y() << ',' << landmarks[i].z() << '\n';
  }
  {
    std::ofstream s(dir / "session.yaml");
    s << "arnav_session_version: 1\nlcm_url: \"" << CanRun::kLcmUrl << "\"\nsecurity: off\n"
      << "scene: " << data("liver/liver_coarse.scene.yaml") << "\n"
      << "registration:\n  live: {landmarks: landmarks.csv, pointer: pointer, accept: pedal_accept, window_ms: 150}\n"
      << "tools:\n  reference: {name: liver_marker}\n  pointer: {name: pointer}\nmodel: {rate_hz: 30}\n";
  }
  const std::string summary = (dir / "host.json").string();
  std::unique_ptr<ChildProcess> host;
  ASSERT_TRUE(start_host(dir, host)) << host->log_tail();
  Eigen::Isometry3d X_RefModel = Eigen::Isometry3d::Identity();
  X_RefModel.linear() = Eigen::AngleAxisd(0.6, Eigen::Vector3d(0.2, 1, 0.3).normalized()).toRotationMatrix();
  X_RefModel.translation() = Eigen::Vector3d(-30, 45, -120);
  lcm::LCM bus(CanRun::kLcmUrl);
  ASSERT_TRUE(bus.good());
  std::atomic<bool> stop{false};
  std::atomic<int> target{0};
  std::thread pointer([&] {
    for (std::int64_t k = 0; !stop.load(); ++k) {
      Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
      X.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
      X.translation() = X_RefModel * landmarks[static_cast<std::size_t>(std::min(target.load(), 3))];
      const tool_pose_t m = ref_pose_msg("pointer", X, k);
      bus.publish(channels::pose("pointer"), &m);
      std::this_thread::sleep_for(std::chrono::microseconds(16'667));
    }
  });
  for (int i = 0; i < 4; ++i) {
    target = i;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // on the landmark, still
    ASSERT_EQ(run.inject("press pedal_accept"), "OK");
    ASSERT_TRUE(run.lcm().wait_for([&](const CanCapture& c) { return c.count_inputs("pedal_accept", input_event_t::STATE_PRESSED) >= static_cast<std::size_t>(i + 1); },
                                   5.0))
        << run.lcm().event_log();
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    ASSERT_EQ(run.inject("release pedal_accept"), "OK");
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  stop = true;
  pointer.join();
  ASSERT_EQ(host->stop(15, 30.0), 0) << host->log_tail();
  std::ifstream in(summary);
  ASSERT_TRUE(in) << host->log_tail();
  const nlohmann::json j = nlohmann::json::parse(in);
  const auto& reg = j["navigation"]["registration"];
  std::printf("[ host-can ] registration %s\n", reg.dump().c_str());
  ASSERT_TRUE(reg["done"].get<bool>()) << reg.dump() << host->log_tail();
  EXPECT_EQ(reg["landmarks_taken"].get<int>(), 4);
  EXPECT_EQ(reg["refused"].get<int>(), 0);
  EXPECT_LT(reg["fre_mm"].get<double>(), 0.01) << "noise-free poses";
  const auto m = reg["X_RefModel"].get<std::vector<double>>();
  Eigen::Matrix4d X;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) X(r, c) = m[static_cast<std::size_t>(4 * r + c)];
  EXPECT_LT((X - X_RefModel.matrix()).cwiseAbs().maxCoeff(), 1e-3) << X;
}

}  // namespace
}  // namespace arnav::hil
