#include "appliance/ndi/test/capture.hpp"

#include <cstdlib>
#include <fstream>
#include <stdexcept>

namespace arnav::ndi::test {

std::filesystem::path data_dir() {
  if (const char* dir = std::getenv("ARNAV_DATA_DIR")) return dir;
  throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
}

std::vector<TranscriptRecord> load_capture() {
  const auto path = data_dir() / "ndi_captures" / "polaris_classic_stream.txt";
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path.string());
  return import_igstk_log(in, path.string());
}

}  // namespace arnav::ndi::test
