#pragma once
// Shape quality of a rest tetrahedral mesh: what decides whether a tissue model can
// deform it without elements going flat. A sliver (four nearly coplanar vertices with
// edges of normal length) has a dihedral angle near 0 or 180 degrees and a tiny volume;
// under load it inverts first. Reported in the scene notes and by arnav-sim; a scene can
// require a minimum (volume.min_dihedral_required_deg, docs/scene.md). Units: mm, degrees.
#include <Eigen/Core>

#include <string>
#include <utility>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

struct TetMeshQuality {
  double min_dihedral_deg = 0.0;      // smallest dihedral angle of any tet
  double p01_dihedral_deg = 0.0;      // 1st percentile of the per-tet smallest dihedral angle
  double max_dihedral_deg = 0.0;      // largest dihedral angle of any tet
  double max_radius_edge_ratio = 0.0; // circumradius / shortest edge (TetGen -q bound; regular tet 0.61)
  double min_volume_mm3 = 0.0;
  int slivers = 0;                    // tets with a dihedral angle below 5 or above 175 degrees
  int worst_tet = -1;                 // tet with the smallest dihedral angle
};

TetMeshQuality tet_mesh_quality(const TetMesh& mesh);

// Smallest and largest dihedral angle (degrees) of the tet (a, b, c, d): goes to 0 or 180 for
// every flat shape (sliver, wedge, cap) and is scale-free; {0, 180} for a degenerate tet (a
// face without area). The one quality measure of the scene, the cutter's checks and the
// models' quality bound.
std::pair<double, double> tet_dihedral_range_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                                 const Eigen::Vector3d& d);

// Removes boundary slivers: tets with exactly two faces on the boundary (a flat tet lying
// on the surface, made of four surface vertices; TetGen keeps them when the surface is
// kept, -Y) whose smallest dihedral angle is below min_dihedral_deg or largest above
// 180 - min_dihedral_deg. The boundary then runs over the sliver's two other faces: it
// moves by at most the sliver's thickness (reported in *max_thickness_mm). A sliver is
// kept when removing it would make the boundary non-manifold (its free edge already on
// the boundary). Repeats until none is left. Returns how many were removed; tet_region
// follows; surface_tris must be recomputed by the caller (validate_tet_mesh).
int peel_boundary_slivers(TetMesh& mesh, double min_dihedral_deg, double* max_thickness_mm = nullptr);

// "min dihedral 7.1 deg (1 %: 14.2), max 161.3 deg, radius-edge <= 2.00, min volume 0.52 mm^3, slivers 0".
std::string describe(const TetMeshQuality& q);

}  // namespace arnav::host
