// libFuzzer target: the point-cloud, landmark and target parsers and the point_cloud_t
// decoder on arbitrary bytes. The first byte picks the parser; errors must surface as
// LoadError, never as a crash or a huge allocation.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/register/point_cloud.hpp"
#include "host/register/point_files.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  static const char* formats[] = {"xyz", "csv", "ply", "obj", "vtk"};
  try {
    if (data[0] >= 224) {  // the LCM message decoder
      decode_point_cloud_message(data + 1, size - 1, "fuzz");
    } else if (data[0] % 7 == 5) {
      parse_landmarks(text, "fuzz_landmarks.csv");
    } else if (data[0] % 7 == 6) {
      parse_targets(text, "fuzz_targets.csv");
    } else {
      const char* f = formats[data[0] % 7 % 5];
      parse_point_cloud(text, std::string("fuzz.") + f, f);
    }
  } catch (const LoadError&) {
  }
  return 0;
}
