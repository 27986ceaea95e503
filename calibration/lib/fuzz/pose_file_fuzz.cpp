// libFuzzer: the pose-list and point-list parsers must either return poses or throw CalibError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/pose_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const auto poses = arnav::calib::parse_pose_list(text, "fuzz");
    for (const auto& p : poses) {
      if (!p.X_ParentChild.matrix().allFinite()) __builtin_trap();
    }
  } catch (const arnav::calib::CalibError&) {
  }
  try {
    const auto points = arnav::calib::parse_point_list(text, "fuzz");
    for (const auto& p : points) {
      if (!p.allFinite()) __builtin_trap();
    }
  } catch (const arnav::calib::CalibError&) {
  }
  return 0;
}
