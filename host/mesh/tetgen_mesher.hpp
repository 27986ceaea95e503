#pragma once
// Volume meshing of a closed surface with TetGen (libtet). The surface is kept as given
// (no Steiner points on it, TetGen -Y) so surface embeddings stay exact; the interior is
// refined to the quality and size bounds. Units: mm, mm^3.
#include <string>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

struct TetGenSettings {
  double max_radius_edge_ratio = 2.0;  // TetGen -q: quality bound (>= 1.1; smaller = better shaped tets)
  double min_dihedral_deg = 0.0;       // TetGen -q/<deg> (0: TetGen's default)
  double max_volume_mm3 = 0.0;         // TetGen -a: size bound (0: no bound)
  bool keep_surface = true;            // TetGen -Y: no Steiner points on the boundary
  int optimisation_level = -1;         // TetGen -O<level>/7 (flips, smoothing, vertex insertion
                                       // and deletion): 0..10, -1: TetGen's default (2)
};

struct TetGenReport {
  std::string switches;
  int input_vertices = 0;
  int input_triangles = 0;
  double wall_time_ms = 0.0;
};

// Throws LoadError naming `source` with TetGen's diagnosis (self-intersection, tiny
// features, bad input) and the fix. The result is validated (positive tets, surface).
TetMesh tetrahedralize_surface(const TriMesh& surface, const TetGenSettings& settings, const std::string& source,
                               TetGenReport* report = nullptr);

}  // namespace arnav::host
