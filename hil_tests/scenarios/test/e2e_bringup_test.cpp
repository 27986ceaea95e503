// End to end on the HIL bench: the real arnav-appliance (libserialport path) against the
// simulated Polaris, poses over LCM udpm in a private network namespace. Bring-up,
// poses equal to the simulator's ground truth at the wire resolution (BX and TX), clean
// shutdown, and arnav-host's view of the same stream.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <map>

#include <nlohmann/json.hpp>

#include "hil_tests/scenarios/hil_run.hpp"
#include "protocol/clock.hpp"
#include "hil_tests/bench/bench_required.hpp"

namespace arnav::hil {
namespace {

// All valid poses match the truth; counts consecutive duplicates per tool.
void expect_poses_match_truth(HilRun& run, Resolution res, std::size_t min_checked) {
  const TruthTable truth = run.truth();
  ASSERT_FALSE(truth.empty());
  std::size_t checked = 0, mismatches = 0;
  std::map<std::string, std::int64_t> last_frame;
  std::size_t duplicates = 0;
  for (const auto& p : run.lcm().poses()) {
    auto [it, inserted] = last_frame.emplace(p.msg.tool_name, p.msg.device_frame_number);
    if (!inserted) {
      if (it->second == p.msg.device_frame_number) ++duplicates;
      it->second = p.msg.device_frame_number;
    }
    if (p.msg.status != tool_pose_t::STATUS_VALID) continue;
    EXPECT_EQ(p.msg.frame_parent, "Ndi");
    const std::string diff = compare_to_truth(p.msg, truth, res);
    if (!diff.empty() && ++mismatches <= 5) ADD_FAILURE() << diff;
    ++checked;
  }
  EXPECT_EQ(mismatches, 0u);
  EXPECT_EQ(duplicates, 0u) << "the same device frame was published twice for a tool";
  EXPECT_GE(checked, min_checked);
  std::printf("[ hil ] %zu published poses checked against ground truth, %zu mismatches\n", checked, mismatches);
}

void run_bring_up(const std::string& reply_mode, Resolution res) {
  HilRun run;
  HilRunOptions o;
  o.reply_mode = reply_mode;
  const std::int64_t t0 = monotonic_us();
  const std::string why = run.start(o);
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.wait_all_valid(120, t0, 90.0)) << "no tracking within 90 s\n" << run.lcm().event_log() << run.logs();
  const auto first = run.lcm().first_valid_after(run.tool_names()[0], t0);
  std::printf("[ hil ] %s: bring-up to first valid pose %.2f s\n", reply_mode.c_str(), static_cast<double>(*first - t0) * 1e-6);
  EXPECT_GE(run.lcm().events_after("NDI_TRACKING_STARTED", t0), 1u) << run.lcm().event_log();
  // A health message with the tracking link and latency percentiles.
  ASSERT_TRUE(run.lcm().wait_for(
      [](const LcmCapture& l) {
        for (const auto& h : l.health())
          if (h.msg.link_state == device_health_t::LINK_TRACKING && h.msg.frames_total > 0) return true;
        return false;
      },
      15.0))
      << run.logs();
  const auto health = run.lcm().health().back().msg;
  std::printf("[ hil ] %s: health %.1f Hz, latency p50 %.0f us, p99 %.0f us, max %.0f us\n", reply_mode.c_str(),
              static_cast<double>(health.frame_rate_hz), static_cast<double>(health.latency_p50_us),
              static_cast<double>(health.latency_p99_us), static_cast<double>(health.latency_max_us));

  const std::int64_t t_stop = monotonic_us();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
  EXPECT_TRUE(run.lcm().wait_for([&](const LcmCapture& l) { return l.events_after("NDI_TRACKING_STOPPED", t_stop) >= 1; }, 5.0))
      << "no clean TSTOP on shutdown\n" << run.lcm().event_log();
  EXPECT_EQ(run.stop_simulator(), 0) << run.logs();
  expect_poses_match_truth(run, res, 200);
  if (::testing::Test::HasFailure()) std::fprintf(stderr, "%s", run.logs().c_str());
}

TEST(HilBringUp, BxPosesEqualGroundTruthAndShutdownIsClean) { run_bring_up("bx", kBxResolution); }

TEST(HilBringUp, TxPosesEqualGroundTruthAtTxResolution) { run_bring_up("tx", kTxResolution); }

TEST(HilBringUp, HostSeesFreshToolsWithoutGaps) {
  if (host_exe().empty()) GTEST_SKIP() << "arnav-host is not built (ARNAV_WITH_HOST=OFF)";
  HilRun run;
  const std::int64_t t0 = monotonic_us();
  const std::string why = run.start(HilRunOptions{});
  ARNAV_BENCH_OR_SKIP(why);
  ASSERT_TRUE(run.wait_all_valid(30, t0, 90.0)) << run.logs();
  const std::string summary = run.dir() + "/host.json";
  ChildProcess host({host_exe(), "--lcm-url", HilRun::kLcmUrl, "--security", "off", "--duration", "4", "--quiet", "--stale-after-ms", "500",
                     "--summary-json", summary},
                    {}, run.dir() + "/host.log");
  ASSERT_EQ(host.wait(60.0).value_or(-1), 0) << host.log_tail();
  std::ifstream in(summary);
  const nlohmann::json j = nlohmann::json::parse(in);
  for (const auto& tool : run.tool_names()) {
    const auto& t = j.at("tools").at(tool);
    EXPECT_GT(t.at("valid").get<int>(), 60) << tool;
    EXPECT_FALSE(t.at("stale_at_exit").get<bool>()) << tool;
    EXPECT_EQ(t.at("duplicate_frames").get<int>(), 0) << tool;
    EXPECT_EQ(t.at("sequence_gaps").get<int>(), 0) << tool;
  }
  EXPECT_NE(host.log_tail().find("fresh"), std::string::npos) << host.log_tail();
  EXPECT_EQ(run.stop_appliance(), 0) << run.logs();
}

}  // namespace
}  // namespace arnav::hil
