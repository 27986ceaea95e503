// libFuzzer target: the scene-file and vessel-tree YAML schema checks on arbitrary text.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/mesh/load_error.hpp"
#include "host/scene/scene_spec.hpp"

using namespace arnav::host;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    parse_scene_spec(text, "fuzz.scene.yaml");
  } catch (const LoadError&) {
  }
  try {
    parse_vessel_tree(text, "fuzz.vessels.yaml");
  } catch (const LoadError&) {
  }
  return 0;
}
