#pragma once
// The boundary of a tet mesh that a cut changes, kept up to date from the tets the cut
// changed (TetCutter's CutStepReport::changed_tets), with its bounding-volume hierarchy
// updated instead of rebuilt (docs/cut.md, "Work per frame"). Frame World, units mm.
//  - Faces are counted per sorted vertex triple with the tets that own them; a face owned by
//    one tet is a boundary face, oriented outward as that tet sees it (the same set and
//    orientation as boundary_faces()). An update removes the old faces of the changed tets
//    and adds their new ones: O(changed tets).
//  - Boundary faces live in slots: a removed face leaves an empty slot, a new face takes a
//    new slot at the end. The hierarchy covers the slots that existed when it was built
//    (empty ones have empty boxes); later slots are searched linearly until there are more
//    than an eighth of the built ones (at least 64) or half the slots are empty, then the
//    slots are compacted and the hierarchy rebuilt over the live faces (amortised).
#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "host/cut/bvh.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host::cut {

class SurfaceTracker {
 public:
  SurfaceTracker() = default;
  // All boundary faces of the mesh: O(tets).
  explicit SurfaceTracker(const TetMesh& mesh);

  // The tets `changed_tets` (any order, duplicates allowed) of `mesh` were changed or
  // appended since the last update; every other tet is as before.
  void update(const TetMesh& mesh, const std::vector<int>& changed_tets);

  // Faces by slot ({-1, -1, -1}: empty). Slot numbers stay valid until the next refit().
  const std::vector<std::array<int, 3>>& slots() const { return slots_; }
  // Live boundary faces in slot order (recomputed after a change, O(slots)).
  const std::vector<std::array<int, 3>>& tris();
  int live_faces() const { return live_; }
  // Slots of the faces that became boundary since the last call (new faces of the cut, faces
  // of the organ surface that changed), for callers that look only at what is new.
  std::vector<int> take_added_slots();

  // Refits the hierarchy to positions x (O(slots)); compacts and rebuilds it when the
  // overflow or the empty slots grew too large (slot numbers change then).
  void refit(const Eigen::Matrix3Xd& x_World_mm);
  // Calls visit(slot) for every live face whose box (at the last refit) overlaps `box`.
  void query(const Aabb& box, const std::function<void(int)>& visit) const;
  // Blade against the boundary (blade_contact); triangle is a slot. Needs refit(x) first.
  Contact contact(const Eigen::Matrix3Xd& x_World_mm, const BladeSegment& blade) const;
  int rebuilds() const { return rebuilds_; }

 private:
  struct Entry {
    int count = 0;
    std::array<int, 2> owners{{-1, -1}};
    std::array<std::array<int, 3>, 2> oriented{};
    int slot = -1;
  };
  static std::uint64_t key(std::array<int, 3> f);
  void add_face(const std::array<int, 3>& oriented, int tet);
  void remove_face(const std::array<int, 3>& oriented, int tet);
  int new_slot(const std::array<int, 3>& face);
  void clear_slot(int slot);
  void rebuild(const Eigen::Matrix3Xd& x);

  std::vector<std::array<int, 4>> tets_;  // the tets as last seen
  std::unordered_map<std::uint64_t, Entry> faces_;
  std::vector<std::array<int, 3>> slots_;
  std::vector<int> added_;
  std::vector<std::array<int, 3>> tris_;
  bool tris_dirty_ = true;
  int live_ = 0;
  int built_ = 0;  // slots covered by the hierarchy
  std::vector<Aabb> boxes_;
  Bvh bvh_;
  int rebuilds_ = 0;
};

}  // namespace arnav::host::cut
