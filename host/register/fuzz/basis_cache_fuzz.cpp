// libFuzzer target: the load basis cache file reader (basis_cache_file.hpp) on arbitrary
// bytes. Every defect must surface as LoadError, never as a crash, an out-of-bounds read or
// an allocation larger than the input. Also round-trips every accepted file.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "host/register/basis_cache_file.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const LoadBasis b = parse_load_basis(bytes, "", 0, "fuzz.bin");
    // accepted: writing it again and reading that back must give the same basis
    const LoadBasis c = parse_load_basis(serialize_load_basis(b, "k"), "k", b.dofs, "fuzz_again.bin");
    if (c.U != b.U || c.G != b.G || c.patch_of_vertex != b.patch_of_vertex || c.mode_kind != b.mode_kind) std::abort();
  } catch (const LoadError&) {
  }
  return 0;
}
