#pragma once
// Volume and surface meshes of a scene, in the scene frame World. Units: mm.
// Shared by scene loading (host/scene) and the tissue models (host/sim).
#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cstdint>
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

// Topology of one tet (its vertices 0..3, positively oriented). Face f lies opposite vertex
// 3 - f; its vertices in this order turn about the outward normal (right-hand rule).
inline constexpr int kTetFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
inline constexpr int kTetEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

// A 64-bit key of the ordered vertex pair (a, b) (a directed edge; ids >= 0).
inline std::uint64_t directed_edge_key(int a, int b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) | static_cast<std::uint32_t>(b);
}
// The same key for both orders (an edge).
inline std::uint64_t edge_key(int a, int b) { return directed_edge_key(std::min(a, b), std::max(a, b)); }

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
