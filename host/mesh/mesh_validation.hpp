#pragma once
// Checks meshes read from files before anything is built on them. Each failure throws a
// LoadError naming the file, the line (when the element came from a text line) or the
// element index, and the fix. Units: mm.
#include <string>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

// Where each element of a parsed mesh came from, for messages (0 = unknown line).
using ElementLines = std::vector<int>;

struct SurfaceCheck {
  int removed_unused_vertices = 0;  // vertices no triangle uses (dropped, indices compacted)
  bool flipped = false;             // the surface was consistently oriented inward; flipped
  double volume_mm3 = 0.0;          // enclosed volume after orientation
  int components = 1;               // connected components (each closed)
};

// A closed 2-manifold: finite coordinates, indices in range, no degenerate (zero-area) or
// repeated triangles, every edge used by exactly two triangles in opposite directions.
// Unused vertices are removed; an inward-oriented surface is flipped to outward.
SurfaceCheck validate_closed_surface(TriMesh& surface, const std::string& source, const ElementLines& tri_lines = {});

// Connected component (over shared vertices) of each triangle, numbered from 0 in order of
// decreasing size; returns the number of components.
int surface_components(const TriMesh& surface, std::vector<int>& component_of_triangle);

// Keeps only the largest connected component (e.g. drops segmentation bubbles inside an
// organ) and compacts vertices. Returns the number of vertices removed.
int keep_largest_component(TriMesh& surface);

struct TetMeshCheck {
  int removed_unused_vertices = 0;
  double volume_mm3 = 0.0;
  double min_quality = 0.0;  // min over tets of 6*sqrt(2)*V / l_rms^3 (1 = regular tet)
};

// Finite coordinates, indices in range, distinct vertices per tet, positively oriented and
// non-degenerate tets, every face shared by at most two tets. Unused vertices are removed.
// Fills surface_tris (outward) and, when empty, tet_region (all 0, "default").
TetMeshCheck validate_tet_mesh(TetMesh& mesh, const std::string& source, const ElementLines& tet_lines = {});

}  // namespace arnav::host
