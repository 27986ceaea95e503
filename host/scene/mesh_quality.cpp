#include "host/scene/mesh_quality.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

namespace arnav::host {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Circumradius of the tet (a, b, c, d); infinite for a flat one.
double circumradius(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  Eigen::Matrix3d A;
  A.row(0) = (b - a).transpose();
  A.row(1) = (c - a).transpose();
  A.row(2) = (d - a).transpose();
  const Eigen::Vector3d rhs(0.5 * (b - a).squaredNorm(), 0.5 * (c - a).squaredNorm(), 0.5 * (d - a).squaredNorm());
  const double det = A.determinant();
  if (!(std::abs(det) > 0.0)) return std::numeric_limits<double>::infinity();
  return A.partialPivLu().solve(rhs).norm();
}

}  // namespace

TetMeshQuality tet_mesh_quality(const TetMesh& mesh) {
  TetMeshQuality q;
  if (mesh.tets.empty()) return q;
  const Eigen::Matrix3Xd& X = mesh.rest_positions_World_mm;
  std::vector<double> per_tet_min(mesh.tets.size());
  q.min_dihedral_deg = 180.0;
  q.min_volume_mm3 = std::numeric_limits<double>::infinity();
  // The six edges (i, j) and the two faces opposite to them meet at the edge with the
  // dihedral angle pi - angle between the outward face normals.
  static constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const auto& v = mesh.tets[t];
    Eigen::Vector3d p[4];
    for (int k = 0; k < 4; ++k) p[k] = X.col(v[k]);
    // Area vectors of the faces opposite each vertex, pointing outward.
    Eigen::Vector3d n[4];
    for (int k = 0; k < 4; ++k) {
      const Eigen::Vector3d& a = p[(k + 1) % 4];
      const Eigen::Vector3d& b = p[(k + 2) % 4];
      const Eigen::Vector3d& c = p[(k + 3) % 4];
      n[k] = (b - a).cross(c - a);
      if (n[k].dot(p[k] - a) > 0) n[k] = -n[k];
    }
    double lo = 180.0, hi = 0.0, shortest = std::numeric_limits<double>::infinity();
    for (const auto& e : kEdge) {
      // The faces containing edge (i, j) are those opposite the two other vertices.
      int others[2], m = 0;
      for (int k = 0; k < 4; ++k)
        if (k != e[0] && k != e[1]) others[m++] = k;
      const double cosang = -n[others[0]].normalized().dot(n[others[1]].normalized());
      const double deg = std::acos(std::clamp(cosang, -1.0, 1.0)) * 180.0 / kPi;
      lo = std::min(lo, deg);
      hi = std::max(hi, deg);
      shortest = std::min(shortest, (p[e[0]] - p[e[1]]).norm());
    }
    if (!std::isfinite(lo)) lo = 0.0;
    per_tet_min[t] = lo;
    if (lo < q.min_dihedral_deg) {
      q.min_dihedral_deg = lo;
      q.worst_tet = static_cast<int>(t);
    }
    q.max_dihedral_deg = std::max(q.max_dihedral_deg, hi);
    if (lo < 5.0 || hi > 175.0) ++q.slivers;
    const double volume = std::abs((p[1] - p[0]).dot((p[2] - p[0]).cross(p[3] - p[0]))) / 6.0;
    q.min_volume_mm3 = std::min(q.min_volume_mm3, volume);
    q.max_radius_edge_ratio = std::max(q.max_radius_edge_ratio, circumradius(p[0], p[1], p[2], p[3]) / shortest);
  }
  const std::size_t k = per_tet_min.size() / 100;
  std::nth_element(per_tet_min.begin(), per_tet_min.begin() + static_cast<std::ptrdiff_t>(k), per_tet_min.end());
  q.p01_dihedral_deg = per_tet_min[k];
  return q;
}

std::string describe(const TetMeshQuality& q) {
  char buf[256];
  std::snprintf(buf, sizeof buf,
                "min dihedral %.1f deg (1st percentile %.1f), max dihedral %.1f deg, radius-edge ratio <= %.2f, "
                "min volume %.3g mm^3, slivers (<5 or >175 deg) %d",
                q.min_dihedral_deg, q.p01_dihedral_deg, q.max_dihedral_deg, q.max_radius_edge_ratio, q.min_volume_mm3, q.slivers);
  return buf;
}

}  // namespace arnav::host
