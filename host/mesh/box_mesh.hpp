#pragma once
// Structured tetrahedral meshes of a box, for verification (cantilever, patch test,
// uniaxial traction) and stress cases. Frame World, units mm.
#include <Eigen/Core>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

// Box [0,size.x] x [0,size.y] x [0,size.z] with nodes (nx+1)(ny+1)(nz+1); each hex cell is
// split into 6 positively oriented tets along its main diagonal (Kuhn split: conforming).
// Surface triangles are filled (outward normals). Vertex index: i + (nx+1)*(j + (ny+1)*k).
TetMesh make_box_tet_mesh(int nx, int ny, int nz, const Eigen::Vector3d& size_mm);

// Index of grid vertex (i, j, k) in a mesh made by make_box_tet_mesh(nx, ny, nz, ...).
inline int box_vertex_index(int nx, int ny, int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); }

// Boundary faces of a tet mesh (faces used by one tet), oriented outward.
std::vector<std::array<int, 3>> boundary_faces(const TetMesh& mesh);

}  // namespace arnav::host
