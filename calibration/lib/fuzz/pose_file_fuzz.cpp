// libFuzzer: the pose-list parser must either return poses or throw CalibError.
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
  return 0;
}
