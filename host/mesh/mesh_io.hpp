#pragma once
// Mesh files in and out, chosen by extension, validated on the way in.
//   surfaces: .obj, .off, .ply (ASCII or binary), .vtk (POLYDATA)
//   volumes:  .ele/.node (TetGen; either name, the other is found beside it),
//             .msh (Gmsh v1/v2 ASCII), .vtk (UNSTRUCTURED_GRID)
// Units: coordinates are mm (a scene may scale them, see scene.hpp).
#include <string>
#include <vector>

#include "host/mesh/mesh_validation.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

std::string read_text_file(const std::string& path);  // throws LoadError naming the path

// Parses without validating (exposed for the fuzzers and tests). `format` is the file
// extension without dot: obj, off, ply, vtk.
TriMesh parse_surface(std::string_view content, const std::string& source, const std::string& format, ElementLines* lines);

// Reads, parses and validates a closed organ or tumour surface.
TriMesh load_surface(const std::string& path, SurfaceCheck* check = nullptr);
// Reads, parses and validates a tetrahedral volume mesh.
TetMesh load_volume(const std::string& path, TetMeshCheck* check = nullptr);

// Writers for results (frame sequences) and generated meshes.
void write_vtk_volume(const std::string& path, const TetMesh& mesh, const Eigen::Matrix3Xd& positions_World_mm,
                      const std::vector<double>& cell_scalar = {}, const std::string& scalar_name = "");
void write_vtk_surface(const std::string& path, const Eigen::Matrix3Xd& positions_World_mm,
                       const std::vector<std::array<int, 3>>& tris);
void write_obj(const std::string& path, const Eigen::Matrix3Xd& positions_World_mm, const std::vector<std::array<int, 3>>& tris);
void write_vtk_lines(const std::string& path, const Eigen::Matrix3Xd& positions_World_mm,
                     const std::vector<std::array<int, 2>>& segments, const std::vector<double>& radius_mm);

}  // namespace arnav::host
