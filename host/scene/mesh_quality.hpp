#pragma once
// Shape quality of a rest tetrahedral mesh: what decides whether a tissue model can
// deform it without elements going flat. A sliver (four nearly coplanar vertices with
// edges of normal length) has a dihedral angle near 0 or 180 degrees and a tiny volume;
// under load it inverts first. Reported in the scene notes and by arnav-sim; a scene can
// require a minimum (volume.min_dihedral_required_deg, docs/scene.md). Units: mm, degrees.
#include <string>

#include "host/scene/tet_mesh.hpp"

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

// "min dihedral 7.1 deg (1 %: 14.2), max 161.3 deg, radius-edge <= 2.00, min volume 0.52 mm^3, slivers 0".
std::string describe(const TetMeshQuality& q);

}  // namespace arnav::host
