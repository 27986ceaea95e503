#include "host/register/surface_index.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>

namespace arnav::host {

// Ericson, Real-Time Collision Detection, 5.1.5: Voronoi regions of the triangle.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) return {1, 0, 0};  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  return {1 - v - w, v, w};
}

SurfaceIndex::SurfaceIndex(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris) : x_(positions), tris_(tris) {
  vertex_normals_ = Eigen::Matrix3Xd::Zero(3, x_.cols());
  if (tris_.empty()) return;
  double edge_sum = 0.0;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::max()), hi = -lo;
  for (const auto& t : tris_) {
    const Eigen::Vector3d a = x_.col(t[0]), b = x_.col(t[1]), c = x_.col(t[2]);
    const Eigen::Vector3d n = (b - a).cross(c - a);
    for (int k = 0; k < 3; ++k) vertex_normals_.col(t[static_cast<std::size_t>(k)]) += n;
    edge_sum += (b - a).norm() + (c - b).norm() + (a - c).norm();
    lo = lo.cwiseMin(a).cwiseMin(b).cwiseMin(c);
    hi = hi.cwiseMax(a).cwiseMax(b).cwiseMax(c);
  }
  for (int i = 0; i < vertex_normals_.cols(); ++i) {
    const double n = vertex_normals_.col(i).norm();
    if (n > 0) vertex_normals_.col(i) /= n;
  }
  const double mean_edge = edge_sum / (3.0 * static_cast<double>(tris_.size()));
  cell_ = std::max(2.0 * mean_edge, 1e-6);
  origin_ = lo;
  // at most ~32^3 cells (far queries visit every shell)
  const Eigen::Vector3d ext = hi - lo;
  cell_ = std::max(cell_, ext.maxCoeff() / 32.0);
  for (int k = 0; k < 3; ++k) dims_[static_cast<std::size_t>(k)] = std::max(1, static_cast<int>(std::floor(ext[k] / cell_)) + 1);
  const int ncell = dims_[0] * dims_[1] * dims_[2];
  std::vector<int> count(static_cast<std::size_t>(ncell) + 1, 0);
  auto range = [&](const std::array<int, 3>& t, std::array<int, 3>& a, std::array<int, 3>& b) {
    const Eigen::Vector3d mn = x_.col(t[0]).cwiseMin(x_.col(t[1])).cwiseMin(x_.col(t[2]));
    const Eigen::Vector3d mx = x_.col(t[0]).cwiseMax(x_.col(t[1])).cwiseMax(x_.col(t[2]));
    for (int k = 0; k < 3; ++k) {
      a[static_cast<std::size_t>(k)] = std::clamp(static_cast<int>(std::floor((mn[k] - origin_[k]) / cell_)), 0, dims_[static_cast<std::size_t>(k)] - 1);
      b[static_cast<std::size_t>(k)] = std::clamp(static_cast<int>(std::floor((mx[k] - origin_[k]) / cell_)), 0, dims_[static_cast<std::size_t>(k)] - 1);
    }
  };
  std::array<int, 3> a{}, b{};
  for (const auto& t : tris_) {
    range(t, a, b);
    for (int k = a[2]; k <= b[2]; ++k)
      for (int j = a[1]; j <= b[1]; ++j)
        for (int i = a[0]; i <= b[0]; ++i) ++count[static_cast<std::size_t>(cell_index(i, j, k)) + 1];
  }
  for (int c = 0; c < ncell; ++c) count[static_cast<std::size_t>(c) + 1] += count[static_cast<std::size_t>(c)];
  cell_start_ = count;
  cell_tris_.resize(static_cast<std::size_t>(count.back()));
  std::vector<int> fill(count.begin(), count.end() - 1);
  for (int ti = 0; ti < static_cast<int>(tris_.size()); ++ti) {
    range(tris_[static_cast<std::size_t>(ti)], a, b);
    for (int k = a[2]; k <= b[2]; ++k)
      for (int j = a[1]; j <= b[1]; ++j)
        for (int i = a[0]; i <= b[0]; ++i) cell_tris_[static_cast<std::size_t>(fill[static_cast<std::size_t>(cell_index(i, j, k))]++)] = ti;
  }
}

SurfaceHit SurfaceIndex::closest(const Eigen::Vector3d& q, double max_distance_mm) const { return closest(q, max_distance_mm, {}); }

SurfaceHit SurfaceIndex::closest(const Eigen::Vector3d& q, double max_distance_mm, const std::function<bool(int)>& skip) const {
  SurfaceHit best;
  if (tris_.empty()) return best;
  // nothing beyond max_distance_mm is of interest: cells and triangles further away are
  // not looked at (a miss costs only the cells within reach)
  double best_d2 = std::isfinite(max_distance_mm) ? max_distance_mm * max_distance_mm * (1.0 + 1e-12) : std::numeric_limits<double>::infinity();
  int c[3];
  for (int k = 0; k < 3; ++k) c[k] = std::clamp(static_cast<int>(std::floor((q[k] - origin_[k]) / cell_)), 0, dims_[static_cast<std::size_t>(k)] - 1);
  // distance from q to the grid box (q may be outside it)
  const Eigen::Vector3d hi = origin_ + cell_ * Eigen::Vector3d(dims_[0], dims_[1], dims_[2]);
  const double outside = (origin_ - q).cwiseMax(q - hi).cwiseMax(0.0).norm();
  const int max_ring = std::max({dims_[0], dims_[1], dims_[2]});
  auto test_cell = [&](int i, int j, int k) {
    const int cell = cell_index(i, j, k);
    if (cell_start_[static_cast<std::size_t>(cell)] == cell_start_[static_cast<std::size_t>(cell) + 1]) return;
    // skip a cell whose box is further than the best so far (its triangles lie inside it)
    const Eigen::Vector3d lo = origin_ + cell_ * Eigen::Vector3d(i, j, k);
    const double box_d2 = (lo - q).cwiseMax(q - lo - Eigen::Vector3d::Constant(cell_)).cwiseMax(0.0).squaredNorm();
    if (box_d2 >= best_d2) return;
    for (int s = cell_start_[static_cast<std::size_t>(cell)]; s < cell_start_[static_cast<std::size_t>(cell) + 1]; ++s) {
      const int ti = cell_tris_[static_cast<std::size_t>(s)];
      const auto& t = tris_[static_cast<std::size_t>(ti)];
      const Eigen::Vector3d w = closest_on_triangle(q, x_.col(t[0]), x_.col(t[1]), x_.col(t[2]));
      const Eigen::Vector3d p = w[0] * x_.col(t[0]) + w[1] * x_.col(t[1]) + w[2] * x_.col(t[2]);
      const double d2 = (p - q).squaredNorm();
      if (d2 < best_d2 && !(skip && skip(ti))) {
        best_d2 = d2;
        best.tri = ti;
        best.barycentric = w;
        best.point = p;
      }
    }
  };
  for (int ring = 0; ring <= max_ring; ++ring) {
    // cells at Chebyshev distance `ring` from c
    for (int k = c[2] - ring; k <= c[2] + ring; ++k) {
      if (k < 0 || k >= dims_[2]) continue;
      for (int j = c[1] - ring; j <= c[1] + ring; ++j) {
        if (j < 0 || j >= dims_[1]) continue;
        const bool shell_jk = std::abs(k - c[2]) == ring || std::abs(j - c[1]) == ring;
        for (int i = c[0] - ring; i <= c[0] + ring; ++i) {
          if (i < 0 || i >= dims_[0]) continue;
          if (!shell_jk && std::abs(i - c[0]) != ring) continue;
          test_cell(i, j, k);
        }
      }
    }
    // every triangle not yet tested lies at least `ring * cell_` from q along one axis,
    // and at least as far as q is outside the grid
    const double reach = std::max(outside, static_cast<double>(ring) * cell_);
    if (best.tri >= 0 && best_d2 <= reach * reach) break;
    if (reach > max_distance_mm) break;  // anything further is of no interest
  }
  if (best.tri < 0 || best_d2 > max_distance_mm * max_distance_mm) {
    SurfaceHit none;
    none.distance_mm = std::numeric_limits<double>::infinity();
    return none;
  }
  const auto& t = tris_[static_cast<std::size_t>(best.tri)];
  best.distance_mm = std::sqrt(best_d2);
  Eigen::Vector3d n = best.barycentric[0] * vertex_normals_.col(t[0]) + best.barycentric[1] * vertex_normals_.col(t[1]) +
                      best.barycentric[2] * vertex_normals_.col(t[2]);
  if (n.norm() < 1e-12) n = (x_.col(t[1]) - x_.col(t[0])).cross(x_.col(t[2]) - x_.col(t[0]));
  best.normal = n.normalized();
  return best;
}

}  // namespace arnav::host
