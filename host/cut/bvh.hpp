#pragma once
// Axis-aligned bounding-box hierarchy over primitives (surface triangles, tetrahedra) whose
// vertices move every frame: built once per topology (median split), refitted in O(n) after
// deformation, queried for boxes and segments. Frame World, units mm.
#include <Eigen/Core>

#include <array>
#include <functional>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

struct Aabb {
  Eigen::Vector3d min = Eigen::Vector3d::Constant(1e300);
  Eigen::Vector3d max = Eigen::Vector3d::Constant(-1e300);
  void extend(const Eigen::Vector3d& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  void extend(const Aabb& b) {
    min = min.cwiseMin(b.min);
    max = max.cwiseMax(b.max);
  }
  bool overlaps(const Aabb& b) const { return (min.array() <= b.max.array()).all() && (b.min.array() <= max.array()).all(); }
  Aabb inflated(double r) const { return {min.array() - r, max.array() + r}; }
  bool contains(const Eigen::Vector3d& p) const { return (min.array() <= p.array()).all() && (p.array() <= max.array()).all(); }
};

// Primitives are given by their boxes; the caller computes them from its own vertices (a
// triangle, a tetrahedron, all the pieces a tetrahedron was cut into).
class Bvh {
 public:
  void build(const std::vector<Aabb>& prim_boxes);
  // New boxes for the same primitives (after deformation): O(n), no re-sorting.
  void refit(const std::vector<Aabb>& prim_boxes);
  // Calls visit(i) for every primitive whose box overlaps `box`.
  void query(const Aabb& box, const std::function<void(int)>& visit) const;
  int size() const { return static_cast<int>(prim_boxes_.size()); }
  const Aabb& root_box() const { return nodes_.empty() ? empty_ : nodes_[0].box; }

 private:
  struct Node {
    Aabb box;
    int left = -1, right = -1;  // children (internal node)
    int first = 0, count = 0;   // range in order_ (leaf)
  };
  int build_node(int first, int count, std::vector<Eigen::Vector3d>& centroids);
  void refit_node(int n);
  std::vector<int> order_;
  std::vector<Aabb> prim_boxes_;
  std::vector<Node> nodes_;
  Aabb empty_;
};

// Blade against the organ surface (a closed triangle mesh at positions x).
struct Contact {
  bool touching = false;
  Eigen::Vector3d point_World_mm = Eigen::Vector3d::Zero();  // where the blade enters the surface
  int triangle = -1;                                         // surface triangle entered
  double depth_mm = 0.0;  // length of blade inside the organ from the entry point to the tip
  bool tip_inside = false;
};

// Crossings of the blade segment with the surface triangles; the entry is the crossing
// closest to the heel (the blade is pushed in tip first). depth_mm is the distance from the
// entry to the tip when the tip is inside (odd number of crossings between tip and heel
// ends), 0 otherwise. The hierarchy must be built on `tris` and refitted to `x`
// (triangle_boxes).
Contact blade_contact(const Bvh& bvh, const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x_World_mm,
                      const BladeSegment& blade);

// The same over any search structure: query(box, visit) calls visit(i) for (at least) every
// triangle i whose box overlaps box; tris[i] == {-1, -1, -1} is skipped.
using TriangleQuery = std::function<void(const Aabb&, const std::function<void(int)>&)>;
Contact blade_contact(const TriangleQuery& query, const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x_World_mm,
                      const BladeSegment& blade);

// Boxes of triangles at positions x, for Bvh::build/refit.
std::vector<Aabb> triangle_boxes(const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x_World_mm);

}  // namespace arnav::host::cut
