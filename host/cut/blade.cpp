#include "host/cut/blade.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace arnav::host::cut {

BladeSegment blade_in_world(const Blade& blade, const Eigen::Isometry3d& X_World_Tool) {
  return {X_World_Tool * blade.tip_Tool_mm, X_World_Tool * blade.heel_Tool_mm};
}

namespace {
Eigen::Vector3d patch(const SweptSurface& s, double u, double t) {
  Eigen::Vector3d p0 = (1 - u) * s.from.tip_World_mm + u * s.from.heel_World_mm;
  const int n = std::max(1, s.strips);
  if (static_cast<int>(s.from_points.size()) == n + 1) {
    const double k = std::clamp(u * n, 0.0, static_cast<double>(n));
    const int i = std::min(static_cast<int>(k), n - 1);
    p0 = s.from_points[static_cast<std::size_t>(i)] + (k - i) * (s.from_points[static_cast<std::size_t>(i) + 1] - s.from_points[static_cast<std::size_t>(i)]);
  }
  const Eigen::Vector3d p1 = (1 - u) * s.to.tip_World_mm + u * s.to.heel_World_mm;
  return (1 - t) * p0 + t * p1;
}
}  // namespace

std::vector<Triangle> SweptSurface::triangles() const {
  std::vector<Triangle> out;
  const int n = std::max(1, strips);
  out.reserve(2 * static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double u0 = static_cast<double>(i) / n, u1 = static_cast<double>(i + 1) / n;
    const Eigen::Vector3d a = patch(*this, u0, 0), b = patch(*this, u1, 0), c = patch(*this, u1, 1), d = patch(*this, u0, 1);
    out.push_back({a, b, c});
    out.push_back({a, c, d});
  }
  return out;
}

double SweptSurface::max_deviation_mm() const {
  const int n = std::max(1, strips);
  double worst = 0.0;
  for (int i = 0; i < n; ++i) {
    const double u0 = static_cast<double>(i) / n, u1 = static_cast<double>(i + 1) / n;
    // The diagonal a-c of each strip against the patch at the same parameters.
    const Eigen::Vector3d mid_diag = 0.5 * (patch(*this, u0, 0) + patch(*this, u1, 1));
    worst = std::max(worst, (mid_diag - patch(*this, 0.5 * (u0 + u1), 0.5)).norm());
  }
  return worst;
}

bool SweptSurface::degenerate(double tolerance_mm) const {
  return (from.tip_World_mm - to.tip_World_mm).norm() <= tolerance_mm &&
         (from.heel_World_mm - to.heel_World_mm).norm() <= tolerance_mm;
}

double point_triangle_distance(const Eigen::Vector3d& p, const Triangle& t, Eigen::Vector3d* closest) {
  // Ericson, Real-Time Collision Detection, 5.1.5 (Voronoi regions of the triangle).
  const Eigen::Vector3d ab = t.b - t.a, ac = t.c - t.a, ap = p - t.a;
  Eigen::Vector3d q;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) {
    q = t.a;
  } else {
    const Eigen::Vector3d bp = p - t.b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    const Eigen::Vector3d cp = p - t.c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    const double vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;
    if (d3 >= 0 && d4 <= d3) {
      q = t.b;
    } else if (vc <= 0 && d1 >= 0 && d3 <= 0) {
      q = t.a + d1 / (d1 - d3) * ab;
    } else if (d6 >= 0 && d5 <= d6) {
      q = t.c;
    } else if (vb <= 0 && d2 >= 0 && d6 <= 0) {
      q = t.a + d2 / (d2 - d6) * ac;
    } else if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
      q = t.b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (t.c - t.b);
    } else {
      const double denom = va + vb + vc;
      if (!(std::abs(denom) > 0)) {
        q = t.a;  // degenerate triangle
      } else {
        q = t.a + (vb / denom) * ab + (vc / denom) * ac;
      }
    }
  }
  if (closest) *closest = q;
  return (p - q).norm();
}

bool segment_triangle_intersection(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Triangle& t, double& s) {
  const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a);
  const double area2 = n.norm();
  if (!(area2 > 0)) return false;
  const Eigen::Vector3d nu = n / area2;
  const double d0 = nu.dot(p0 - t.a), d1 = nu.dot(p1 - t.a);
  if ((d0 > 0 && d1 > 0) || (d0 < 0 && d1 < 0)) return false;
  if (d0 == d1) return false;  // in the plane (or both zero): no transversal crossing
  s = d0 / (d0 - d1);
  const Eigen::Vector3d p = p0 + s * (p1 - p0);
  // Barycentric test with a tolerance relative to the triangle size (edges included, so a
  // point on the common edge of two sweep triangles is found by both).
  const double eps = 1e-9;
  const double w_a = nu.dot((t.b - p).cross(t.c - p)) / area2;
  const double w_b = nu.dot((t.c - p).cross(t.a - p)) / area2;
  const double w_c = 1.0 - w_a - w_b;
  return w_a >= -eps && w_b >= -eps && w_c >= -eps;
}

}  // namespace arnav::host::cut
