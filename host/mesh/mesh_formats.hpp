#pragma once
// Text mesh formats (parsers only; validation is separate, see mesh_validation.hpp):
//   surfaces: Wavefront OBJ (v / f, polygons fanned, negative indices), OFF, PLY (ASCII,
//             binary little/big-endian; ply_format.cpp);
//   volumes:  TetGen .node/.ele, Gmsh .msh version 1 ($NOD/$ELM) and version 2 ASCII.
// Coordinates are taken as mm. Each parser throws LoadError naming source and line.
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "host/mesh/mesh_validation.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

TriMesh parse_obj(std::string_view content, const std::string& source, ElementLines* lines = nullptr);
TriMesh parse_off(std::string_view content, const std::string& source, ElementLines* lines = nullptr);
// Stanford PLY: vertex x/y/z and face vertex_indices (polygons fanned); other elements and
// properties are skipped by type. Errors name the header line, body line (ASCII) or byte
// offset (binary).
TriMesh parse_ply(std::string_view content, const std::string& source, ElementLines* lines = nullptr);

// The same reader for point clouds (depth cameras, Open3D): vertices with optional normals
// (nx, ny, nz: all three or none), faces optional unless `faces_required`.
struct PlyPoints {
  TriMesh mesh;                    // positions (mm) and the faces, if any
  Eigen::Matrix3Xd normals;        // per vertex, or 0 columns when the file has none
  std::vector<int> vertex_lines;   // body line of each vertex (ASCII), 0 for binary files
};
PlyPoints parse_ply_points(std::string_view content, const std::string& source, bool faces_required,
                           ElementLines* face_lines = nullptr);

// TetGen: the node and element files are separate. Indices may start at 0 or 1 (the first
// node's number decides, as in TetGen). A region attribute per element (tetgen -A) becomes
// tet_region, named "region_<attribute>".
TetMesh parse_tetgen(std::string_view node_content, const std::string& node_source, std::string_view ele_content,
                     const std::string& ele_source, ElementLines* lines = nullptr);

// Gmsh ASCII versions 1 and 2. Linear tetrahedra (type 4) are kept; points, lines and
// triangles are skipped; other volume elements are errors. Distinct physical tags become
// regions (names from $PhysicalNames when present).
TetMesh parse_gmsh(std::string_view content, const std::string& source, ElementLines* lines = nullptr);

}  // namespace arnav::host
