#pragma once
// Self-contact of a closed organ surface during the non-rigid fit (paper 002's
// self-collision term): lobes must not pass through each other. A surface vertex is in
// contact with a triangle of another part of the surface when it comes closer than a
// margin to that triangle's outer side or has crossed it. "Another part": the triangle
// has no vertex within `exclusion_mm` of the vertex along the surface's edges (geodesic
// on the edge graph, at rest), and at rest the vertex lay on the triangle's outer side
// (so the two faces of a thin lobe, which face away from each other, are not a contact).
// The search uses the SurfaceIndex grid on the current positions.
// Frame: that of the positions given (Model in the registration). Units: mm.
#include <Eigen/Core>

#include <array>
#include <vector>

namespace arnav::host {

struct SelfContact {
  int vertex = -1;                                         // column of the positions
  int tri = -1;                                            // index into the triangles
  Eigen::Vector3d barycentric = Eigen::Vector3d::Zero();   // closest point on the triangle
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();        // outward, unit, at the closest point
  double signed_distance_mm = 0.0;                         // normal . (vertex - point); < 0: crossed
  double wanted_mm = 0.0;                                  // the separation the vertex should keep
};

class SelfContactDetector {
 public:
  // rest: positions (3 x n, the columns the triangles index); tris: closed, outward.
  // exclusion_mm <= 0: three times the mean edge length.
  SelfContactDetector(const Eigen::Matrix3Xd& rest, const std::vector<std::array<int, 3>>& tris, double exclusion_mm = 0.0);
  // Contacts at positions x: vertices closer than margin_mm to the outer side of another
  // part's triangle (wanted separation min(margin, rest separation)), or behind it by up
  // to max_depth_mm.
  std::vector<SelfContact> find(const Eigen::Matrix3Xd& x, double margin_mm, double max_depth_mm) const;
  // Surface vertices that lie inside another part at x (crossed a non-adjacent triangle):
  // the measure of lobes passing through each other.
  int count_crossed(const Eigen::Matrix3Xd& x, double max_depth_mm) const;
  double exclusion_mm() const { return exclusion_mm_; }
  // A vertex whose rest clearance exceeds twice the largest displacement from rest plus
  // the search reach cannot touch another part: find() skips it (most of a convex organ).

 private:
  Eigen::Matrix3Xd rest_;
  std::vector<std::array<int, 3>> tris_;
  std::vector<int> vertices_;                  // surface vertices
  std::vector<std::vector<int>> near_;         // per column: sorted columns within the exclusion radius (surface only)
  std::vector<double> clearance_;              // per column: rest distance to the nearest facing triangle of another part (capped)
  double exclusion_mm_ = 0.0;
};

}  // namespace arnav::host
