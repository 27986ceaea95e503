#include "host/overlay/overlay_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include <Eigen/Geometry>

#include "host/mesh/surface_shapes.hpp"

namespace arnav::host::overlay {

Eigen::Matrix3Xd vertex_normals(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris) {
  Eigen::Matrix3Xd n = Eigen::Matrix3Xd::Zero(3, positions.cols());
  for (const auto& t : tris) {
    const Eigen::Vector3d a = positions.col(t[0]), b = positions.col(t[1]), c = positions.col(t[2]);
    const Eigen::Vector3d fn = (b - a).cross(c - a);  // length = 2 x area: area weighting
    for (int k = 0; k < 3; ++k) n.col(t[k]) += fn;
  }
  for (Eigen::Index i = 0; i < n.cols(); ++i) {
    const double len = n.col(i).norm();
    if (len > 0) n.col(i) /= len;
  }
  return n;
}

TriMesh offset_surface(const TriMesh& surface, double margin_mm) {
  TriMesh out = surface;
  out.positions_World_mm += margin_mm * vertex_normals(surface.positions_World_mm, surface.tris);
  return out;
}

TriMesh tubes(const Eigen::Matrix3Xd& nodes, const std::vector<double>& radius_mm, const std::vector<std::array<int, 2>>& segments,
              int sides) {
  TriMesh out;
  std::vector<Eigen::Vector3d> verts;
  for (const auto& s : segments) {
    const Eigen::Vector3d a = nodes.col(s[0]), b = nodes.col(s[1]);
    const Eigen::Vector3d axis = b - a;
    if (axis.norm() < 1e-9) continue;
    const Eigen::Vector3d d = axis.normalized();
    const Eigen::Vector3d helper = std::abs(d.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    const Eigen::Vector3d e1 = d.cross(helper).normalized(), e2 = d.cross(e1);
    const double ra = radius_mm[static_cast<std::size_t>(s[0])], rb = radius_mm[static_cast<std::size_t>(s[1])];
    const int base = static_cast<int>(verts.size());
    for (int k = 0; k < sides; ++k) {
      const double phi = 2.0 * std::numbers::pi * k / sides;
      const Eigen::Vector3d dir = std::cos(phi) * e1 + std::sin(phi) * e2;
      verts.push_back(a + ra * dir);
      verts.push_back(b + rb * dir);
    }
    verts.push_back(a);
    verts.push_back(b);
    const int ca = base + 2 * sides, cb = ca + 1;
    for (int k = 0; k < sides; ++k) {
      const int k1 = (k + 1) % sides;
      const int a0 = base + 2 * k, b0 = a0 + 1, a1 = base + 2 * k1, b1 = a1 + 1;
      // Outward normals: (e1 x e2) = d, so counter-clockwise seen from outside.
      out.tris.push_back({a0, a1, b1});
      out.tris.push_back({a0, b1, b0});
      out.tris.push_back({ca, a1, a0});
      out.tris.push_back({cb, b0, b1});
    }
  }
  out.positions_World_mm.resize(3, static_cast<Eigen::Index>(verts.size()));
  for (std::size_t i = 0; i < verts.size(); ++i) out.positions_World_mm.col(static_cast<Eigen::Index>(i)) = verts[i];
  return out;
}

std::vector<EdgeFaces> edge_faces(const std::vector<std::array<int, 3>>& tris) {
  std::map<std::pair<int, int>, std::size_t> index;
  std::vector<EdgeFaces> out;
  for (std::size_t f = 0; f < tris.size(); ++f) {
    for (std::size_t k = 0; k < 3; ++k) {
      const int i = tris[f][k], j = tris[f][(k + 1) % 3];
      const auto [it, inserted] = index.try_emplace({std::min(i, j), std::max(i, j)}, out.size());
      if (inserted)
        out.push_back({std::min(i, j), std::max(i, j), static_cast<int>(f), -1});
      else
        out[it->second].face2 = static_cast<int>(f);
    }
  }
  return out;
}

std::vector<std::array<int, 2>> silhouette_edges(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris,
                                                 const std::vector<EdgeFaces>& edges, const Eigen::Vector3d& eye_position) {
  std::vector<char> front(tris.size());
  for (std::size_t f = 0; f < tris.size(); ++f) {
    const auto& t = tris[f];
    const Eigen::Vector3d a = positions.col(t[0]);
    const Eigen::Vector3d fn = (positions.col(t[1]) - a).cross(positions.col(t[2]) - a);
    front[f] = fn.dot(eye_position - a) > 0 ? 1 : 0;
  }
  // An open boundary edge (one face) counts when its face is turned to the eye.
  std::vector<std::array<int, 2>> out;
  for (const auto& e : edges) {
    const bool f1 = front[static_cast<std::size_t>(e.face1)];
    if (e.face2 < 0 ? f1 : f1 != static_cast<bool>(front[static_cast<std::size_t>(e.face2)])) out.push_back({e.v0, e.v1});
  }
  return out;
}

std::vector<std::array<int, 2>> silhouette_edges(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris,
                                                 const Eigen::Vector3d& eye_position) {
  return silhouette_edges(positions, tris, edge_faces(tris), eye_position);
}

namespace {

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5).
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace

double point_mesh_distance(const Eigen::Vector3d& p, const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris) {
  double best = std::numeric_limits<double>::infinity();
  for (const auto& t : tris) {
    const Eigen::Vector3d q = closest_on_triangle(p, positions.col(t[0]), positions.col(t[1]), positions.col(t[2]));
    best = std::min(best, (q - p).squaredNorm());
  }
  return std::sqrt(best);
}

double blade_to_margin_mm(const Eigen::Vector3d& blade_a, const Eigen::Vector3d& blade_b, const TriMesh& tumour, double margin_mm,
                          double step_mm) {
  const double length = (blade_b - blade_a).norm();
  const int samples = std::max(1, static_cast<int>(std::ceil(length / step_mm)));
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= samples; ++i) {
    const Eigen::Vector3d p = blade_a + (blade_b - blade_a) * (static_cast<double>(i) / samples);
    double d = point_mesh_distance(p, tumour.positions_World_mm, tumour.tris);
    if (winding_number(tumour, p) > 0.5) d = -d;
    best = std::min(best, d);
  }
  return best - margin_mm;
}

}  // namespace arnav::host::overlay
