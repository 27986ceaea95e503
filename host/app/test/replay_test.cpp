// arnav-host --replay on an lcm-logger log written here (lcm::LogFile, the same format):
// the navigation session re-run offline is deterministic (two replays give the same
// overlay.csv except the wall-clock columns), draws the tumour where the frame chain puts
// it, shows the stale banner while the board's poses are missing from the log, and bad
// inputs exit 2. No network needed.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>

#include <lcm/lcm-cpp.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "arnav/input_event_t.hpp"
#include "host/app/recorder.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/scene/scene.hpp"
#include "protocol/channels.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

std::string arnav_host() {
  const char* d = std::getenv("ARNAV_BINARY_DIR");
  return std::string(d ? d : ".") + "/host/app/arnav-host";
}

int run(const std::string& cmd, std::string* output = nullptr) {
  const std::string full = cmd + " 2>&1";
  FILE* p = ::popen(full.c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  std::string out;
  while (std::fgets(buf, sizeof buf, p)) out += buf;
  const int status = ::pclose(p);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

template <class Msg>
void log_event(lcm::LogFile& log, const std::string& channel, const Msg& msg, std::int64_t wall_us) {
  std::vector<std::uint8_t> buf(static_cast<std::size_t>(msg.getEncodedSize()));
  msg.encode(buf.data(), 0, static_cast<int>(buf.size()));
  lcm::LogEvent ev{};
  ev.timestamp = wall_us;
  ev.channel = channel;
  ev.datalen = static_cast<std::int32_t>(buf.size());
  ev.data = buf.data();
  log.writeEvent(&ev);
}

std::string slurp_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// overlay.csv's columns (csv_header) and which of them hold times measured on this run's
// clock (render, decode, shown: they differ between two replays).
std::vector<std::string> csv_columns() {
  std::vector<std::string> c;
  std::stringstream ss(csv_header());
  for (std::string x; std::getline(ss, x, ',');) c.push_back(x);
  return c;
}
bool measured_column(std::size_t col) {
  static const std::vector<std::string> c = csv_columns();
  const std::string& n = c.at(col);
  return n == "render_done_mono_us" || n == "motion_to_photon_ms" || n == "decode_done_mono_us" || n == "shown_mono_us";
}

std::vector<std::vector<std::string>> read_csv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::vector<std::vector<std::string>> rows;
  std::getline(in, line);
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string x;
    while (std::getline(ss, x, ',')) f.push_back(x);
    if (!line.empty() && line.back() == ',') f.emplace_back();
    rows.push_back(f);
  }
  return rows;
}

TEST(Replay, DeterministicOverlayWithBannersFromAnLcmLoggerLog) {
  SessionFolder f("replay");
  const std::string session = f.session();
  const std::string log_path = (f.dir / "session.lcmlog").string();
  constexpr std::int64_t kWall = 1'700'000'000'000'000;
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    for (std::int64_t k = 0; k < 60; ++k) {
      const std::int64_t t = 1'000'000 + k * 16'667;
      // Frames 20-39: the board's poses are not in the log (the appliance stopped sending).
      if (k < 20 || k >= 40)
        log_event(log, channels::pose("liver_marker"), pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t + 500 + kWall + 100);
      log_event(log, channels::frame("cam0"), frame_msg(k, t), t + 4000 + kWall);
    }
  }
  std::string out;
  ASSERT_EQ(run(arnav_host() + " " + session + " --replay " + log_path + " --replay-speed 0 --quiet --record " + (f.dir / "a").string(), &out), 0)
      << out;
  ASSERT_EQ(run(arnav_host() + " " + session + " --replay " + log_path + " --replay-speed 0 --quiet --record " + (f.dir / "b").string(), &out), 0)
      << out;
  const auto a = read_csv((f.dir / "a" / "overlay.csv").string()), b = read_csv((f.dir / "b" / "overlay.csv").string());
  ASSERT_EQ(a.size(), 60u);
  ASSERT_EQ(b.size(), 60u);
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse.scene.yaml");
  const Eigen::Vector3d c = tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm);
  const auto intr = test_intrinsics();
  int stale = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].size(), csv_columns().size());
    // Identical except the measured times (render done, latency, decode done, shown);
    // published and received are the log's.
    for (std::size_t col = 0; col < a[i].size(); ++col) {
      if (!measured_column(col)) {
        EXPECT_EQ(a[i][col], b[i][col]) << "row " << i << " column " << csv_columns()[col];
      }
    }
    const auto k = static_cast<std::int64_t>(i);
    EXPECT_EQ(std::stoll(a[i][0]), k);
    const bool has_pose = k < 20 || k >= 40;
    if (has_pose) {
      ASSERT_FALSE(a[i][6].empty()) << "row " << i << " flags " << a[i][9];
      const Eigen::Vector3d p = test_X_CamRef(k) * test_X_RefModel() * c;
      std::vector<cv::Point3d> in{{p.x(), p.y(), p.z()}};
      std::vector<cv::Point2d> px;
      cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(intr.camera_matrix), intr.distortion_mat(), px);
      EXPECT_LT(std::hypot(std::stod(a[i][6]) - px[0].x, std::stod(a[i][7]) - px[0].y), 0.05) << "row " << i;
    } else if (a[i][9].find("reference_stale") != std::string::npos) {
      EXPECT_TRUE(a[i][6].empty());
      ++stale;
    } else {
      // Within the 100 ms limit the newest pose still counts (not of this frame: flagged).
      EXPECT_NE(a[i][9].find("pose_not_matched"), std::string::npos) << "row " << i;
      EXPECT_LE(k, 19 + 6) << "stale banner later than 100 ms after the last pose";
    }
  }
  EXPECT_GE(stale, 20 - 6);
  // Bad inputs: a missing log, a session with a typo.
  EXPECT_EQ(run(arnav_host() + " " + session + " --replay " + (f.dir / "nope.lcmlog").string(), &out), 2);
  EXPECT_NE(out.find("nope.lcmlog"), std::string::npos) << out;
  const std::string bad = f.write("bad.yaml", "arnav_session_version: 1\nmodle: {rate_hz: 60}\n");
  EXPECT_EQ(run(arnav_host() + " " + bad + " --replay " + log_path, &out), 2);
  EXPECT_NE(out.find("bad.yaml:2: key 'modle': unknown key"), std::string::npos) << out;
  EXPECT_EQ(run(arnav_host() + " --replay " + log_path, &out), 2) << "--replay needs a session";
}

// Cutting with the pedal from the log (ARNAV_INPUT changes, ARNAV_INPUT_STATE snapshots):
// two replays cut the same organ (identical cut columns, events).
TEST(Replay, DeterministicWithCuttingAndThePedal) {
  SessionFolder f("replay_cut");
  const std::string session = f.write("cut.yaml", "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                                                      "/liver/liver_coarse_cut.scene.yaml\nregistration: X_RefModel.yaml\n"
                                                      "tools:\n  reference: {name: liver_marker, stale_after_ms: 100}\n"
                                                      "  scalpel: {name: scalpel, stale_after_ms: 100, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 60]}}\n"
                                                      "inputs: {cut_enable: pedal_right}\n"
                                                      "camera:\n  name: cam0\n  intrinsics: camera.yaml\n  pose_from: reference\n"
                                                      "model: {rate_hz: 60, gravity: false}\nsecurity: off\n");
  const std::string log_path = (f.dir / "cut.lcmlog").string();
  constexpr std::int64_t kWall = 1'700'000'000'000'000;
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    std::int64_t seq = 0;
    for (std::int64_t k = 0; k < 50; ++k) {
      const std::int64_t t = 1'000'000 + k * 16'667;
      log_event(log, channels::pose("liver_marker"), pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t + 500 + kWall);
      Eigen::Isometry3d X_ModelTool = Eigen::Isometry3d::Identity();
      X_ModelTool.linear() = Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d(1, 0.5, 0).normalized()).toRotationMatrix();
      X_ModelTool.translation() = kTumourCentre_Model + Eigen::Vector3d(-20.0 + 0.9 * k, -10 + 0.45 * k, 18);
      log_event(log, channels::pose("scalpel"), pose_msg("scalpel", "Ref", test_X_RefModel() * X_ModelTool, k, t, true, tool_pose_t::SOURCE_NDI),
                t + 700 + kWall);
      if (k == 3 || k == 45) {  // pedal down, up
        input_event_t m{};
        m.input_name = "pedal_right";
        m.state = k == 3 ? input_event_t::STATE_PRESSED : input_event_t::STATE_RELEASED;
        m.cause = input_event_t::CAUSE_FRAME;
        m.publish_time_mono_us = t + 800;
        m.publish_time_wall_us = t + 800 + kWall;
        m.sequence = ++seq;
        log_event(log, std::string(channels::kInput), m, t + 800 + kWall);
      }
      if (k % 10 == 0) {
        input_event_t m{};
        m.input_name = "pedal_right";
        m.state = k >= 3 && k < 45 ? input_event_t::STATE_PRESSED : input_event_t::STATE_RELEASED;
        m.cause = input_event_t::CAUSE_STATE;
        m.publish_time_mono_us = t + 900;
        m.publish_time_wall_us = t + 900 + kWall;
        m.sequence = seq;
        log_event(log, std::string(channels::kInputState), m, t + 900 + kWall);
      }
      log_event(log, channels::frame("cam0"), frame_msg(k, t), t + 4000 + kWall);
    }
  }
  std::string out;
  for (const char* dir : {"a", "b"})
    ASSERT_EQ(run(arnav_host() + " " + session + " --replay " + log_path + " --replay-speed 0 --quiet --summary --record " + (f.dir / dir).string(), &out), 0)
        << out;
  EXPECT_NE(out.find("cutting (input): 4"), std::string::npos) << out;
  const auto a = read_csv((f.dir / "a" / "overlay.csv").string()), b = read_csv((f.dir / "b" / "overlay.csv").string());
  ASSERT_EQ(a.size(), 50u);
  ASSERT_EQ(b.size(), 50u);
  int cutting = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a[i].size(), csv_columns().size());
    for (std::size_t col = 0; col < a[i].size(); ++col) {
      if (!measured_column(col)) {
        EXPECT_EQ(a[i][col], b[i][col]) << "row " << i << " column " << csv_columns()[col];
      }
    }
    cutting += a[i][10] == "1";
  }
  EXPECT_GE(cutting, 40);
  EXPECT_GT(std::stoi(a.back()[11]), 0) << "cut faces at the end";
  // Bad inputs/cutting declarations: exit 2 naming file:line and the fix.
  std::string text = slurp_file(session);
  const std::string bad_key = f.write("bad_inputs.yaml", std::regex_replace(text, std::regex("cut_enable: pedal_right"), "cut_enabel: pedal_right"));
  EXPECT_EQ(run(arnav_host() + " " + bad_key + " --replay " + log_path, &out), 2);
  EXPECT_NE(out.find("bad_inputs.yaml:8: key 'inputs.cut_enabel': unknown key (known keys: accept, cut_enable)"), std::string::npos) << out;
  const std::string no_mode = f.write("no_mode.yaml", std::regex_replace(text, std::regex("inputs: \\{cut_enable: pedal_right\\}\n"), ""));
  EXPECT_EQ(run(arnav_host() + " " + no_mode + " --replay " + log_path, &out), 2);
  EXPECT_NE(out.find("no_mode.yaml:3: key 'scene': "), std::string::npos) << out;
  EXPECT_NE(out.find("say when the scalpel cuts"), std::string::npos) << out;
}


// The replay steps the model by the log's clock before each message, as the live model
// thread steps while the messages arrive: a model step sees only the poses received before
// it. A grasper whose poses are missing from the log for 333 ms (frames every 0.5 s) is
// released as stale and grasped again when it returns. (Stepping only at camera frames ran
// the steps of the gap after the grasper's next pose had arrived, each with that later
// pose: never stale, one grasp; on the demo's ring cut this made the replay's cut-path tail,
// docs/benchmarks.md "Fifth round".)
TEST(Replay, ModelStepsSeeOnlyThePosesReceivedBeforeThem) {
  SessionFolder f("replay_grasp");
  const std::string scene_path = data_dir() + "/liver/liver_coarse.scene.yaml";
  const std::string session = f.write("grasp.yaml", "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + scene_path +
                                                        "\nregistration: X_RefModel.yaml\n"
                                                        "tools:\n  reference: {name: liver_marker, stale_after_ms: 100}\n"
                                                        "  grasper: {name: grasper, stale_after_ms: 100, radius_mm: 10, grasp: {always: true}}\n"
                                                        "camera:\n  name: cam0\n  intrinsics: camera.yaml\n  pose_from: reference\n"
                                                        "model: {rate_hz: 60, gravity: false}\nsecurity: off\n");
  // The grasper's tip on the organ's surface (the vertex nearest to the underside's middle).
  const Scene scene = load_scene(scene_path);
  const Eigen::Matrix3Xd surface = scene.organ_embedding.apply(scene.problem.mesh, scene.problem.mesh.rest_positions_World_mm);
  Eigen::Index v0 = 0;
  (surface.colwise() - Eigen::Vector3d(70, 160, 60)).colwise().norm().minCoeff(&v0);
  Eigen::Isometry3d X_ModelTool = Eigen::Isometry3d::Identity();
  X_ModelTool.translation() = surface.col(v0);
  const std::string log_path = (f.dir / "grasp.lcmlog").string();
  constexpr std::int64_t kWall = 1'700'000'000'000'000;
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    for (std::int64_t k = 0; k < 120; ++k) {
      const std::int64_t t = 1'000'000 + k * 16'667;
      const Eigen::Isometry3d X_CamRef = test_X_CamRef(k);
      log_event(log, channels::pose("liver_marker"), pose_msg("liver_marker", "Cam", X_CamRef, k, t), t + 500 + kWall);
      if (k < 60 || k >= 80)  // the grasper's poses are missing for 333 ms
        log_event(log, channels::pose("grasper"), pose_msg("grasper", "Cam", X_CamRef * test_X_RefModel() * X_ModelTool, k, t), t + 600 + kWall);
      if (k % 30 == 0 || k == 119) log_event(log, channels::frame("cam0"), frame_msg(k, t), t + 4000 + kWall);
    }
  }
  std::string out;
  const std::string json = (f.dir / "grasp.json").string();
  ASSERT_EQ(run(arnav_host() + " " + session + " --replay " + log_path + " --replay-speed 0 --quiet --summary-json " + json, &out), 0) << out;
  const nlohmann::json g = nlohmann::json::parse(slurp_file(json))["navigation"]["grasper"];
  EXPECT_EQ(g["stale_releases"].get<int>(), 1) << g.dump() << "\n" << out;
  EXPECT_EQ(g["grasps"].get<int>(), 2) << g.dump() << "\n" << out;
  EXPECT_NE(out.find("released"), std::string::npos) << out;
  EXPECT_GT(g["steps_grasping"].get<int>(), 60) << g.dump();
}

}  // namespace
}  // namespace arnav::host
