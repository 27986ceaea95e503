#include <gtest/gtest.h>
#include <lcm/lcm-cpp.hpp>

#include <atomic>

#include "protocol/channels.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav {
namespace {

TEST(PoseConvert, RoundTripPreservesTransform) {
  Eigen::Isometry3d X_NdiTool = Eigen::Isometry3d::Identity();
  X_NdiTool.linear() = Eigen::AngleAxisd(2.5, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
  X_NdiTool.translation() = Eigen::Vector3d(-240.11, 64.70, -1564.67);
  tool_pose_t msg{};
  set_pose(msg, X_NdiTool);
  EXPECT_GE(msg.q_ParentChild_wxyz[0], 0.0);
  const Eigen::Isometry3d back = get_pose(msg);
  EXPECT_TRUE(back.isApprox(X_NdiTool, 1e-12));
}

TEST(PoseConvert, ZeroQuaternionIsRejected) {
  tool_pose_t msg{};
  msg.tool_name = "pointer";
  EXPECT_THROW(get_pose(msg), std::invalid_argument);
}

TEST(Protocol, ToolPoseSurvivesLcmEncoding) {
  lcm::LCM bus("memq://");
  ASSERT_TRUE(bus.good());
  tool_pose_t sent{};
  sent.tool_name = "pointer";
  sent.tool_id = 2;
  sent.source = tool_pose_t::SOURCE_NDI;
  sent.frame_parent = "Ndi";
  sent.frame_child = "Tool";
  sent.status = tool_pose_t::STATUS_VALID;
  sent.sequence = 41;
  sent.receive_time_mono_us = monotonic_us();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.translation() = Eigen::Vector3d(1, 2, 3);
  set_pose(sent, X);

  struct Sink {
    tool_pose_t got{};
    int count = 0;
    void on(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { got = *m; ++count; }
  } sink;
  bus.subscribe(std::string(channels::kPoseRegex), &Sink::on, &sink);
  bus.publish(channels::pose("pointer"), &sent);
  ASSERT_GT(bus.handleTimeout(1000), 0);
  EXPECT_EQ(sink.count, 1);
  EXPECT_EQ(sink.got.tool_name, "pointer");
  EXPECT_EQ(sink.got.sequence, 41);
  EXPECT_DOUBLE_EQ(sink.got.p_ParentChild_mm[2], 3.0);
}

TEST(Clock, MonotonicAdvances) {
  const auto a = monotonic_us();
  const auto b = monotonic_us();
  EXPECT_LE(a, b);
  EXPECT_GT(wall_us(), 1'600'000'000'000'000LL);  // after 2020
}

}  // namespace
}  // namespace arnav
