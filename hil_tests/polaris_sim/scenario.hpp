#pragma once
// What the simulated Polaris does: its tools (ROM, motion), frame rate and the faults to
// inject. Read from a YAML scenario file (docs/hil.md) and/or the command line. Fault
// commands are one-line texts ("cable_pull 2.0") shared by scenario files and the
// control socket, so tests, the demo and hand sessions speak the same language.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "hil_tests/polaris_sim/marker_measurement.hpp"
#include "hil_tests/polaris_sim/tool_motion.hpp"

namespace arnav::hil {

// Thrown for a bad scenario file or fault command; the message names the input.
struct ScenarioError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct SimTool {
  std::string name;
  std::vector<std::uint8_t> rom;  // tool definition; empty: matched by loading order
  std::string rom_path;           // for messages
  std::string serial = "00000000";  // 8 chars, reported by PHINF
  ToolMotion motion;
  double rms_error_mm = 0.12;      // reported by the ideal model (the realistic one reports its fit's)
  // The marker spheres in the tool frame (mm): markers_mm, else the ROM's, else
  // default_marker_geometry(); the realistic measurement fits them (marker_measurement.hpp).
  std::vector<Eigen::Vector3d> markers_Tool_mm = default_marker_geometry();
};

struct FaultCommand {
  enum class Kind {
    kCablePull,     // port disappears for duration_s, then returns; device state kept
    kReset,         // spontaneous device reset: RESET at 9600, state lost
    kDropBytes,     // drop `count` bytes of the next reply
    kGarble,        // flip bits in `count` bytes of the next reply
    kBadCrc,        // next reply carries a wrong CRC
    kPartial,       // next reply cut short (its tail is never sent)
    kChunked,       // replies for duration_s go out in small chunks with gaps
    kGarbage,       // `count` random bytes before the next reply
    kMissing,       // tool `tool` not seen for duration_s
    kOutOfVolume,   // tool `tool` outside the characterised volume for duration_s
    kSlow,          // next `count` replies delayed by delay_s
    kNoReply,       // next `count` commands get no reply
    kError,         // next `count` commands answered ERROR<code>
    kBaudMismatch,  // device silently moves to another baud rate (`baud`)
  };
  Kind kind = Kind::kReset;
  double duration_s = 0.0;
  double delay_s = 0.0;
  int count = 1;
  std::uint8_t code = 0;
  int baud = 0;
  std::string tool;
  std::string text;  // the command as written, for logs
};

// Parses one fault command line. Throws ScenarioError naming `where` on bad input.
FaultCommand parse_fault(const std::string& line, const std::string& where = "fault command");

struct TimedFault {
  double at_s = 0.0;  // seconds after the first TSTART of the session
  FaultCommand fault;
};

struct Scenario {
  double frame_rate_hz = 60.0;
  std::uint32_t first_frame = 1000;
  std::string serial_number = "P9-00042";
  std::vector<SimTool> tools;
  std::vector<TimedFault> faults;
  // The bench's world clock (epoch_mono_us: a CLOCK_MONOTONIC time, microseconds): when
  // set, the tools' motions run on the time since it (the frame's time), not on the time
  // since the device booted, so the simulated Polaris, the synthetic camera's phantom and
  // the CAN simulator's steps that name the same epoch see the same world at the same
  // instant however late each of them starts (docs/hil.md).
  std::optional<std::int64_t> epoch_mono_us;
  // How tools are measured (measurement: {model: ideal|realistic, marker_noise_rms_mm,
  // dropout_rate, seed}); ideal when the scenario has no such block (docs/hil.md).
  MeasurementModel measurement;
};

// Applies "ideal" or "realistic" (--sensors) over the scenario's measurement block; a seed
// given on the command line (--sensor-seed) replaces the scenario's. Throws ScenarioError.
void set_sensors(Scenario& scenario, const std::string& sensors, std::optional<std::uint64_t> seed);

inline constexpr double kMaxFrameRateHz = 400.0;

// Loads a scenario file; ROM paths are relative to the file's folder.
Scenario load_scenario(const std::filesystem::path& file);
// Same from text (the fuzzer's entry point); `base_dir` resolves ROM paths.
Scenario parse_scenario(const std::string& yaml_text, const std::string& source_name,
                        const std::filesystem::path& base_dir);
// Adds a tool given as NAME=ROM_PATH (command line), with the default motion.
void add_tool_spec(Scenario& scenario, const std::string& spec);
// Reads a .rom file; throws ScenarioError naming the file if it is unreadable or not NDI.
std::vector<std::uint8_t> read_rom(const std::filesystem::path& file);

}  // namespace arnav::hil
