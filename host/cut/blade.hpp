#pragma once
// The tracked scalpel as a segment and the surface it sweeps between two frames.
// Frames: Tool (the scalpel's marker body, from the tracker) and World (the scene frame).
// Units: mm. The blade is the segment from the tip to the heel, a point further along the
// cutting edge (both calibrated in the tool frame: pivot for the tip plus a second point).
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <string>
#include <vector>

namespace arnav::host::cut {

// Blade geometry in the tool frame.
struct Blade {
  Eigen::Vector3d tip_Tool_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d heel_Tool_mm = Eigen::Vector3d(0, 0, 20);
};

// The blade edge in World at one instant.
struct BladeSegment {
  Eigen::Vector3d tip_World_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d heel_World_mm = Eigen::Vector3d::Zero();
};

// The blade moved by the tool pose X_World_Tool (pose of the tool frame in World).
BladeSegment blade_in_world(const Blade& blade, const Eigen::Isometry3d& X_World_Tool);

struct Triangle {
  Eigen::Vector3d a, b, c;
};

// The ruled surface swept by the blade from `from` to `to`: the bilinear patch
// S(u, s) = (1-s) [(1-u) tip0 + u heel0] + s [(1-u) tip1 + u heel1], u along the blade
// (tip 0, heel 1), s in time. It is triangulated into `strips` strips along the blade (two
// triangles each); for a blade that moves without twisting (all four points coplanar) one
// strip is exact, otherwise the triangles deviate from the patch by at most
// max_deviation_mm() (reported by the cut benchmark as part of path fidelity).
struct SweptSurface {
  BladeSegment from, to;
  int strips = 1;
  // Optional: the start line as strips + 1 points, tip first (the previous blade carried along
  // with the tissue during the last step: the new strip starts on the material the last one
  // ended on). Replaces `from` when it has strips + 1 points.
  std::vector<Eigen::Vector3d> from_points;

  std::vector<Triangle> triangles() const;
  // Largest distance between the bilinear patch and its triangulation (mid-points of the
  // strip diagonals), mm.
  double max_deviation_mm() const;
  // True when the blade did not move (no area swept).
  bool degenerate(double tolerance_mm = 1e-9) const;
};

// Point-triangle distance (mm) and closest point.
double point_triangle_distance(const Eigen::Vector3d& p, const Triangle& t, Eigen::Vector3d* closest = nullptr);

// Intersection of segment p0-p1 with triangle t. Returns true and the parameter s in [0, 1]
// along the segment when the segment crosses or touches the triangle (edges included, within
// a relative tolerance); a segment lying in the triangle's plane reports no crossing.
bool segment_triangle_intersection(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Triangle& t, double& s);

}  // namespace arnav::host::cut
