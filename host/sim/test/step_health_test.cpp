// The health rule for inverted elements (docs/sim.md, "Run-time health"): counted warning,
// recovery reported, unhealthy only for a collapse held beyond kCollapseTime_s.
#include <gtest/gtest.h>

#include "host/sim/step_health.hpp"

namespace arnav::host {
namespace {

TEST(InversionMonitor, FewInvertedAreCountedAndRecoveryIsReported) {
  InversionMonitor m;
  for (int k = 0; k < 300; ++k) {  // 3 s with 3 of 1000 inverted
    StepSummary s;
    m.update(3, 1000, 0.01, s);
    ASSERT_TRUE(s.healthy) << s.warning;
    EXPECT_EQ(s.inverted_elements, 3);
    EXPECT_NE(s.warning.find("inverted tets: 3 of 1000"), std::string::npos) << s.warning;
  }
  EXPECT_NEAR(m.episode_s(), 3.0, 1e-9);
  EXPECT_EQ(m.steps_with_inversions(), 300);
  StepSummary s;
  m.update(0, 1000, 0.01, s);
  EXPECT_TRUE(s.healthy);
  EXPECT_EQ(s.inverted_elements, 0);
  EXPECT_NE(s.warning.find("recovered after 3.00 s"), std::string::npos) << s.warning;
  EXPECT_EQ(m.episode_s(), 0.0);
  EXPECT_NEAR(m.worst_episode_s(), 3.0, 1e-9);
  StepSummary quiet;
  m.update(0, 1000, 0.01, quiet);
  EXPECT_TRUE(quiet.warning.empty()) << quiet.warning;
  m.update(7, 1000, 0.01, quiet);
  EXPECT_EQ(m.peak_inverted(), 7);
}

TEST(InversionMonitor, CollapseIsUnhealthyOnlyWhenHeldBeyondTheGraceTime) {
  InversionMonitor m;
  const int total = 1000, many = static_cast<int>(kCollapseFraction * total) + 1;
  int first_unhealthy = -1;
  for (int k = 0; k < 40 && first_unhealthy < 0; ++k) {  // steps of 1/16 s (exact in binary)
    StepSummary s;
    m.update(many, total, 0.0625, s);
    if (!s.healthy) {
      first_unhealthy = k;
      EXPECT_NE(s.warning.find("mesh collapse"), std::string::npos) << s.warning;
    }
  }
  EXPECT_EQ(first_unhealthy, 16);  // 16 steps = 1 s (not more), the 17th is beyond
  // Exactly at the fraction is not a collapse; a dip below it restarts the clock.
  InversionMonitor edge;
  for (int k = 0; k < 100; ++k) {
    StepSummary s;
    edge.update(k % 10 == 0 ? 5 : static_cast<int>(kCollapseFraction * total), total, 0.05, s);
    ASSERT_TRUE(s.healthy) << k << ": " << s.warning;
  }
  // set_state: a new episode.
  m.reset_episode();
  StepSummary s;
  m.update(many, total, 0.05, s);
  EXPECT_TRUE(s.healthy);
}

}  // namespace
}  // namespace arnav::host
