// arnav-can-sim's scenario files and command checking (no bus needed).
#include <gtest/gtest.h>

#include <filesystem>
#include <chrono>
#include <fstream>
#include <thread>

#include "appliance/can/test/test_config.hpp"
#include "hil_tests/can_sim/can_sim.hpp"
#include "protocol/clock.hpp"

namespace arnav::hil {
namespace {

std::string write(const std::string& name, const std::string& text) {
  const auto p = std::filesystem::temp_directory_path() / ("arnav_can_sim_test_" + std::to_string(::getpid()) + "_" + name);
  std::ofstream(p) << text;
  return p.string();
}

TEST(CanSimScenario, ParsesSteps) {
  const auto path = write("ok.yaml", "steps:\n  - {at_s: 0.5, do: \"press pedal_cut\"}\n  - {at_s: 1, do: \"bus_off 0.2\"}\n");
  const auto steps = load_can_scenario(path);
  ASSERT_EQ(steps.size(), 2u);
  EXPECT_EQ(steps[0].at_s, 0.5);
  EXPECT_EQ(steps[1].command, "bus_off 0.2");
  std::filesystem::remove(path);
}

TEST(CanSimScenario, ErrorsNameFileAndLine) {
  auto expect = [](const std::string& text, const std::string& want) {
    const auto path = write("bad.yaml", text);
    try {
      (void)load_can_scenario(path);
      ADD_FAILURE() << "no error for " << text;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(path + want), std::string::npos) << e.what();
    }
    std::filesystem::remove(path);
  };
  expect("steps:\n  - {at_s: -1, do: press}\n", ":2: at_s must be >= 0");
  expect("steps:\n  - {at: 1, do: press}\n", ":2: a step is {at_s: SECONDS, do: COMMAND}");
  expect("stepz: []\n", ":1: unknown key 'stepz'");
  expect("steps: [\n", ":2: YAML syntax error");
  try {
    (void)load_can_scenario("/nonexistent/scenario.yaml");
    ADD_FAILURE();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot read"), std::string::npos);
  }
}

TEST(CanSimCommands, DryRunChecksWithoutActing) {
  CanSim sim({}, *can::parse_can_config(can::test::kPedalConfig, "t.yaml"));
  EXPECT_EQ(sim.command("train pedal_cut 5 10", true), "OK");
  EXPECT_EQ(sim.command("frame 123#00", true), "OK");
  EXPECT_EQ(sim.frames_sent(), 0);
  EXPECT_EQ(sim.command("train pedal_cut five 10", true).rfind("ERROR usage", 0), 0u);
  EXPECT_EQ(sim.command("frame 123#00"), "OK");
  EXPECT_EQ(sim.frames_sent(), 1);
}

TEST(CanSimCommands, CheckedBeforeTheyRun) {
  CanSim sim({}, *can::parse_can_config(can::test::kPedalConfig, "t.yaml"));
  EXPECT_EQ(sim.command("press pedal_cut"), "OK");
  EXPECT_EQ(sim.command("bounce pedal_cut 3 2"), "OK");
  EXPECT_EQ(sim.command("value pedal_analog 900"), "OK");
  EXPECT_EQ(sim.command("node pedal off"), "OK");
  EXPECT_EQ(sim.command("frame 123#DEADBEEF"), "OK");
  EXPECT_EQ(sim.command("press nothing").rfind("ERROR no input 'nothing'", 0), 0u);
  EXPECT_EQ(sim.command("node nobody off").rfind("ERROR no device 'nobody'", 0), 0u);
  EXPECT_EQ(sim.command("value pedal_cut 3").rfind("ERROR usage", 0), 0u);  // not analogue
  EXPECT_EQ(sim.command("bus_off -1").rfind("ERROR usage", 0), 0u);
  EXPECT_EQ(sim.command("frame 123#XYZ").rfind("ERROR usage", 0), 0u);
  EXPECT_EQ(sim.command("garbage 10").rfind("ERROR garbage is for the slcan path", 0), 0u);  // no pty here
  EXPECT_EQ(sim.command("jump").rfind("ERROR unknown command 'jump'", 0), 0u);
}

}  // namespace
}  // namespace arnav::hil

namespace arnav::hil {
namespace {

// --epoch-mono-us (the bench's world clock, docs/hil.md): a step runs at epoch + at_s on
// CLOCK_MONOTONIC, not at the simulator's start; one already past runs at once.
TEST(CanSimCommands, StepsOnTheWorldClockRunAtEpochPlusAt) {
  CanSim sim({}, *can::parse_can_config(can::test::kPedalConfig, "t.yaml"));
  const std::int64_t epoch = monotonic_us() + 300'000;
  sim.schedule_from_epoch(epoch, 0.1, "frame 123#00");      // at epoch + 0.1 s
  sim.schedule_from_epoch(epoch - 10'000'000, 2.0, "frame 124#00");  // 8 s ago: at once
  volatile bool stop = false;
  std::thread t([&] { sim.run(stop); });
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  const std::int64_t early = sim.frames_sent();
  while (monotonic_us() < epoch + 250'000) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  stop = true;
  t.join();
  EXPECT_EQ(early, 1) << "only the past step by 150 ms";
  EXPECT_EQ(sim.frames_sent(), 2) << "the world-clock step by epoch + 0.25 s";
}

}  // namespace
}  // namespace arnav::hil
