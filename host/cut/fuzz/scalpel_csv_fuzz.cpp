// libFuzzer target: the scalpel path CSV parser (arnav-sim --scalpel) on arbitrary text, and
// interpolation of whatever it accepts.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "host/cut/scalpel_path.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const cut::ScalpelPath path = cut::parse_scalpel_csv(text, "fuzz.csv");
    for (double t : {-1.0, path.samples.front().t_s, 0.5 * (path.samples.front().t_s + path.samples.back().t_s), 1e9}) {
      const cut::ScalpelSample s = path.at(t);
      if (!s.blade.tip_World_mm.allFinite() || !s.blade.heel_World_mm.allFinite()) std::abort();
    }
  } catch (const LoadError&) {
  }
  return 0;
}
