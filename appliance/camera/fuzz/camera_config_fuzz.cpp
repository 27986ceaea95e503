// libFuzzer: the camera: and frames: sections of the appliance configuration must turn any
// text into a configuration or a CameraConfigError, nothing else.
#include <cstddef>
#include <cstdint>
#include <string>

#include "appliance/camera/camera_config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    arnav::camera::parse_camera_config(text, "fuzz.yaml", "/nonexistent");
  } catch (const arnav::camera::CameraConfigError&) {
  }
  try {
    arnav::camera::parse_frames_config(text, "fuzz.yaml", "/nonexistent");
  } catch (const arnav::camera::CameraConfigError&) {
  }
  return 0;
}
