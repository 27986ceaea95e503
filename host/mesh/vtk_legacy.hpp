#pragma once
// Legacy VTK reader (".vtk", versions up to 4.2), ASCII and BINARY (big-endian), datasets
// POLYDATA (POLYGONS; triangles are kept, polygons fanned) and UNSTRUCTURED_GRID (CELLS +
// CELL_TYPES; linear tetrahedra, type 10). Point/cell attributes after the geometry are
// ignored. Coordinates are taken as mm.
#include <string>
#include <string_view>
#include <vector>

#include "host/mesh/mesh_validation.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

struct VtkLegacyData {
  bool unstructured = false;          // UNSTRUCTURED_GRID (else POLYDATA)
  Eigen::Matrix3Xd points;
  std::vector<std::vector<int>> polygons;   // POLYDATA polygons
  std::vector<std::vector<int>> cells;      // UNSTRUCTURED_GRID cells
  std::vector<int> cell_types;
  std::vector<int> element_lines;           // ASCII line of each polygon/cell (0 for binary)
};

// Parses the file content; throws LoadError naming `source`, the line or byte offset.
VtkLegacyData parse_vtk_legacy(std::string_view content, const std::string& source);

// Triangle surface from a POLYDATA file (polygons with more than 3 vertices are fanned).
TriMesh vtk_surface(const VtkLegacyData& data, const std::string& source, ElementLines* lines = nullptr);
// Tetrahedra from an UNSTRUCTURED_GRID file; other cell types are errors unless they are
// lower-dimensional (vertex, line, triangle: skipped, e.g. boundary faces exported with it).
TetMesh vtk_volume(const VtkLegacyData& data, const std::string& source, ElementLines* lines = nullptr);

}  // namespace arnav::host
