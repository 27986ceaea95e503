// libFuzzer target: scenario files, scripted tool paths (CSV) and fault command lines, the simulator's own text
// inputs (recordings are read by appliance/ndi's transcript reader, fuzzed there).
#include <cstddef>
#include <cstdint>
#include <string>

#include "hil_tests/polaris_sim/scenario.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    arnav::hil::parse_scenario(text, "fuzz.yaml", "/nonexistent-fuzz-dir");
  } catch (const arnav::hil::ScenarioError&) {
  }
  try {
    const auto path = arnav::hil::parse_tool_path_csv(text, "fuzz.csv");
    (void)path.X_ModelTool(0.5 * (path.t_s.front() + path.t_s.back()));
  } catch (const arnav::hil::ToolPathError&) {
  }
  try {
    arnav::hil::parse_fault(text);
  } catch (const arnav::hil::ScenarioError&) {
  }
  return 0;
}
