#pragma once
// Invariants a cut must keep, checked by the tests, the fuzz run and the cut benchmark:
// positive tets, the pieces (face-connected components), a closed, 2-manifold, consistently
// oriented boundary surface, element quality. Frame World, units mm, mm^3, degrees.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

struct CutMeshCheck {
  double total_volume_mm3 = 0.0;
  double min_tet_volume_mm3 = 0.0;
  int nonpositive_tets = 0;
  double min_dihedral_deg = 180.0;
  std::vector<int> piece_of_tet;          // face-connected component of each tet
  std::vector<double> piece_volume_mm3;   // per piece
  int boundary_faces = 0;
  int open_edges = 0;          // boundary edges without a matching opposite edge (holes)
  int nonmanifold_edges = 0;   // boundary edges used by more than two boundary faces
  int misoriented_edges = 0;   // boundary edges used twice in the same direction
  int overshared_faces = 0;    // faces used by more than two tets
  bool valid() const {
    return nonpositive_tets == 0 && open_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0 && overshared_faces == 0;
  }
  std::string summary() const;
};

// Checks the mesh at the given vertex positions (rest positions when x is empty).
CutMeshCheck check_cut_mesh(const TetMesh& mesh, const Eigen::Matrix3Xd& x_World_mm = Eigen::Matrix3Xd());

// Smallest dihedral angle (degrees) of one tet.
double min_dihedral_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d);

}  // namespace arnav::host::cut
