// The security banner's decision (host/app/security_alarm.hpp): which frames carry a
// SECURITY banner and what it says, from the sealed bus's drops and their receive times.
#include <gtest/gtest.h>

#include "host/app/security_alarm.hpp"

namespace arnav::host {
namespace {

using seal::Verdict;

constexpr std::int64_t kS = 1'000'000;

TEST(SecurityAlarm, NoDropNoBanner) {
  SecurityAlarm a;
  EXPECT_TRUE(a.banners_at(100 * kS).empty());
  EXPECT_FALSE(a.window_at(100 * kS).active());
  EXPECT_FALSE(a.last_drop_us());
  EXPECT_FALSE(a.on_drop(Verdict::Accepted, "ARNAV_POSE_scalpel", 1 * kS)) << "an accepted message is not a drop";
  EXPECT_TRUE(a.banners_at(2 * kS).empty());
  EXPECT_EQ(a.total().dropped(), 0u);
}

TEST(SecurityAlarm, RejectedSealedMessagesShowTheirKindsWhileRisingAndClearAfterTheHold) {
  SecurityAlarm a;  // hold 5 s
  const std::int64_t t0 = 10 * kS;
  EXPECT_TRUE(a.on_drop(Verdict::Forged, "ARNAV_POSE_scalpel", t0)) << "the first drop starts an alert";
  EXPECT_FALSE(a.on_drop(Verdict::Replayed, "ARNAV_POSE_liver_marker", t0 + 100'000));
  EXPECT_FALSE(a.on_drop(Verdict::Tampered, "ARNAV_INPUT", t0 + 200'000));
  EXPECT_FALSE(a.on_drop(Verdict::Tampered, "ARNAV_INPUT", t0 + 300'000));
  // A frame that arrived before the first drop: nothing (live == replay).
  EXPECT_TRUE(a.banners_at(t0 - 1).empty());
  // Between the drops: only those received by then.
  std::vector<std::string> b = a.banners_at(t0 + 150'000);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0], "SECURITY: bus messages rejected (last 5 s): forged 1, replayed 1");
  b = a.banners_at(t0 + 1 * kS);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0], "SECURITY: bus messages rejected (last 5 s): forged 1, tampered 2, replayed 1");
  const SecurityWindow w = a.window_at(t0 + 1 * kS);
  EXPECT_EQ(w.sealed_rejected(), 4u);
  EXPECT_EQ(w.last_rejected_channel, "ARNAV_INPUT");
  EXPECT_EQ(w.dropped.unsealed, 0u);
  // The window slides: 5 s after the first drop it has left, the others are still in.
  b = a.banners_at(t0 + 5 * kS + 50'000);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0], "SECURITY: bus messages rejected (last 5 s): tampered 2, replayed 1");
  // 5 s after the last: gone.
  EXPECT_TRUE(a.banners_at(t0 + 300'000 + 5 * kS).empty());
  EXPECT_EQ(*a.last_drop_us(), t0 + 300'000);
  // A drop after a quiet hold starts a new alert.
  EXPECT_TRUE(a.on_drop(Verdict::Stale, "ARNAV_POSE_liver_marker", t0 + 300'000 + 5 * kS));
  EXPECT_EQ(a.banners_at(t0 + 6 * kS)[0], "SECURITY: bus messages rejected (last 5 s): stale 1");
  EXPECT_EQ(a.total().dropped(), 5u);
  EXPECT_EQ(a.total().tampered, 2u);
}

TEST(SecurityAlarm, UnsealedMessageOnTheSealedBusNamesItsChannel) {
  SecurityAlarm a;
  EXPECT_TRUE(a.on_drop(Verdict::Unsealed, "ARNAV_POSE_scalpel", 1 * kS));
  EXPECT_FALSE(a.on_drop(Verdict::Unsealed, "ARNAV_INPUT", 2 * kS));
  std::vector<std::string> b = a.banners_at(2 * kS);
  ASSERT_EQ(b.size(), 1u) << "no sealed message was rejected: the unsealed line only";
  EXPECT_EQ(b[0], "SECURITY: unsealed messages on the sealed bus (last 5 s): 2, last on ARNAV_INPUT");
  EXPECT_EQ(a.banners_at(1 * kS)[0], "SECURITY: unsealed messages on the sealed bus (last 5 s): 1, last on ARNAV_POSE_scalpel");
  // Both kinds: two lines, the sealed one first.
  a.on_drop(Verdict::Malformed, "ARNAV_FRAME_bench", 3 * kS);
  b = a.banners_at(3 * kS);
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b[0], "SECURITY: bus messages rejected (last 5 s): malformed 1");
  EXPECT_EQ(b[1], "SECURITY: unsealed messages on the sealed bus (last 5 s): 2, last on ARNAV_INPUT");
  // The unsealed ones leave the window before the malformed one.
  b = a.banners_at(7 * kS + 1);
  ASSERT_EQ(b.size(), 1u);
  EXPECT_EQ(b[0], "SECURITY: bus messages rejected (last 5 s): malformed 1");
}

TEST(SecurityAlarm, AFloodIsBoundedAndStillShown) {
  SecurityAlarmOptions o;
  o.max_entries = 1000;
  SecurityAlarm a(o);
  const std::int64_t t0 = 100 * kS;
  for (int i = 0; i < 20000; ++i) a.on_drop(i % 2 ? Verdict::Forged : Verdict::Unsealed, "ARNAV_POSE_x" + std::to_string(i % 500), t0 + i * 100);
  EXPECT_EQ(a.total().dropped(), 20000u);
  const SecurityWindow w = a.window_at(t0 + 20000 * 100);
  // 2 s of drops, all within the hold, but only the newest 1000 remembered: a lower bound.
  EXPECT_GE(w.dropped.dropped(), 1000u);
  EXPECT_LE(w.dropped.dropped(), 20000u);
  EXPECT_EQ(a.banners_at(t0 + 20000 * 100).size(), 2u);
  // Many channel names: remembered up to a bound, the rest under one name.
  EXPECT_EQ(w.last_unsealed_channel, "(one of many channels)");
  EXPECT_TRUE(a.banners_at(t0 + 20000 * 100 + 6 * kS).empty());
}

TEST(SecurityAlarm, OldDropsAreForgotten) {
  SecurityAlarm a;
  a.on_drop(Verdict::Forged, "ARNAV_INPUT", 1 * kS);
  for (int i = 0; i < 100; ++i) a.on_drop(Verdict::Replayed, "ARNAV_INPUT", 100 * kS + i);
  // The forged drop 99 s before is outside any frame's window: the window's counts are exact.
  const SecurityWindow w = a.window_at(100 * kS + 200);
  EXPECT_EQ(w.dropped.replayed, 100u);
  EXPECT_EQ(w.dropped.forged, 0u);
  EXPECT_EQ(a.total().forged, 1u);
}

}  // namespace
}  // namespace arnav::host
