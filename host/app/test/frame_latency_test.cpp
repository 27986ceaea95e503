// Latency by stage (host/app/frame_latency): stages from given instants (no clock read),
// misses counted and treated as infinitely late, stamps out of order named.
#include <gtest/gtest.h>

#include "host/app/frame_latency.hpp"

namespace arnav::host {
namespace {

FrameStamps stamps(std::int64_t seq, std::int64_t exposure_us) {
  // readout 16.7 ms + appliance 5 ms, transport 0.3 ms, decode 4 ms, render 6 ms, display 1 ms.
  return {seq, exposure_us, exposure_us + 21'700, exposure_us + 22'000, exposure_us + 26'000, exposure_us + 32'000, exposure_us + 33'000};
}

TEST(FrameLatency, StagesAddUpToExposureToDisplay) {
  FrameLatency lat;
  for (std::int64_t k = 0; k < 10; ++k) {
    lat.received(k);
    lat.shown(stamps(k, 1'000'000 + k * 16'667));
  }
  const auto j = lat.json();
  EXPECT_NEAR(j["stages_ms"]["exposure_to_published"]["p50"].get<double>(), 21.7, 1e-9);
  EXPECT_NEAR(j["stages_ms"]["transport"]["p99"].get<double>(), 0.3, 1e-9);
  EXPECT_NEAR(j["stages_ms"]["decode"]["p50"].get<double>(), 4.0, 1e-9);
  EXPECT_NEAR(j["stages_ms"]["render"]["p50"].get<double>(), 6.0, 1e-9);
  EXPECT_NEAR(j["stages_ms"]["display"]["max"].get<double>(), 1.0, 1e-9);
  EXPECT_NEAR(j["exposure_to_display_ms"]["p99_9"].get<double>(), 33.0, 1e-9);
  EXPECT_NEAR(j["received_to_shown_ms"]["p50"].get<double>(), 11.0, 1e-9);
  EXPECT_NEAR(j["host_processing_latency_ms"]["p50"].get<double>(), 10.0, 1e-9);
  EXPECT_EQ(j["misses"]["total"].get<int>(), 0);
  EXPECT_EQ(j["stamps_out_of_order"].get<int>(), 0);
  EXPECT_EQ(lat.summary_line(), "exposure-to-display: p50 33.0 ms, p99 33.0 ms, p99.9 33.0 ms (10 frames shown, 0 missed)");
}

TEST(FrameLatency, GapsDropsAndUndecodableFramesAreMisses) {
  FrameLatency lat;
  for (std::int64_t k : {0, 1, 2, 5, 6, 7, 9}) lat.received(k);  // 3, 4 and 8 never arrived
  lat.received(6);  // a late duplicate does not hide or add a gap
  lat.dropped_by_host();
  lat.undecodable();
  for (std::int64_t k : {0, 1, 2, 5, 6, 9}) lat.shown(stamps(k, k * 16'667));
  EXPECT_EQ(lat.misses(), 5);
  const auto j = lat.json();
  EXPECT_EQ(j["misses"]["not_received"].get<int>(), 3);
  EXPECT_EQ(j["misses"]["dropped_by_host"].get<int>(), 1);
  EXPECT_EQ(j["misses"]["undecodable"].get<int>(), 1);
  // 6 shown + 5 misses: the median is still a shown frame, the p99 a miss.
  EXPECT_NEAR(j["exposure_to_display_with_misses_ms"]["p50"].get<double>(), 33.0, 1e-9);
  EXPECT_TRUE(j["exposure_to_display_with_misses_ms"]["p99"].is_null());
}

TEST(FrameLatency, StampsOutOfOrderAreCountedAndNamed) {
  FrameStamps s = stamps(7, 1'000'000);
  EXPECT_EQ(stamp_order_error(s), "");
  s.received_us = s.published_us - 2'000;  // a receive clock behind the sender's
  EXPECT_EQ(stamp_order_error(s), "frame 7: received (1019700 us) before published (1021700 us) by 2.000 ms");
  FrameLatency lat;
  lat.shown(s);
  lat.shown(stamps(8, 2'000'000));
  const auto j = lat.json();
  EXPECT_EQ(j["stamps_out_of_order"].get<int>(), 1);
  EXPECT_NE(j["first_out_of_order"].get<std::string>().find("frame 7"), std::string::npos);
}

TEST(Quantiles, NearestRankAndMissesAtTheTail) {
  std::vector<double> v;
  for (int i = 1; i <= 1000; ++i) v.push_back(i);
  const Quantiles q = quantiles(v);
  EXPECT_EQ(q.n, 1000u);
  EXPECT_DOUBLE_EQ(q.p50, 501.0);
  EXPECT_DOUBLE_EQ(q.p99, 990.0);
  EXPECT_DOUBLE_EQ(q.p999, 999.0);
  EXPECT_DOUBLE_EQ(q.max, 1000.0);
  // One miss in 1001 frames leaves p99 a measured value; eleven make it a miss.
  EXPECT_TRUE(quantile_with_misses(v, 1, 0.99).has_value());
  EXPECT_FALSE(quantile_with_misses(v, 11, 0.99).has_value());
  EXPECT_FALSE(quantile_with_misses({}, 0, 0.5).has_value());
  EXPECT_EQ(quantiles({}).n, 0u);
}

}  // namespace
}  // namespace arnav::host
