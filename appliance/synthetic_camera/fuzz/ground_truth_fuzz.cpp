// libFuzzer: the ground-truth CSV reader must reject any text with GroundTruthError only.
#include <cstddef>
#include <cstdint>
#include <string>

#include "appliance/synthetic_camera/ground_truth.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    arnav::camera_sim::parse_ground_truth(std::string(reinterpret_cast<const char*>(data), size), "fuzz");
  } catch (const arnav::camera_sim::GroundTruthError&) {
  }
  return 0;
}
