#pragma once
// Closed analytic surfaces for synthetic internal structures (a tumour placed in the
// bundled liver) and point-in-surface tests. Units: mm.
#include <Eigen/Core>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

// Ellipsoid as a subdivided icosahedron (20 * 4^subdivisions triangles), outward normals.
TriMesh make_ellipsoid_surface(const Eigen::Vector3d& center_mm, const Eigen::Vector3d& radii_mm, int subdivisions);

// Generalised winding number of a closed, outward-oriented surface at p: ~1 inside, ~0
// outside (robust near small defects).
double winding_number(const TriMesh& surface, const Eigen::Vector3d& p_mm);

// Volume centroid of a closed triangle surface over positions p (divergence theorem), in
// the frame of p; the mean of the positions when the enclosed volume is 0.
Eigen::Vector3d closed_surface_centroid(const Eigen::Matrix3Xd& p_mm, const std::vector<std::array<int, 3>>& tris);

}  // namespace arnav::host
