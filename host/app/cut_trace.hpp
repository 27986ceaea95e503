#pragma once
// The path the scalpel's blade tip has taken through the tissue, carried by the volume:
// each point is stored as a tet and barycentric weights at the moment it was cut, so the
// trace moves with the deforming organ. It is what the overlay's "cut" layer shows until
// the cutting stage (host/cut) supplies the cut surface itself. Frame Model, mm.
#include <Eigen/Core>

#include <cstddef>
#include <vector>

#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

class CutTrace {
 public:
  explicit CutTrace(double spacing_mm = 1.0) : spacing_mm_(spacing_mm) {}

  // Adds the tip when it lies inside the volume (vertex positions x of mesh) and at least
  // spacing_mm from the last point; a tip outside ends the current stroke. Returns whether
  // a point was added.
  bool add(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& tip_Model_mm);
  // Strokes (polylines) at the current vertex positions.
  std::vector<std::vector<Eigen::Vector3d>> strokes(const Eigen::Matrix3Xd& x, const TetMesh& mesh) const;
  std::size_t size() const { return points_.size(); }

 private:
  struct Point {
    int tet = -1;
    Eigen::Vector4d w = Eigen::Vector4d::Zero();
    bool starts_stroke = false;
  };
  double spacing_mm_;
  std::vector<Point> points_;
  bool in_stroke_ = false;
};

// The tet of mesh (at positions x) containing p and p's barycentric weights; -1 when none.
int locate_in_volume(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& p, Eigen::Vector4d& weights);

}  // namespace arnav::host
