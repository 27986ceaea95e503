#pragma once
// Surface simplification by edge collapse with quadric error metrics (Garland and
// Heckbert 1997), keeping a closed surface closed and manifold: a collapse is refused when
// it would break the link condition, flip or squash a triangle. Used to make coarse
// volume meshes of the same organ (TetGen keeps every surface vertex). Units: mm.
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

struct DecimationReport {
  int input_vertices = 0;
  int output_vertices = 0;
  double max_error_mm2 = 0.0;  // largest quadric error of an accepted collapse (squared distance)
};

// Simplifies `surface` in place to about target_vertices (stops earlier when no valid
// collapse is left). Throws std::invalid_argument for target_vertices < 8.
DecimationReport decimate_surface(TriMesh& surface, int target_vertices);

}  // namespace arnav::host
