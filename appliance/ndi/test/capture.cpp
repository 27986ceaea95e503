#include "appliance/ndi/test/capture.hpp"

#include <cstdlib>
#include <fstream>
#include <stdexcept>

namespace arnav::ndi::test {

std::filesystem::path shared_dir() {
  if (const char* dir = std::getenv("ARNAV_SHARED_DIR")) return dir;
  throw std::runtime_error("ARNAV_SHARED_DIR is not set (run the test through ctest)");
}

std::vector<TranscriptRecord> load_capture() {
  const auto path = shared_dir() / "data" / "ndi_captures" / "polaris_classic_stream.txt";
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path.string());
  return import_igstk_log(in, path.string());
}

}  // namespace arnav::ndi::test
