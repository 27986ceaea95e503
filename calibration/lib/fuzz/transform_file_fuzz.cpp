// libFuzzer: the rigid transform parser must either return a rigid transform or throw
// CalibError.
#include <cstddef>
#include <cstdint>
#include <string>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/rigid_transform_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const auto r = arnav::calib::parse_transform(text, "fuzz");
    if (!r.X_ParentChild.matrix().allFinite()) __builtin_trap();
  } catch (const arnav::calib::CalibError&) {
  }
  return 0;
}
