#include <gtest/gtest.h>

#include <filesystem>
#include <cmath>
#include <fstream>
#include <numbers>
#include <unistd.h>

#include "hil_tests/polaris_sim/device_model.hpp"
#include "hil_tests/polaris_sim/scenario.hpp"
#include "protocol/testing/error_of.hpp"

namespace arnav::hil {
namespace {

std::string source_dir() { return std::string(std::getenv("ARNAV_SOURCE_DIR")); }
std::string data_dir() { return std::string(std::getenv("ARNAV_DATA_DIR")); }

TEST(Scenario, ParsesToolsMotionAndFaults) {
  const std::string yaml = R"(
frame_rate_hz: 400
first_frame: 7
tools:
  - name: pointer
    rom: data/ndi_roms/8700340.rom
    serial: 3A2B1C00
    motion: {center_mm: [10, 20, -1500], amplitude_mm: [0, 0, 0], rotation_amplitude_rad: 0}
  - name: reference
faults:
  - {at_s: 2.5, do: "cable_pull 1.5"}
  - {at_s: 4, do: "missing reference 0.5"}
)";
  const Scenario s = parse_scenario(yaml, "test.yaml", source_dir());
  EXPECT_EQ(s.frame_rate_hz, 400.0);
  EXPECT_EQ(s.first_frame, 7u);
  ASSERT_EQ(s.tools.size(), 2u);
  EXPECT_EQ(s.tools[0].rom.size(), 752u);
  EXPECT_EQ(s.tools[0].serial, "3A2B1C00");
  EXPECT_TRUE(s.tools[1].rom.empty());
  const Eigen::Isometry3d X = s.tools[0].motion.X_NdiTool(3.0);
  EXPECT_TRUE(X.translation().isApprox(Eigen::Vector3d(10, 20, -1500)));
  ASSERT_EQ(s.faults.size(), 2u);
  EXPECT_EQ(s.faults[0].fault.kind, FaultCommand::Kind::kCablePull);
  EXPECT_EQ(s.faults[0].fault.duration_s, 1.5);
  EXPECT_EQ(s.faults[1].fault.tool, "reference");
}

TEST(Scenario, ErrorsNameTheInput) {
  const auto error_of = [](const std::string& yaml) {
    return arnav::testing::error_of<ScenarioError>([&] { parse_scenario(yaml, "bad.yaml", "/nonexistent"); });
  };
  EXPECT_NE(error_of("frame_rate_hz: 1000").find("bad.yaml: frame_rate_hz"), std::string::npos);
  EXPECT_NE(error_of("tools: [{name: a, colour: red}]").find("unknown key 'colour'"), std::string::npos);
  EXPECT_NE(error_of("tools: [{name: a, rom: x.rom}]").find("/nonexistent/x.rom"), std::string::npos);
  EXPECT_NE(error_of("tools: [{name: a}, {name: a}]").find("duplicate"), std::string::npos);
  EXPECT_NE(error_of("faults: [{at_s: 1, do: explode}]").find("unknown fault 'explode'"), std::string::npos);
  EXPECT_NE(error_of("frame_rate_hz: [1").find("bad.yaml: line"), std::string::npos);
  EXPECT_NE(error_of("tools: [{name: a, motion: {center_mm: [1, 2]}}]").find("3 numbers"), std::string::npos);
}

TEST(Scenario, FaultCommands) {
  EXPECT_EQ(parse_fault("reset").kind, FaultCommand::Kind::kReset);
  EXPECT_EQ(parse_fault("garble 3").count, 3);
  EXPECT_EQ(parse_fault("error 0c 2").code, 0x0C);
  EXPECT_EQ(parse_fault("slow 0.5 4").delay_s, 0.5);
  EXPECT_EQ(parse_fault("baud_mismatch 57600").baud, 57600);
  EXPECT_THROW(parse_fault("cable_pull"), ScenarioError);
  EXPECT_THROW(parse_fault("cable_pull -1"), ScenarioError);
  EXPECT_THROW(parse_fault("garble 1.5"), ScenarioError);
  EXPECT_THROW(parse_fault("error 123"), ScenarioError);
  EXPECT_THROW(parse_fault("baud_mismatch 12345"), ScenarioError);
  EXPECT_THROW(parse_fault("reset now"), ScenarioError);
  EXPECT_THROW(parse_fault(""), ScenarioError);
}

TEST(Scenario, RomFilesAreChecked) {
  EXPECT_EQ(read_rom(data_dir() + "/ndi_roms/8700248.rom").size(), 752u);
  EXPECT_THROW(read_rom(data_dir() + "/ndi_captures/polaris_classic_stream.txt"), ScenarioError);
  Scenario s;
  EXPECT_THROW(add_tool_spec(s, "pointer"), ScenarioError);
  EXPECT_THROW(add_tool_spec(s, "pointer=/nonexistent.rom"), ScenarioError);
}

TEST(Scenario, PhantomMotionFollowsTheRecordedTool) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_phsim_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  camera_sim::PhantomRecording rec;
  rec.tool_names = {"grasper", "scalpel"};
  rec.target_names = {"tumour_centroid"};
  rec.vertex_count = 3;
  rec.faces = {{0, 1, 2}};
  for (int k = 0; k < 2; ++k) {
    camera_sim::PhantomFrame f;
    f.t_s = k;
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.translation() = Eigen::Vector3d(70, 160, 57 - 20.0 * k);
    f.X_ModelTool = {X, Eigen::Isometry3d::Identity()};
    f.targets_Model_mm = {Eigen::Vector3d(70, 160, 140)};
    f.vertices_Model_mm = Eigen::Matrix3Xd::Identity(3, 3);
    rec.frames.push_back(f);
  }
  camera_sim::write_phantom_recording(dir / "phantom.txt", rec);
  const std::string yaml = R"(
frame_rate_hz: 60
first_frame: 600
tools:
  - name: scalpel
    motion: {phantom: phantom.txt, tool: grasper, X_NdiModel: [1, 0, 0, -198,  0, 1, 0, -138,  0, 0, 1, -1590,  0, 0, 0, 1]}
)";
  const Scenario s = parse_scenario(yaml, "sim.yaml", dir);
  ASSERT_EQ(s.tools.size(), 1u);
  // Device time 600 / 60 = 10 s is the recording's start; halfway through: 10.5 s.
  const Eigen::Isometry3d X = s.tools[0].motion.X_NdiTool(10.5);
  EXPECT_TRUE(X.translation().isApprox(Eigen::Vector3d(70 - 198, 160 - 138, 47 - 1590), 1e-9)) << X.translation().transpose();
  EXPECT_TRUE(s.tools[0].motion.X_NdiTool(100.0).translation().isApprox(Eigen::Vector3d(-128, 22, 37 - 1590), 1e-9));
  const auto expect_error = [&](const std::string& from, const std::string& to, const std::string& needle) {
    std::string text = yaml;
    text.replace(text.find(from), from.size(), to);
    try {
      parse_scenario(text, "sim.yaml", dir);
      ADD_FAILURE() << "accepted:\n" << text;
    } catch (const ScenarioError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error("tool: grasper", "tool: pointer", "has no tool 'pointer'");
  expect_error("phantom: phantom.txt", "phantom: none.txt", "none.txt: cannot read the phantom recording");
  expect_error(", X_NdiModel: [1, 0, 0, -198,  0, 1, 0, -138,  0, 0, 1, -1590,  0, 0, 0, 1]", "", "X_NdiModel: missing");
  expect_error("[1, 0, 0, -198,", "[2, 0, 0, -198,", "not a rigid transform");
  expect_error("tool: grasper", "tool: grasper, speed: 2", "unknown key 'speed'");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil

namespace arnav::hil {
namespace {

TEST(ToolPath, PiecewiseLinearInModelPlacedByXNdiModel) {
  const ScriptedToolPath p = parse_tool_path_csv(
      "t_s,x_mm,y_mm,z_mm\n# comment\n\n0, 0, 0, 0\n2, 10, -20, 4\n3, 10, -20, 4\n", "p.csv");
  ASSERT_EQ(p.t_s.size(), 3u);
  EXPECT_TRUE(p.X_ModelTool(1.0).translation().isApprox(Eigen::Vector3d(5, -10, 2)));
  EXPECT_TRUE(p.X_ModelTool(-5.0).translation().isZero());
  EXPECT_TRUE(p.X_ModelTool(99.0).translation().isApprox(Eigen::Vector3d(10, -20, 4)));
  EXPECT_TRUE(p.X_ModelTool(1.0).linear().isIdentity(1e-12));
  // Orientation columns: slerp between rows.
  const double s = std::sqrt(0.5);
  const ScriptedToolPath q = parse_tool_path_csv("0,0,0,0,1,0,0,0\n1,0,0,0," + std::to_string(s) + ",0,0," + std::to_string(s) + "\n", "q.csv");
  const Eigen::AngleAxisd aa(q.X_ModelTool(0.5).linear());
  EXPECT_NEAR(std::abs(aa.angle()), std::numbers::pi / 4, 1e-5);
}

TEST(ToolPath, ScenarioPlacesThePathAndShiftsByStartAndBoot) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("arnav_path_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    std::ofstream f(dir / "tip.csv");
    f << "t_s,x_mm,y_mm,z_mm\n0,0,0,0\n10,100,0,0\n";
  }
  const std::string yaml = R"(
frame_rate_hz: 50
first_frame: 100
tools:
  - name: pointer
    motion: {path: tip.csv, start_s: 1, X_NdiModel: [1, 0, 0, 5,  0, 1, 0, 6,  0, 0, 1, -1500,  0, 0, 0, 1]}
)";
  const Scenario s = parse_scenario(yaml, "sc.yaml", dir);
  ASSERT_EQ(s.tools.size(), 1u);
  // device time 2 s = boot (100/50) -> path time start_s = 1 s -> x = 10.
  EXPECT_TRUE(s.tools[0].motion.X_NdiTool(2.0).translation().isApprox(Eigen::Vector3d(15, 6, -1500)));
  EXPECT_TRUE(s.tools[0].motion.X_NdiTool(6.0).translation().isApprox(Eigen::Vector3d(55, 6, -1500)));
  auto err = [&](const std::string& y) { return arnav::testing::error_of<ScenarioError>([&] { parse_scenario(y, "sc.yaml", dir); }); };
  EXPECT_NE(err("tools:\n  - name: a\n    motion: {path: nope.csv, X_NdiModel: [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}\n").find("cannot read"), std::string::npos);
  EXPECT_NE(err("tools:\n  - name: a\n    motion: {path: tip.csv}\n").find("X_NdiModel: missing"), std::string::npos);
  EXPECT_NE(err("tools:\n  - name: a\n    motion: {path: tip.csv, X_NdiModel: [2,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}\n").find("not a rigid"), std::string::npos);
  EXPECT_NE(err("tools:\n  - name: a\n    motion: {path: tip.csv, speed: 3, X_NdiModel: [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}\n").find("unknown key 'speed'"), std::string::npos);
  {
    std::ofstream f(dir / "bad.csv");
    f << "t_s,x_mm,y_mm,z_mm\n0,0,0,0\n1,0,x,0\n";
  }
  const std::string e = err("tools:\n  - name: a\n    motion: {path: bad.csv, X_NdiModel: [1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}\n");
  EXPECT_NE(e.find("bad.csv:3: column y_mm must be a finite number, got 'x'"), std::string::npos) << e;
  std::filesystem::remove_all(dir);
}

TEST(ToolPath, BadRowsNameTheLine) {
  auto err = [](const std::string& text) { return arnav::testing::error_of<ToolPathError>([&] { parse_tool_path_csv(text, "p.csv"); }); };
  EXPECT_NE(err("").find("p.csv: no path rows"), std::string::npos);
  EXPECT_NE(err("t_s,x_mm,y_mm,z_mm\n").find("no path rows"), std::string::npos);
  EXPECT_NE(err("0,1,2\n").find("p.csv:1: expected 4 columns"), std::string::npos);
  EXPECT_NE(err("0,1,2,3,\n").find("p.csv:1: expected 4 columns"), std::string::npos);
  EXPECT_NE(err("0,1,2,3\n1,1,2,nan\n").find("p.csv:2: column z_mm must be a finite number"), std::string::npos);
  EXPECT_NE(err("0,1,2,3\n0,1,2,3\n").find("p.csv:2: t_s must increase strictly"), std::string::npos);
  EXPECT_NE(err("-1,1,2,3\n").find("p.csv:1: t_s -1 is outside"), std::string::npos);
  EXPECT_NE(err("0,1,2,3000\n").find("p.csv:1: z_mm is outside"), std::string::npos);
  EXPECT_NE(err("0,1,2,3,1,1,0,0\n").find("p.csv:1: orientation qw, qx, qy, qz must be a unit quaternion"), std::string::npos);
  EXPECT_NE(err("t_s,x_mm,y_mm,z_mm\nt_s,x_mm,y_mm,z_mm\n").find("p.csv:2: column t_s"), std::string::npos);
}

}  // namespace
}  // namespace arnav::hil

namespace arnav::hil {
namespace {

// The bench's world clock (docs/hil.md "World clock"): with epoch_mono_us the tools' motions
// run on the frame's CLOCK_MONOTONIC time minus the epoch, whenever the device booted; without
// it, on the time since the boot. A negative epoch is refused.
TEST(Scenario, WorldClockEpochShiftsTheMotionToTheSharedTime) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / ("arnav_epoch_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    std::ofstream f(dir / "tip.csv");
    f << "t_s,x_mm,y_mm,z_mm\n0,0,0,0\n100,1000,0,0\n";  // 10 mm per second of path time
  }
  const std::string base = "frame_rate_hz: 50\nfirst_frame: 100\ntools:\n  - name: pointer\n"
                           "    motion: {path: tip.csv, X_NdiModel: [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}\n";
  // Monotonic clock 1000 s at the simulator's time 0; the device booted 2.5 s later; the
  // world's epoch at monotonic 1001 s.
  PolarisModel with_epoch(parse_scenario(base + "epoch_mono_us: 1001000000\n", "sc.yaml", dir));
  with_epoch.set_clock_origin_mono_s(1000.0);
  with_epoch.reset(2.5);
  PolarisModel without(parse_scenario(base, "sc.yaml", dir));
  without.set_clock_origin_mono_s(1000.0);
  without.reset(2.5);
  // Frame 100 + 50: 1 s after the boot = monotonic 1003.5 s = world 2.5 s.
  const auto x_at = [&](const PolarisModel& m, std::uint32_t frame) {
    return parse_scenario(base, "sc.yaml", dir).tools[0].motion.X_NdiTool(m.motion_time_s(frame)).translation().x();
  };
  EXPECT_NEAR(x_at(with_epoch, 150), 25.0, 1e-6);
  EXPECT_NEAR(x_at(without, 150), 10.0, 1e-6);
  // Another boot time, same world instant, same pose.
  PolarisModel late(parse_scenario(base + "epoch_mono_us: 1001000000\n", "sc.yaml", dir));
  late.set_clock_origin_mono_s(1000.0);
  late.reset(3.0);  // booted 0.5 s later: monotonic 1003.5 s is its frame 100 + 25
  EXPECT_NEAR(x_at(late, 125), 25.0, 1e-6);
  try {
    parse_scenario(base + "epoch_mono_us: -5\n", "sc.yaml", dir);
    ADD_FAILURE() << "a negative epoch was accepted";
  } catch (const ScenarioError& e) {
    EXPECT_NE(std::string(e.what()).find("epoch_mono_us"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace arnav::hil
