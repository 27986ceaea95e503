// arnav-host --replay on an lcm-logger log written here (lcm::LogFile, the same format):
// the navigation session re-run offline is deterministic (two replays give the same
// overlay.csv except the wall-clock columns), draws the tumour where the frame chain puts
// it, shows the stale banner while the board's poses are missing from the log, and bad
// inputs exit 2. No network needed.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <sstream>

#include <lcm/lcm-cpp.hpp>
#include <opencv2/calib3d.hpp>

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
    ASSERT_EQ(a[i].size(), 10u);
    // Identical except render_done and latency (columns 4 and 5: measured render time).
    for (std::size_t col : {0u, 1u, 2u, 3u, 6u, 7u, 8u, 9u}) EXPECT_EQ(a[i][col], b[i][col]) << "row " << i << " column " << col;
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

}  // namespace
}  // namespace arnav::host
