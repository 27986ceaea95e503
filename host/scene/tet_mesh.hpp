#pragma once
// Volume and surface meshes of a scene, in the scene frame World. Units: mm.
// Shared by scene loading (host/scene) and the tissue models (host/sim).
#include <Eigen/Core>

#include <array>
#include <string>
#include <vector>

namespace arnav::host {

// Linear (P1) tetrahedral mesh. Vertex i is column i of rest_positions_World_mm.
// Tetrahedra are positively oriented: det([x1-x0, x2-x0, x3-x0]) > 0.
struct TetMesh {
  Eigen::Matrix3Xd rest_positions_World_mm;
  std::vector<std::array<int, 4>> tets;
  std::vector<int> tet_region;                     // region index per tet (0 = default)
  std::vector<std::string> region_names;           // region index -> name
  std::vector<std::array<int, 3>> surface_tris;    // boundary faces, outward normals

  int num_vertices() const { return static_cast<int>(rest_positions_World_mm.cols()); }
  int num_tets() const { return static_cast<int>(tets.size()); }
};

// Closed triangle surface (organ boundary, tumour, ...). Units: mm.
struct TriMesh {
  Eigen::Matrix3Xd positions_World_mm;
  std::vector<std::array<int, 3>> tris;
};

// Vessel tree as a graph of centerline nodes with radii. Units: mm.
struct VesselTree {
  Eigen::Matrix3Xd nodes_World_mm;
  std::vector<double> radius_mm;                   // per node
  std::vector<std::array<int, 2>> segments;        // node index pairs
};

}  // namespace arnav::host
