#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "appliance/realtime/latency_stats.hpp"

namespace arnav::app {
namespace {

TEST(LatencyWindow, NearestRankPercentiles) {
  LatencyWindow w(1000);
  std::vector<float> v(100);
  std::iota(v.begin(), v.end(), 1.0f);  // 1..100
  std::shuffle(v.begin(), v.end(), std::mt19937(7));
  for (float x : v) w.add(x);
  const LatencySummary s = w.take();
  EXPECT_EQ(s.samples, 100u);
  EXPECT_FLOAT_EQ(s.p50_us, 50.0f);
  EXPECT_FLOAT_EQ(s.p99_us, 99.0f);
  EXPECT_FLOAT_EQ(s.max_us, 100.0f);
  const LatencySummary empty = w.take();  // take() starts a new window
  EXPECT_EQ(empty.samples, 0u);
  EXPECT_FLOAT_EQ(empty.max_us, 0.0f);
}

TEST(LatencyWindow, OverflowKeepsTheTrueMaximum) {
  LatencyWindow w(10);
  w.add(500.0f);
  for (int i = 0; i < 50; ++i) w.add(1.0f);
  const LatencySummary s = w.take();
  EXPECT_EQ(s.samples, 10u);
  EXPECT_FLOAT_EQ(s.p99_us, 1.0f);
  EXPECT_FLOAT_EQ(s.max_us, 500.0f);
}

TEST(LatencyWindow, SingleSample) {
  LatencyWindow w;
  w.add(12.5f);
  const LatencySummary s = w.take();
  EXPECT_FLOAT_EQ(s.p50_us, 12.5f);
  EXPECT_FLOAT_EQ(s.p99_us, 12.5f);
}

}  // namespace
}  // namespace arnav::app
