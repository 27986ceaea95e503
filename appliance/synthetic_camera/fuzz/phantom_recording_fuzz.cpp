// libFuzzer: the phantom recording reader must reject any text with PhantomError only,
// and what it accepts must interpolate and write back without failing.
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>

#include "appliance/synthetic_camera/phantom_recording.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const auto rec = arnav::camera_sim::parse_phantom_recording(std::string(reinterpret_cast<const char*>(data), size), "fuzz");
    (void)rec.at(0.5 * rec.duration_s());
    for (std::size_t i = 0; i < rec.tool_names.size(); ++i) (void)rec.tool_pose_at(0.3, static_cast<int>(i));
    std::ostringstream out;
    arnav::camera_sim::write_phantom_recording(out, rec);
  } catch (const arnav::camera_sim::PhantomError&) {
  }
  return 0;
}
