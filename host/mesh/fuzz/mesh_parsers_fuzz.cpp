// libFuzzer target: every mesh parser and the validators on arbitrary bytes. The first
// byte picks the format; parse errors must surface as LoadError, never as a crash.
#include <cstddef>
#include <cstdint>
#include <string>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_formats.hpp"
#include "host/mesh/mesh_validation.hpp"
#include "host/mesh/vtk_legacy.hpp"

using namespace arnav::host;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::string_view text(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    switch (data[0] % 6) {
      case 0: {
        TriMesh s = parse_obj(text, "fuzz.obj");
        validate_closed_surface(s, "fuzz.obj");
        break;
      }
      case 1: {
        TriMesh s = parse_off(text, "fuzz.off");
        validate_closed_surface(s, "fuzz.off");
        break;
      }
      case 2: {
        const VtkLegacyData d = parse_vtk_legacy(text, "fuzz.vtk");
        if (d.unstructured) {
          TetMesh m = vtk_volume(d, "fuzz.vtk");
          validate_tet_mesh(m, "fuzz.vtk");
        } else {
          TriMesh s = vtk_surface(d, "fuzz.vtk");
          validate_closed_surface(s, "fuzz.vtk");
        }
        break;
      }
      case 3: {
        TetMesh m = parse_gmsh(text, "fuzz.msh");
        validate_tet_mesh(m, "fuzz.msh");
        break;
      }
      case 5: {
        TriMesh s = parse_ply(text, "fuzz.ply");
        validate_closed_surface(s, "fuzz.ply");
        break;
      }
      default: {
        // Node and element files split at the first NUL byte (or half way).
        std::size_t cut = text.find('\0');
        if (cut == std::string_view::npos) cut = text.size() / 2;
        TetMesh m = parse_tetgen(text.substr(0, cut), "fuzz.node", text.substr(std::min(cut + 1, text.size())), "fuzz.ele");
        validate_tet_mesh(m, "fuzz.ele");
        break;
      }
    }
  } catch (const LoadError&) {
  }
  return 0;
}
