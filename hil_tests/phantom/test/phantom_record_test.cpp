#include <gtest/gtest.h>

#include "hil_tests/phantom/phantom_record.hpp"

namespace arnav::hil {
namespace {

TEST(PhantomScript, PullRisesHoldsAndReturns) {
  PhantomScript s;
  EXPECT_EQ(s.pull_fraction(0.0), 0.0);
  EXPECT_NEAR(s.pull_fraction(s.start_s + s.ramp_s * 0.5), 0.5, 1e-12);
  EXPECT_EQ(s.pull_fraction(s.start_s + s.ramp_s + 0.5 * s.hold_s), 1.0);
  EXPECT_NEAR(s.pull_fraction(s.start_s + 2 * s.ramp_s + s.hold_s), 0.0, 1e-12);
}

}  // namespace
}  // namespace arnav::hil
