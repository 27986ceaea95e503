#pragma once
// Barycentric embedding of points (tumour surfaces, vessel centerlines, the display
// surface) in a tetrahedral mesh: each point is a fixed affine combination of the four
// vertices of one tet, so it follows the volume exactly for any affine motion of that tet
// and continuously otherwise. Frame World, units mm.
#include <Eigen/Core>

#include <vector>

#include "host/mesh/tet_mesh.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

struct Embedding {
  std::vector<int> tet;            // containing (or nearest) tet per point
  Eigen::Matrix4Xd weights;        // barycentric weights per point (sum to 1)
  double max_outside_mm = 0.0;     // largest distance of a point outside the mesh (0: all inside)

  int size() const { return static_cast<int>(tet.size()); }
  // Positions of the embedded points for mesh vertex positions x.
  Eigen::Matrix3Xd apply(const TetMesh& mesh, const Eigen::Matrix3Xd& x_World_mm) const;
  // The point as a material point, e.g. for an attachment (a grasp on the tumour).
  MaterialPoint material_point(const TetMesh& mesh, int i) const;
};

// Embeds points given in the rest configuration. Points outside the mesh by at most
// tolerance_mm use the nearest tet (weights extrapolate, still exact for affine motion);
// a point further out throws LoadError naming `what` (e.g. the tumour surface) and the point.
Embedding embed_points(const TetMesh& mesh, const Eigen::Matrix3Xd& points_World_mm, double tolerance_mm,
                       const std::string& what);

}  // namespace arnav::host
