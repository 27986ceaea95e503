#include "hil_tests/scenarios/surface_error.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace arnav::hil {

CentroidError3d centroid_error_3d(const Eigen::Vector3d& drawn, const Eigen::Vector3d& truth) {
  if (!(truth.norm() > 0.0)) throw std::invalid_argument("centroid_error_3d: the true centroid is at the camera centre");
  const Eigen::Vector3d d = drawn - truth;
  const Eigen::Vector3d ray = truth.normalized();
  CentroidError3d e;
  e.distance_mm = d.norm();
  e.along_ray_mm = d.dot(ray);
  e.across_ray_mm = (d - e.along_ray_mm * ray).norm();
  return e;
}

// Closest point on a triangle by regions (Voronoi regions of vertices, edges, face).
double point_triangle_distance_mm(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return ap.norm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return bp.norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return cp.norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

namespace {

void check(const TriSurface& s, const char* which) {
  if (s.vertices_mm.empty() || s.triangles.empty())
    throw std::invalid_argument(std::string("surface_distance: the ") + which + " surface is empty");
  const int n = static_cast<int>(s.vertices_mm.size());
  for (const auto& t : s.triangles)
    if ((t.array() < 0).any() || (t.array() >= n).any())
      throw std::invalid_argument(std::string("surface_distance: a triangle of the ") + which + " surface indexes a vertex out of range");
}

// Distances from each vertex of `from` to the surface `to`, appended.
void vertex_distances(const TriSurface& from, const TriSurface& to, std::vector<double>& out) {
  for (const auto& p : from.vertices_mm) {
    double best = std::numeric_limits<double>::infinity();
    for (const auto& t : to.triangles)
      best = std::min(best, point_triangle_distance_mm(p, to.vertices_mm[static_cast<std::size_t>(t[0])],
                                                       to.vertices_mm[static_cast<std::size_t>(t[1])],
                                                       to.vertices_mm[static_cast<std::size_t>(t[2])]));
    out.push_back(best);
  }
}

}  // namespace

SurfaceDistance surface_distance(const TriSurface& drawn, const TriSurface& truth) {
  check(drawn, "drawn");
  check(truth, "true");
  std::vector<double> d;
  vertex_distances(drawn, truth, d);
  vertex_distances(truth, drawn, d);
  SurfaceDistance s;
  for (double x : d) {
    s.mean_mm += x;
    s.max_mm = std::max(s.max_mm, x);
  }
  s.mean_mm /= static_cast<double>(d.size());
  return s;
}

}  // namespace arnav::hil
