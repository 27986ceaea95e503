#pragma once
// Closest points on a triangle surface (organ surface, model or deformed), for ICP and
// the non-rigid data term. A uniform grid of triangle boxes; a query searches growing
// shells of cells until no closer triangle can exist, so the answer is exact.
// Frame: that of the positions given. Units: mm.
#include <Eigen/Core>

#include <array>
#include <functional>
#include <limits>
#include <vector>

namespace arnav::host {

struct SurfaceHit {
  int tri = -1;
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();  // weights of the triangle's 3 vertices
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();       // interpolated vertex normal, unit, outward
  double distance_mm = 0.0;
};

class SurfaceIndex {
 public:
  SurfaceIndex() = default;
  // Triangles must reference columns of positions; normals point to the side the
  // triangles' counter-clockwise order faces.
  SurfaceIndex(const Eigen::Matrix3Xd& positions, const std::vector<std::array<int, 3>>& tris);
  // Nothing within max_distance_mm: tri = -1 and distance_mm = +inf (cheap for outliers).
  SurfaceHit closest(const Eigen::Vector3d& q, double max_distance_mm = std::numeric_limits<double>::infinity()) const;
  // The same over the triangles for which skip(triangle index) is false (self-contact:
  // the part of the surface around the query's own vertex is skipped).
  SurfaceHit closest(const Eigen::Vector3d& q, double max_distance_mm, const std::function<bool(int)>& skip) const;
  bool empty() const { return tris_.empty(); }
  const Eigen::Matrix3Xd& vertex_normals() const { return vertex_normals_; }
  const Eigen::Matrix3Xd& positions() const { return x_; }
  const std::vector<std::array<int, 3>>& tris() const { return tris_; }

 private:
  Eigen::Matrix3Xd x_;
  std::vector<std::array<int, 3>> tris_;
  Eigen::Matrix3Xd vertex_normals_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double cell_ = 1.0;
  std::array<int, 3> dims_{1, 1, 1};
  std::vector<int> cell_start_;  // CSR: triangles per cell
  std::vector<int> cell_tris_;
  int cell_index(int i, int j, int k) const { return (k * dims_[1] + j) * dims_[0] + i; }
};

// Closest point on triangle abc to p; returns barycentric weights of a, b, c.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c);

}  // namespace arnav::host
