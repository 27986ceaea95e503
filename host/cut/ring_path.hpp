#pragma once
// A lesion cut out the way a surgeon would (paper 000's ring-shaped lesion), derived from the
// scene rather than written for one mesh (docs/cut.md, "Ring path from the scene"):
//  - access: the direction from the tumour to the organ surface (among `directions` evenly
//    spread ones) with the shallowest tumour
//    whose cored cylinder (ring radius, from the surface down to the bottom cut) holds no
//    fixed vertex: the cut never goes through the organ's attachment (ligaments), so the
//    block comes out as a free body;
//  - ring: the blade along that axis, from the surface to `bottom_overshoot_mm` past the bottom
//    cut, plunged in outside the tumour's margin and taken round a circle of radius
//    (tumour's extent across the axis + margin) at `ring_speed_mm_s`, `overlap_deg` past
//    its start, then lifted out along itself;
//  - bottom cut: a straight blade across the axis in the plane `margin` beyond the tumour's
//    far side, spanning the ring and RingPath::extension_mm beyond it on both sides, swept
//    across at `bottom_speed_mm_s` from outside the organ on the side where its edge is
//    nearest (the shortest slit through healthy tissue) to extension_mm past the ring's far
//    side; then the blade is taken out of the organ (cutting off) in one frame. The ring
//    reaches below the bottom cut, and the bottom cut beyond the ring, by the crack front's
//    lag (the longest edge round the ring's foot: RingPath::overshoot_mm, extension_mm), so
//    that the two cuts meet in the mesh.
// Frame World (the configuration given: the organ as it hangs), units mm, s.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/cut/scalpel_path.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

struct RingPathSettings {
  double margin_mm = 10.0;              // ring and bottom cut beyond the tumour's extent
  double ring_speed_mm_s = 20.0;        // blade speed round the ring (issue 11: 20 mm/s)
  double bottom_speed_mm_s = 40.0;      // bottom cut's speed
  double plunge_speed_mm_s = 80.0;      // plunging in and lifting out, along the blade
  double overlap_deg = 15.0;            // ring and bottom cut go this far past their start
  double bottom_overshoot_mm = 5.0;     // ring blade's end past the bottom cut's plane (at least; see RingPath::overshoot_mm)
  double bottom_extension_mm = 5.0;     // bottom blade beyond the ring (at least; see RingPath::extension_mm)
  double outside_mm = 10.0;             // blade ends outside the organ by this much
  double wait_s = 0.5;                  // blade outside before each stroke
  double hold_s = 1.0;                  // after the bottom cut (the block falls)
  int directions = 256;                 // access directions tried
};

struct RingPath {
  ScalpelPath path;
  Eigen::Vector3d centre_World_mm = Eigen::Vector3d::Zero();  // tumour centre (mean of its points)
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();             // unit, from the tumour towards the access surface
  double radius_mm = 0;        // ring radius
  double bottom_mm = 0;        // bottom cut's plane: centre - bottom_mm * axis
  double surface_mm = 0;       // the organ's surface along the axis (farthest vertex in the cylinder)
  double overshoot_mm = 0;     // ring blade's end below the bottom cut (crack front lag: the longest edge round the ring's foot)
  double extension_mm = 0;     // bottom cut beyond the ring on each side (the same)
  double ring_end_s = 0;       // time the ring stroke ends (cutting off), the bottom stroke starts after
  double cut_end_s = 0;        // time the bottom cut ends
  std::string csv() const;     // the arnav-sim --scalpel CSV of the path
};

// The ring and bottom cut round the tumour whose points (World, the configuration x) are
// given. x: positions of mesh's vertices (the organ as it hangs); fixed: the fixed vertices.
// Throws std::invalid_argument when no access direction keeps the fixed vertices out of the
// block (the tumour lies against the attachment: then no cut frees it) or the tumour has no
// points.
RingPath make_ring_path(const TetMesh& mesh, const Eigen::Matrix3Xd& x_World_mm, const std::vector<int>& fixed_vertices,
                        const Eigen::Matrix3Xd& tumour_World_mm, const RingPathSettings& settings = {});

// The blade as a surgeon following the lesion holds it: the planned blade (World, in the
// configuration the path was made in) carried by the rigid motion (rotation and translation,
// least squares: Eigen::umeyama) that best maps the tracked points from where they were then
// (tracked_then, e.g. the tumour's points when make_ring_path ran) to where they are now
// (tracked_now, the same points in the same order). The cut stays round the lesion while the
// organ swings; what is tracked is the lesion's rigid motion, not its deformation (the blade
// is not bent with the tissue). Throws std::invalid_argument when the point sets differ in
// size or have fewer than 3 points.
BladeSegment follow_tracked(const BladeSegment& planned_World_mm, const Eigen::Matrix3Xd& tracked_then_World_mm,
                            const Eigen::Matrix3Xd& tracked_now_World_mm);

// True when the piece holding tet seed_tet has no fixed vertex: it has come free (a piece is
// a vertex-connected part of the mesh; a cut duplicates the vertices on it, so pieces share
// none). O(tets). A surgeon following the lesion (follow_tracked) stops following it then.
bool piece_is_free(const TetMesh& mesh, int seed_tet, const std::vector<int>& fixed_vertices);

}  // namespace arnav::host::cut
