// The model's input clock (host/app/model_input_clock.hpp): steps on the device clock, each
// with the samples measured by its time, whatever the host's timing.
#include <gtest/gtest.h>

#include <vector>

#include "host/app/model_input_clock.hpp"

namespace arnav::host {
namespace {

constexpr std::int64_t kPeriod = 16'667;  // 60 Hz

BladeSample blade_at(std::int64_t t_us, double y_mm, bool cutting = true) {
  return BladeSample{t_us, std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(0, y_mm, 0), Eigen::Vector3d(0, y_mm, 40)}, cutting};
}

// What a run hands the model: per step, its device time and the y of each blade sample.
struct StepRecord {
  std::int64_t t_us;
  std::vector<double> ys;
  bool operator==(const StepRecord&) const = default;
};

std::vector<StepRecord> drain(ModelInputClock& clock, std::int64_t host_now_us) {
  std::vector<StepRecord> out;
  while (const auto t = clock.due(host_now_us)) {
    const ModelStepInputs in = clock.take(*t, host_now_us);
    StepRecord r{in.device_time_us, {}};
    for (const auto& b : in.blades) r.ys.push_back(b.blade_Model_mm ? (*b.blade_Model_mm)[0].y() : -1.0);
    out.push_back(r);
  }
  return out;
}

TEST(ModelInputClock, AStepWaitsForTheSamplesMeasuredByItsTime) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0);
  clock.require_blade();
  const std::int64_t t0 = 100 * kPeriod;
  EXPECT_FALSE(clock.due(0)) << "no sample yet: nothing to step on";
  // The first step is the grid point at or after the first sample; it waits for a sample
  // measured at or after it (one measured before it may still come).
  clock.push_blade(blade_at(t0 - 3000, 1.0), t0);
  EXPECT_TRUE(drain(clock, t0).empty());
  clock.push_blade(blade_at(t0 - 1000, 2.0), t0 + 100);
  EXPECT_TRUE(drain(clock, t0 + 200).empty());
  clock.push_blade(blade_at(t0 + 2000, 3.0), t0 + 3000);
  const auto steps = drain(clock, t0 + 3000);
  ASSERT_EQ(steps.size(), 1u);
  EXPECT_EQ(steps[0].t_us, t0);
  EXPECT_EQ(steps[0].ys, (std::vector<double>{1.0, 2.0})) << "every sample, in order, none merged";
  EXPECT_EQ(clock.counters().steps_waited_out, 0);
}

// The same samples give the same steps whether the host drains after every sample (idle)
// or in bursts long after (a loaded machine's late model thread).
TEST(ModelInputClock, SameStepsWhateverTheHostTiming) {
  std::vector<BladeSample> samples;
  for (int i = 0; i < 400; ++i) samples.push_back(blade_at(1'000'000 + i * 4'167 + (i * 37) % 900, 0.1 * i));  // 240 Hz, jittered
  ModelInputClock idle(60.0, 500.0, 1000.0, 100.0), loaded(60.0, 500.0, 1000.0, 100.0);
  idle.require_blade();
  loaded.require_blade();
  std::vector<StepRecord> a, b;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const std::int64_t arrival = samples[i].device_time_us + 1'500;
    idle.push_blade(samples[i], arrival);
    for (auto& r : drain(idle, arrival)) a.push_back(r);
    loaded.push_blade(samples[i], arrival + 40'000);  // delivered late ...
    if (i % 23 == 22)                                 // ... and stepped in bursts
      for (auto& r : drain(loaded, arrival + 180'000)) b.push_back(r);
  }
  for (auto& r : drain(loaded, samples.back().device_time_us + 200'000)) b.push_back(r);
  // The loaded run's last burst may run one more step (waited out) than the idle one has.
  ASSERT_GE(b.size(), a.size());
  b.resize(a.size());
  EXPECT_EQ(a, b);
  std::size_t applied = 0;
  for (const auto& r : a) applied += r.ys.size();
  EXPECT_GE(applied, samples.size() - 4) << "every sample up to the last complete step reaches a step";
  EXPECT_EQ(idle.counters().late_samples, 0);
  EXPECT_EQ(loaded.counters().steps_skipped, 0);
}

TEST(ModelInputClock, ALateStreamIsWaitedForAtMostTheWaitThenItsSamplesComeNextStepInOrder) {
  ModelInputClock clock(60.0, 100.0, 1000.0, 100.0);
  clock.require_blade();
  clock.require_grasp();
  const std::int64_t t0 = 600 * kPeriod;
  clock.push_blade(blade_at(t0, 1.0), t0 + 1'000);
  clock.push_grasp({t0, {}}, t0 + 1'000);
  ASSERT_EQ(drain(clock, t0 + 1'000).size(), 1u);
  // The grasper's stream goes on; the scalpel's stalls (a link stall): step t0 + kPeriod
  // waits up to 100 ms on the host clock, then runs without it.
  clock.push_grasp({t0 + kPeriod, {}}, t0 + kPeriod + 1'000);
  EXPECT_TRUE(drain(clock, t0 + kPeriod + 50'000).empty());
  const auto steps = drain(clock, t0 + kPeriod + 1'000 + 100'000);
  ASSERT_EQ(steps.size(), 1u);
  EXPECT_EQ(clock.counters().steps_waited_out, 1);
  // The stalled samples arrive: applied at the next step, in order, counted late.
  clock.push_blade(blade_at(t0 + 5'000, 2.0), t0 + 120'000);
  clock.push_blade(blade_at(t0 + kPeriod + 5'000, 3.0), t0 + 120'000);
  EXPECT_EQ(clock.counters().late_samples, 1);
  clock.push_grasp({t0 + 2 * kPeriod, {}}, t0 + 121'000);
  clock.push_blade(blade_at(t0 + 2 * kPeriod + 1'000, 4.0), t0 + 121'000);
  const auto next = drain(clock, t0 + 121'000);
  ASSERT_EQ(next.size(), 1u);
  EXPECT_EQ(next[0].ys, (std::vector<double>{2.0, 3.0}));
}

// A tool the tracker stops reporting (the other tools' poses go on): its stream is not
// waited for once the tracker is gap_ms past its last sample; not counted as waited out.
TEST(ModelInputClock, AToolTheTrackerStoppedReportingIsNotWaitedFor) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0);
  clock.require_grasp();
  const std::int64_t t0 = 600 * kPeriod;
  std::size_t steps = 0;
  for (int k = 0; k < 30; ++k) {
    const std::int64_t t = t0 + k * kPeriod;
    if (k < 10) clock.push_grasp({t, {}}, t + 1'000);
    clock.tracker_at(t, t + 1'000);
    steps += drain(clock, t + 1'000).size();
  }
  // Steps 0..9 with the grasper; 10..28 once the tracker is 100 ms past its last pose.
  EXPECT_GE(steps, 30u - 7u);
  EXPECT_EQ(clock.counters().steps_waited_out, 0);
}

TEST(ModelInputClock, FarBehindItSkipsGridStepsButKeepsEverySample) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0);
  clock.require_blade();
  const std::int64_t t0 = 60 * kPeriod;
  for (int i = 0; i <= 180; ++i)  // 3 s of samples, the pedal up, no step
    clock.push_blade(blade_at(t0 + i * kPeriod, i, false), t0 + i * kPeriod + 1'000);
  const auto steps = drain(clock, t0 + 180 * kPeriod + 1'000);
  EXPECT_GT(clock.counters().steps_skipped, 100);
  std::size_t applied = 0;
  for (const auto& r : steps) applied += r.ys.size();
  EXPECT_EQ(applied, 181u) << "skipped grid steps drop model time, never blade samples";
  EXPECT_EQ(steps.back().t_us, t0 + 180 * kPeriod);
}

// Issue 20: a late model thread skipped grid steps in the middle of a stroke, so the blade
// samples of the skipped time all met the tissue as it was before (the grasper's pull of
// that time came in one jump after them) and the cut left the blade's path in the material.
// Far behind, it now skips only up to the stroke: the stroke's steps all run, each with its
// own samples, then it skips to the present.
TEST(ModelInputClock, FarBehindItSkipsUpToAStrokeRunsEachOfItsStepsThenSkipsOn) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0);
  clock.require_blade();
  const std::int64_t t0 = 60 * kPeriod;
  // 1 s with the pedal up, 1.5 s cutting, 1.5 s up; 4 samples a step, none stepped yet.
  const auto cutting_at = [&](std::int64_t t) { return t > t0 + 60 * kPeriod && t <= t0 + 150 * kPeriod; };
  for (int i = 0; i <= 4 * 240; ++i) {
    const std::int64_t t = t0 + i * kPeriod / 4;
    clock.push_blade(blade_at(t, i, cutting_at(t)), t + 1'000);
  }
  const auto steps = drain(clock, t0 + 240 * kPeriod + 1'000);
  int stroke_steps = 0;
  for (const auto& r : steps) {
    std::size_t cutting = 0;
    for (double y : r.ys) cutting += cutting_at(t0 + static_cast<std::int64_t>(y) * kPeriod / 4) ? 1 : 0;
    if (cutting == 0) continue;
    ++stroke_steps;
    EXPECT_EQ(cutting, 4u) << "step at " << r.t_us << ": each step of the stroke holds its own period's cutting samples";
  }
  EXPECT_EQ(stroke_steps, 90) << "every grid step of the stroke ran";
  EXPECT_GT(clock.counters().steps_skipped, 60) << "before and after the stroke it caught up by skipping";
  EXPECT_GT(clock.counters().steps_kept_for_cut, 30);
  EXPECT_EQ(clock.counters().cut_samples_merged, 0);
  std::size_t applied = 0;
  for (const auto& r : steps) applied += r.ys.size();
  EXPECT_EQ(applied, 4u * 240 + 1);
  EXPECT_EQ(steps.back().t_us, t0 + 240 * kPeriod);
}

// A model far too slow for the machine still comes back to the present: past cut_catch_up_ms
// behind, steps of a stroke are skipped too, and its samples that share a step are counted.
TEST(ModelInputClock, PastTheStrokesCatchUpLimitStrokeStepsAreSkippedAndCounted) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0, 2000.0);
  clock.require_blade();
  const std::int64_t t0 = 60 * kPeriod;
  for (int i = 0; i <= 180; ++i) clock.push_blade(blade_at(t0 + i * kPeriod, i), t0 + i * kPeriod + 1'000);  // 3 s cutting
  const auto steps = drain(clock, t0 + 180 * kPeriod + 1'000);
  EXPECT_LT(steps.size(), 10u);
  EXPECT_GT(clock.counters().steps_skipped, 170);
  EXPECT_GT(clock.counters().cut_samples_merged, 170);
  std::size_t applied = 0;
  for (const auto& r : steps) applied += r.ys.size();
  EXPECT_EQ(applied, 181u);
}

TEST(ModelInputClock, WithoutInputsTheHostClockDrivesItAndOverrunsAreNotCaughtUp) {
  ModelInputClock clock(60.0, 500.0, 1000.0, 100.0);
  EXPECT_FALSE(clock.has_inputs());
  const std::int64_t t0 = 60 * kPeriod;
  ASSERT_EQ(drain(clock, t0).size(), 1u);
  EXPECT_TRUE(drain(clock, t0 + 10'000).empty());
  EXPECT_EQ(drain(clock, t0 + 20'000).size(), 1u);
  EXPECT_LE(drain(clock, t0 + 500'000).size(), 2u) << "a late thread takes the current step, not a burst";
}

}  // namespace
}  // namespace arnav::host
