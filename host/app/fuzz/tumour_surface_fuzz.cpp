// libFuzzer: the tumour_Cam.bin reader (arnav-ar-error --tumour-surfaces) must reject any
// bytes with TumourSurfaceFileError only, and every surface it accepts has triangles that
// index its own vertices.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <sstream>
#include <string>

#include "host/app/tumour_surface_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::istringstream in(std::string(reinterpret_cast<const char*>(data), size));
  try {
    for (const auto& [seq, m] : arnav::host::parse_tumour_surfaces(in, "fuzz"))
      for (const auto& t : m.tris)
        for (int v : t)
          if (v < 0 || v >= m.positions_World_mm.cols()) std::abort();
  } catch (const arnav::host::TumourSurfaceFileError&) {
  }
  return 0;
}
