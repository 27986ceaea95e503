// End to end on the HIL bench: the appliance's pointer swab (docs/appliance.md, `swab:`)
// with the simulated Polaris, received over LCM udpm in a private network namespace.
#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <string>
#include <vector>

#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/clock.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

// Pointer swab (docs/appliance.md `swab:`), continuous: the appliance publishes the
// pointer's tip as point_cloud_t on ARNAV_CLOUD_pointer; every point is the tip offset
// carried by one of the pointer poses it published, in the same frame, and the sequence
// numbers have no gaps.
TEST(HilSwab, ContinuousSwabPublishesThePointerTip) {
  HilRunOptions o;
  o.extra_config = "swab:\n  tool: pointer\n  tip_mm: [0.0, 0.0, -150.0]\n  continuous: true\n  min_spacing_mm: 0.0\n  points_per_message: 10\n";
  HilRun run;
  const std::int64_t t0 = monotonic_us();
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.wait_all_valid(30, t0, 90.0)) << run.logs();
  ASSERT_TRUE(run.lcm().wait_for([](const LcmCapture& c) { return c.clouds().size() >= 5; }, 30.0)) << run.logs();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  const auto clouds = run.lcm().clouds();
  std::vector<Eigen::Vector3d> tips;
  std::vector<std::string> frames;
  for (const auto& p : run.lcm().poses()) {
    if (p.msg.tool_name != "pointer" || p.msg.status == tool_pose_t::STATUS_MISSING || p.msg.status == tool_pose_t::STATUS_DISABLED) continue;
    const Eigen::Quaterniond q(p.msg.q_ParentChild_wxyz[0], p.msg.q_ParentChild_wxyz[1], p.msg.q_ParentChild_wxyz[2], p.msg.q_ParentChild_wxyz[3]);
    tips.push_back(Eigen::Vector3d(p.msg.p_ParentChild_mm[0], p.msg.p_ParentChild_mm[1], p.msg.p_ParentChild_mm[2]) +
                   q.normalized() * Eigen::Vector3d(0, 0, -150.0));
    frames.push_back(p.msg.frame_parent);
  }
  ASSERT_FALSE(tips.empty());
  std::size_t points = 0;
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    const point_cloud_t& m = clouds[i].msg;
    EXPECT_EQ(m.source, "pointer");
    EXPECT_EQ(m.sequence, static_cast<std::int64_t>(i)) << "a lost or reordered message";
    EXPECT_EQ(m.num_normals, 0);
    for (int k = 0; k < m.num_points; ++k) {
      const Eigen::Vector3d pt(m.p_mm[static_cast<std::size_t>(k)][0], m.p_mm[static_cast<std::size_t>(k)][1], m.p_mm[static_cast<std::size_t>(k)][2]);
      double best = 1e9;
      for (std::size_t j = 0; j < tips.size(); ++j)
        if (frames[j] == m.frame_name) best = std::min(best, (tips[j] - pt).norm());
      EXPECT_LT(best, 1e-3) << "point " << k << " of message " << i << " is not the tip of a published pose";
      ++points;
    }
  }
  EXPECT_GE(points, 50u);
}


}  // namespace
}  // namespace arnav::hil
