#pragma once
// Embedded structures split along the cut (docs/cut.md, "Tumours and vessels"): a tumour
// surface (closed triangle mesh) or vessel centerlines (segments) carried by the volume are
// split where the cut separates the volume, in the rest configuration:
//  - an edge (segment) of the structure crosses the cut where it passes through a pair of
//    coincident boundary faces of the cut mesh with opposite orientation (the two lips of a
//    cut face); the crossing becomes two new points, one embedded in the tet on each side
//    (on its lip face), so each follows its own piece when the cut opens;
//  - a triangle with two crossed edges is split into three (one on the lone vertex's side,
//    two on the other), one crossed edge (the cut ends inside the triangle) into two meeting
//    at the opposite vertex, three crossed edges (two cuts) into its three corners;
//  - each boundary loop the splitting opens is closed, so every part stays a closed,
//    consistently oriented 2-manifold surface: a loop of one side (the cut goes through) by a
//    fan of triangles around a centre put on the cut (embedded on the loop's side); a slit
//    (the cut ends inside the surface: the loop runs from one crack end along the copies of
//    one side to the other crack end and back along the other side's) by a surface per side
//    spanning its copies and the chord between the crack ends, the triangulation of least
//    area (short rungs along a long curved slit, where a fan from one point makes slivers
//    that cross the surface), the two sides' mirror images meeting along the chord;
//  - a segment crossed is replaced by two segments ending at the two new points.
// The split is recomputed from the uncut structure against the current cut mesh, so it only
// depends on where the cut is. Frame World, units mm.
#include <Eigen/Core>

#include <array>
#include <optional>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/cut/bvh.hpp"
#include "host/scene/embedding.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

// Where a rest segment p0-p1 crosses the cut.
struct SegmentCut {
  double s = 0.0;                 // crossing at p0 + s (p1 - p0)
  int tet0 = -1, tet1 = -1;       // tets on p0's and p1's side, each holding the crossing on a lip face
  Eigen::Vector3d normal0 = Eigen::Vector3d::Zero();  // outward unit normal of tet0's lip face (towards p1's side)
};

// The lips of the cut near a region of the rest configuration: boundary faces of the cut
// mesh's tets whose rest boxes meet the region, in a hierarchy.
class CutLips {
 public:
  // region_tets: tets that may hold the lips (e.g. the pieces of the input tets meeting a
  // structure's box that have a face on a cut); only their faces are looked at, and
  // locate() searches only them.
  CutLips(const TetMesh& mesh, const std::vector<int>& region_tets);
  // First crossing from p0 (rest positions); nullopt when the segment does not cross the cut.
  std::optional<SegmentCut> crossing(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1) const;
  // The lip nearest to p along the line p + s d (|s| <= reach) whose tet lies on the side d
  // points into (its outward normal against d): the point there and that tet; tet -1 none.
  int lip_along(const Eigen::Vector3d& p, const Eigen::Vector3d& d, double reach, Eigen::Vector3d& on_lip) const;
  // The region tet containing p (rest), or the one with the largest smallest weight; -1 none.
  int locate(const Eigen::Vector3d& p, Eigen::Vector4d& weights) const;
  int lip_faces() const { return static_cast<int>(faces_.size()); }  // faces with a twin (both lips counted)

 private:
  struct Face {
    Triangle tri;
    int tet;
    Eigen::Vector3d normal;
  };
  const TetMesh& mesh_;
  std::vector<int> region_tets_;
  std::vector<Face> faces_;
  Bvh bvh_;
};

// The edges (segments) of an uncut structure in the rest configuration, in a hierarchy: which
// faces a cut added could split it. A face no edge passes through leaves the split as it was
// (split_surface and split_segments only split edges that pass through a lip), so a step
// whose new cut faces miss the structure need not split it again (CutSession).
class StructureEdges {
 public:
  StructureEdges() = default;
  StructureEdges(const Eigen::Matrix3Xd& rest_World_mm, std::vector<std::array<int, 2>> edges);
  // Some edge passes through the face, or within a thousandth of its size beyond its sides
  // (a segment through the common edge of two faces is split by either).
  bool crossed_by(const Triangle& face) const;

 private:
  Eigen::Matrix3Xd rest_;
  std::vector<std::array<int, 2>> edges_;
  Bvh bvh_;
};

// The edges of a triangle mesh, each once.
std::vector<std::array<int, 2>> surface_edges(const std::vector<std::array<int, 3>>& tris);

// Barycentric weights of rest point p in tet t of mesh.
Eigen::Vector4d rest_weights(const TetMesh& mesh, int tet, const Eigen::Vector3d& p);

struct SplitStructure {
  Eigen::Matrix3Xd rest_World_mm;        // the input points, then the new ones
  Embedding embedding;                   // one column per point
  std::vector<int> source;               // per point: the input point it takes its side from (itself for input points; -1 for a cap centre)
  std::vector<std::array<int, 3>> tris;  // split surface (closed again) or empty
  std::vector<std::array<int, 2>> segments;  // split polyline or empty
  int crossed_edges = 0;                 // input edges/segments crossing the cut
  int caps = 0;                          // loops closed (a fan, or a slit's two sides)
  int slits = 0;                         // of which slits (the cut ends inside the surface)
  int ragged_slits = 0;                  // of which sewn by the loop's own triangulation (not side by side)
  int first_cap_tri = 0;                 // tris[first_cap_tri..]: the triangles closing the loops
};

// Splits a closed surface (rest points, their embedding in mesh, triangles) along the cut.
SplitStructure split_surface(const TetMesh& mesh, const CutLips& lips, const Eigen::Matrix3Xd& rest_World_mm,
                             const Embedding& embedding, const std::vector<std::array<int, 3>>& tris);

// Splits polyline segments along the cut.
SplitStructure split_segments(const TetMesh& mesh, const CutLips& lips, const Eigen::Matrix3Xd& rest_World_mm,
                              const Embedding& embedding, const std::vector<std::array<int, 2>>& segments);

}  // namespace arnav::host::cut
