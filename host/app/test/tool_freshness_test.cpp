#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include "host/app/status_report.hpp"
#include "host/app/tool_freshness.hpp"
#include "protocol/channels.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host {
namespace {

tool_pose_t pose(const std::string& tool, std::int64_t frame, std::int64_t seq, std::int8_t status = tool_pose_t::STATUS_VALID) {
  tool_pose_t m{};
  m.tool_name = tool;
  m.frame_parent = "Ndi";
  m.frame_child = "Tool";
  m.status = status;
  m.device_frame_number = frame;
  m.sequence = seq;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(1.0, 2.0, -1500.0 + static_cast<double>(frame));
  set_pose(m, X);
  return m;
}

TEST(ToolFreshness, StaleAfterTheConfiguredAge) {
  ToolFreshnessTracker t(100'000);  // 100 ms
  t.on_pose(pose("pointer", 10, 0), 1'000'000);
  EXPECT_FALSE(t.tools().at("pointer").stale);
  t.update(1'099'000);
  EXPECT_FALSE(t.tools().at("pointer").stale);
  t.update(1'101'000);
  EXPECT_TRUE(t.tools().at("pointer").stale);
  EXPECT_EQ(t.tools().at("pointer").stale_episodes, 1);
  // A MISSING pose does not make it fresh again.
  t.on_pose(pose("pointer", 11, 1, tool_pose_t::STATUS_MISSING), 1'150'000);
  EXPECT_TRUE(t.tools().at("pointer").stale);
  t.on_pose(pose("pointer", 12, 2), 1'200'000);
  EXPECT_FALSE(t.tools().at("pointer").stale);
  EXPECT_EQ(t.tools().at("pointer").max_valid_gap_us, 200'000);
  EXPECT_NEAR(t.tools().at("pointer").X_ParentChild.translation().z(), -1488.0, 1e-9);
}

TEST(ToolFreshness, FrameCounterContinuity) {
  ToolFreshnessTracker t(100'000);
  std::int64_t now = 0;
  t.on_pose(pose("ref", 100, 0), now += 1000);
  t.on_pose(pose("ref", 101, 1), now += 1000);
  t.on_pose(pose("ref", 101, 2), now += 1000);  // duplicate
  t.on_pose(pose("ref", 105, 4), now += 1000);  // 3 frames skipped, 1 message lost
  t.on_pose(pose("ref", 3, 5), now += 1000);    // device reset: counter restarted
  const auto& r = t.tools().at("ref");
  EXPECT_EQ(r.messages, 5);
  EXPECT_EQ(r.duplicate_frames, 1);
  EXPECT_EQ(r.frame_gaps, 3);
  EXPECT_EQ(r.sequence_gaps, 1);
  EXPECT_EQ(r.counter_restarts, 1);
}

TEST(ToolFreshness, RateOverTheWindow) {
  ToolFreshnessTracker t(100'000, 1'000'000);
  for (int i = 0; i < 120; ++i) t.on_pose(pose("p", i, i), 10'000'000 + i * 16'667);  // 60 Hz for 2 s
  t.update(10'000'000 + 120 * 16'667);
  EXPECT_NEAR(t.tools().at("p").rate_hz, 60.0, 1.0);
}

TEST(ToolFreshness, TableShowsToolsAndDevices) {
  ToolFreshnessTracker t(100'000);
  t.on_pose(pose("pointer", 7, 0), 1'000);
  device_health_t h{};
  h.device = "ndi";
  h.link_state = device_health_t::LINK_TRACKING;
  h.latency_p99_us = 42.0f;
  t.on_health(h, 1'000);
  const std::string table = format_status_table(t, 2'000);
  EXPECT_NE(table.find("pointer"), std::string::npos);
  EXPECT_NE(table.find("fresh"), std::string::npos);
  EXPECT_NE(table.find("TRACKING"), std::string::npos);
  EXPECT_NE(table.find("/42/"), std::string::npos);
  appliance_event_t e{};
  e.code = "NDI_RECOVERED";
  e.text = "recovered after 703 ms";
  t.on_event(e);
  const std::string summary = format_summary(t, 2.0);
  EXPECT_NE(summary.find("tool pointer"), std::string::npos) << summary;
  EXPECT_NE(summary.find("worst p99 of the run 42 us"), std::string::npos) << summary;
  EXPECT_NE(summary.find("NDI_RECOVERED x1"), std::string::npos) << summary;
  EXPECT_NE(summary.find("recovered after 703 ms"), std::string::npos) << summary;
}

// The same bookkeeping fed over LCM (memq://), as arnav-host subscribes.
TEST(ToolFreshness, OverLcm) {
  lcm::LCM bus("memq://");
  ASSERT_TRUE(bus.good());
  ToolFreshnessTracker t(100'000);
  struct H {
    ToolFreshnessTracker& t;
    std::int64_t now = 0;
    void on(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { t.on_pose(*m, now += 1000); }
  } h{t};
  bus.subscribe(std::string(channels::kPoseRegex), &H::on, &h);
  for (int i = 0; i < 3; ++i) {
    const tool_pose_t m = pose("pointer", 50 + i, i);
    bus.publish(channels::pose("pointer"), &m);
  }
  for (int i = 0; i < 3; ++i) ASSERT_GE(bus.handleTimeout(1000), 1);
  EXPECT_EQ(t.tools().at("pointer").valid, 3);
  EXPECT_EQ(t.tools().at("pointer").last_frame, 52);
}

}  // namespace
}  // namespace arnav::host
