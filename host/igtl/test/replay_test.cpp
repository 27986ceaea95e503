// arnav-igtl on a recorded session (--lcm 'file://LOG?speed=1'): a log written here with
// lcm::LogFile (poses after a 4 s lead-in, so the client is connected before they play),
// the real executable, a client on 127.0.0.1. The latest pose of each tool always arrives,
// every TRANSFORM carries a logged pose's time, a missing pose is never sent, the host's
// last organ surface arrives as POLYDATA with its model step's time, and the program exits
// 0 at the end of the log with --exit-at-end.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <map>
#include <set>

#include <lcm/lcm-cpp.hpp>

#include "arnav/tool_pose_t.hpp"
#include "host/igtl/messages.hpp"
#include "host/igtl/test/test_client.hpp"
#include "protocol/channels.hpp"
#include "protocol/pose_convert.hpp"
#include "protocol/testing/child_process.hpp"

namespace arnav::igtl {
namespace {

constexpr std::int64_t kWall0_us = 1'764'633'600'000'000;

void write_event(lcm::LogFile& log, std::int64_t t_us, const std::string& channel, std::vector<std::uint8_t> bytes) {
  lcm::LogEvent e{};
  e.timestamp = t_us;
  e.channel = channel;
  e.datalen = static_cast<std::int32_t>(bytes.size());
  e.data = bytes.data();
  ASSERT_EQ(log.writeEvent(&e), 0);
}

template <class Msg>
std::vector<std::uint8_t> encode(const Msg& p) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(p.getEncodedSize()));
  p.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}

TEST(IgtlReplay, RecordedSessionServedAtItsPace) {
  const std::string log_path = std::filesystem::temp_directory_path() / ("arnav-igtl-replay-" + std::to_string(::getpid()) + ".lcmlog");
  std::map<std::string, std::set<std::int64_t>> logged_times;
  std::int64_t missing_time = 0;
  {
    lcm::LogFile log(log_path, "w");
    ASSERT_TRUE(log.good());
    write_event(log, 0, "ARNAV_LEAD_IN", {0});
    for (int f = 0; f < 60; ++f) {
      for (const std::string tool : {"pointer", "reference"}) {
        tool_pose_t p{};
        p.tool_name = tool;
        p.source = tool_pose_t::SOURCE_NDI;
        p.frame_parent = tool == "pointer" ? "Ref" : "Ndi";
        p.frame_child = "Tool";
        Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
        X.translation() = Eigen::Vector3d(f, 0, -1500);
        set_pose(p, X);
        p.status = tool == "reference" && f == 30 ? tool_pose_t::STATUS_MISSING : tool_pose_t::STATUS_VALID;
        p.device_frame_number = f;
        p.receive_time_wall_us = kWall0_us + f * 16667;
        if (p.status == tool_pose_t::STATUS_VALID)
          logged_times[tool == "pointer" ? "PointerToReference" : "ReferenceToTracker"].insert(p.receive_time_wall_us);
        else
          missing_time = p.receive_time_wall_us;
        write_event(log, 4'000'000 + f * 16667, channels::pose(tool), encode(p));
      }
      if (f % 6 == 0)  // the host's surfaces at 10 Hz
        write_event(log, 4'000'000 + f * 16667 + 100, channels::surface("organ"),
                    encode(test::sphere_surface("organ", 4, 6, 0.1 * f, kWall0_us + f * 16667)));
    }
  }
  const std::string cmd = "'" + testing::binary_path("host/igtl/arnav-igtl") + "' --lcm 'file://" + log_path +
                          "?speed=1' --security off --port 0 --exit-at-end 2>&1";
  FILE* igtl = ::popen(cmd.c_str(), "r");
  ASSERT_NE(igtl, nullptr);
  char line[256] = {};
  ASSERT_NE(std::fgets(line, sizeof line, igtl), nullptr);
  // arnav-igtl announces the bus's security first (stderr, folded in here: docs/protocol.md).
  EXPECT_NE(std::string(line).find("security: OFF"), std::string::npos) << line;
  ASSERT_NE(std::fgets(line, sizeof line, igtl), nullptr);
  int port = 0;
  ASSERT_EQ(std::sscanf(line, "READY %d", &port), 1) << line;
  test::TestClient client(port);
  ASSERT_TRUE(client.connected()) << client.why();
  const auto& got = client.receive_until(1u << 20, 30.0);  // until arnav-igtl exits at the end of the log
  EXPECT_TRUE(client.closed_by_server());
  std::string output;
  while (std::fgets(line, sizeof line, igtl)) output += line;
  const int status = ::pclose(igtl);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << output;
  EXPECT_NE(output.find("end of the log: 120 poses"), std::string::npos) << output;
  std::filesystem::remove(log_path);

  std::map<std::string, std::int64_t> last_time;
  std::size_t transforms = 0;
  for (const auto& m : got) {
    if (m.header.type != "TRANSFORM") continue;
    ++transforms;
    const auto u = test::unpack(m);
    EXPECT_TRUE(u.crc_ok);
    ASSERT_TRUE(logged_times.count(u.device_name)) << u.device_name;
    EXPECT_TRUE(logged_times[u.device_name].count(u.wall_us)) << u.device_name << " at " << u.wall_us << " was not logged";
    EXPECT_FALSE(u.wall_us == missing_time && u.device_name == "ReferenceToTracker") << "a missing pose was sent";
    last_time[u.device_name] = u.wall_us;
  }
  EXPECT_GE(transforms, 60u);  // 119 valid poses; a loaded machine may coalesce some
  std::int64_t last_organ_us = 0;
  for (const auto& m : got)
    if (m.header.type == "POLYDATA" && m.header.device_name == "Organ") {
      const auto u = test::unpack(m);
      EXPECT_TRUE(u.crc_ok);
      last_organ_us = u.wall_us;
    }
  EXPECT_EQ(last_organ_us, kWall0_us + 54 * 16667) << "the last logged organ surface did not arrive";
  EXPECT_EQ(last_time["PointerToReference"], kWall0_us + 59 * 16667);
  EXPECT_EQ(last_time["ReferenceToTracker"], kWall0_us + 59 * 16667);
}

}  // namespace
}  // namespace arnav::igtl
