#include "host/mesh/mesh_quality.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
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

std::pair<double, double> dihedral_range(const Eigen::Matrix3Xd& X, const std::array<int, 4>& v) {
  return tet_dihedral_range_deg(X.col(v[0]), X.col(v[1]), X.col(v[2]), X.col(v[3]));
}

using Face = std::array<int, 3>;
using Edge = std::array<int, 2>;
Face face_key(const std::array<int, 4>& t, int skip) {
  Face f{};
  for (int k = 0, m = 0; k < 4; ++k)
    if (k != skip) f[m++] = t[k];
  std::sort(f.begin(), f.end());
  return f;
}
Edge sorted_edge(int a, int b) { return a < b ? Edge{a, b} : Edge{b, a}; }

}  // namespace

int peel_boundary_slivers(TetMesh& mesh, double min_dihedral_deg, double* max_thickness_mm) {
  if (max_thickness_mm) *max_thickness_mm = 0.0;
  if (!(min_dihedral_deg > 0.0)) return 0;
  const Eigen::Matrix3Xd& X = mesh.rest_positions_World_mm;
  std::map<Face, int> face_count;
  for (const auto& t : mesh.tets)
    for (int k = 0; k < 4; ++k) ++face_count[face_key(t, k)];
  std::map<Edge, int> boundary_edge_faces;  // boundary faces on each edge
  auto add_boundary_face = [&](const Face& f, int d) {
    for (int i = 0; i < 3; ++i) boundary_edge_faces[sorted_edge(f[i], f[(i + 1) % 3])] += d;
  };
  for (const auto& [f, c] : face_count)
    if (c == 1) add_boundary_face(f, 1);
  std::vector<char> removed(mesh.tets.size(), 0);
  int total = 0;
  for (bool changed = true; changed;) {
    changed = false;
    for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
      if (removed[t]) continue;
      const auto& v = mesh.tets[t];
      int on_boundary[4], nb = 0;
      for (int k = 0; k < 4; ++k) {
        on_boundary[k] = face_count[face_key(v, k)] == 1;
        nb += on_boundary[k];
      }
      if (nb != 2) continue;
      const auto [lo, hi] = dihedral_range(X, v);
      if (lo >= min_dihedral_deg && hi <= 180.0 - min_dihedral_deg) continue;
      // The boundary faces are opposite two vertices c, d (the "free" edge cd of the new
      // boundary); it must not be a boundary edge already.
      int cd[2], m = 0;
      for (int k = 0; k < 4; ++k)
        if (on_boundary[k]) cd[m++] = v[k];
      const auto it = boundary_edge_faces.find(sorted_edge(cd[0], cd[1]));
      if (it != boundary_edge_faces.end() && it->second > 0) continue;
      removed[t] = 1;
      ++total;
      changed = true;
      double max_twice_area = 0.0;
      const double six_v = std::abs((X.col(v[1]) - X.col(v[0])).dot((X.col(v[2]) - X.col(v[0])).cross(X.col(v[3]) - X.col(v[0]))));
      for (int k = 0; k < 4; ++k) {
        const Face f = face_key(v, k);
        const double twice_area = (X.col(f[1]) - X.col(f[0])).cross(X.col(f[2]) - X.col(f[0])).norm();
        max_twice_area = std::max(max_twice_area, twice_area);
        int& c = face_count[f];
        if (c == 1) add_boundary_face(f, -1);  // was boundary: gone with the tet
        --c;
        if (c == 1) add_boundary_face(f, 1);   // was interior: now boundary
      }
      // Thickness: the height over the largest face.
      if (max_thickness_mm && max_twice_area > 0) *max_thickness_mm = std::max(*max_thickness_mm, six_v / max_twice_area);
    }
  }
  if (total == 0) return 0;
  std::vector<std::array<int, 4>> tets;
  std::vector<int> region;
  for (std::size_t t = 0; t < mesh.tets.size(); ++t)
    if (!removed[t]) {
      tets.push_back(mesh.tets[t]);
      if (t < mesh.tet_region.size()) region.push_back(mesh.tet_region[t]);
    }
  mesh.tets = std::move(tets);
  if (!mesh.tet_region.empty()) mesh.tet_region = std::move(region);
  return total;
}

std::pair<double, double> tet_dihedral_range_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                                                 const Eigen::Vector3d& d) {
  const Eigen::Vector3d p[4] = {a, b, c, d};
  // Outward normal of the face opposite vertex k; the dihedral angle at the edge shared by
  // the faces opposite k and l is pi minus the angle between their normals.
  Eigen::Vector3d n[4];
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d& p0 = p[(k + 1) % 4];
    Eigen::Vector3d nk = (p[(k + 2) % 4] - p0).cross(p[(k + 3) % 4] - p0);
    if (nk.dot(p[k] - p0) > 0) nk = -nk;
    const double len = nk.norm();
    if (!(len > 0.0)) return {0.0, 180.0};
    n[k] = nk / len;
  }
  double lo = 180.0, hi = 0.0;
  for (int k = 0; k < 4; ++k)
    for (int l = k + 1; l < 4; ++l) {
      const double deg = std::acos(std::clamp(-n[k].dot(n[l]), -1.0, 1.0)) * 180.0 / kPi;
      lo = std::min(lo, deg);
      hi = std::max(hi, deg);
    }
  return {lo, hi};
}

TetMeshQuality tet_mesh_quality(const TetMesh& mesh) {
  TetMeshQuality q;
  if (mesh.tets.empty()) return q;
  const Eigen::Matrix3Xd& X = mesh.rest_positions_World_mm;
  std::vector<double> per_tet_min(mesh.tets.size());
  q.min_dihedral_deg = 180.0;
  q.min_volume_mm3 = std::numeric_limits<double>::infinity();
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const auto& v = mesh.tets[t];
    Eigen::Vector3d p[4];
    for (int k = 0; k < 4; ++k) p[k] = X.col(v[k]);
    const auto [lo, hi] = tet_dihedral_range_deg(p[0], p[1], p[2], p[3]);
    double shortest = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 4; ++k)
      for (int l = k + 1; l < 4; ++l) shortest = std::min(shortest, (p[k] - p[l]).norm());
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
