#include "host/app/cut_trace.hpp"

#include <Eigen/Dense>

namespace arnav::host {

int locate_in_volume(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& p, Eigen::Vector4d& weights) {
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    const Eigen::Vector3d a = x.col(tet[0]), b = x.col(tet[1]), c = x.col(tet[2]), d = x.col(tet[3]);
    // Bounding-box rejection first: most tets are far from p.
    const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c).cwiseMin(d), hi = a.cwiseMax(b).cwiseMax(c).cwiseMax(d);
    if ((p.array() < lo.array()).any() || (p.array() > hi.array()).any()) continue;
    Eigen::Matrix3d E;
    E << b - a, c - a, d - a;
    const Eigen::Vector3d l = E.partialPivLu().solve(p - a);
    const Eigen::Vector4d w(1.0 - l.sum(), l.x(), l.y(), l.z());
    if (w.minCoeff() >= -1e-9) {
      weights = w;
      return t;
    }
  }
  return -1;
}

bool CutTrace::add(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const Eigen::Vector3d& tip) {
  Eigen::Vector4d w;
  const int t = locate_in_volume(mesh, x, tip, w);
  if (t < 0) {
    in_stroke_ = false;
    return false;
  }
  if (in_stroke_ && !points_.empty()) {
    const Point& last = points_.back();
    const auto& lt = mesh.tets[static_cast<std::size_t>(last.tet)];
    Eigen::Vector3d q = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) q += last.w[k] * x.col(lt[static_cast<std::size_t>(k)]);
    if ((q - tip).norm() < spacing_mm_) return false;
  }
  points_.push_back({t, w, !in_stroke_});
  in_stroke_ = true;
  return true;
}

std::vector<std::vector<Eigen::Vector3d>> CutTrace::strokes(const Eigen::Matrix3Xd& x, const TetMesh& mesh) const {
  std::vector<std::vector<Eigen::Vector3d>> out;
  for (const auto& p : points_) {
    if (p.starts_stroke || out.empty()) out.emplace_back();
    const auto& tet = mesh.tets[static_cast<std::size_t>(p.tet)];
    Eigen::Vector3d q = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) q += p.w[k] * x.col(tet[static_cast<std::size_t>(k)]);
    out.back().push_back(q);
  }
  return out;
}

}  // namespace arnav::host
