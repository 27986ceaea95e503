// The incrementally kept boundary (SurfaceTracker) against the boundary recomputed from the
// whole mesh (boundary_faces) after every cut step of random blade sweeps, and its contact
// query against the one over a freshly built hierarchy.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "host/cut/surface_tracker.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/mesh/box_mesh.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {

// Oriented face with its smallest vertex first (the same face and orientation compare equal).
std::array<int, 3> canonical(std::array<int, 3> f) {
  while (f[0] > f[1] || f[0] > f[2]) f = {f[1], f[2], f[0]};
  return f;
}

std::vector<std::array<int, 3>> canonical_sorted(const std::vector<std::array<int, 3>>& faces) {
  std::vector<std::array<int, 3>> out;
  for (const auto& f : faces) out.push_back(canonical(f));
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

TEST(SurfaceTracker, MatchesTheRecomputedBoundaryThroughRandomCuts) {
  TetMesh mesh = make_box_tet_mesh(8, 3, 3, Eigen::Vector3d(80, 24, 24));
  TetCutter cutter(mesh, CutSettings{});
  SurfaceTracker tracker(mesh);
  ASSERT_EQ(canonical_sorted(tracker.tris()), canonical_sorted(boundary_faces(mesh)));
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-8, 32), along(-5, 85);
  int steps_changed = 0, contacts = 0, added = 0;
  for (int stroke = 0; stroke < 12; ++stroke) {
    cutter.begin_stroke();
    const double x0 = along(rng), x1 = along(rng);
    BladeSegment prev{Eigen::Vector3d(x0, u(rng), -6), Eigen::Vector3d(x0 + u(rng) / 4, u(rng), 30)};
    const BladeSegment end{Eigen::Vector3d(x1, u(rng), -6), Eigen::Vector3d(x1 + u(rng) / 4, u(rng), 30)};
    for (int f = 1; f <= 6; ++f) {
      const double s = f / 6.0;
      const BladeSegment cur{(1 - s) * prev.tip_World_mm + s * end.tip_World_mm, (1 - s) * prev.heel_World_mm + s * end.heel_World_mm};
      const CutStepReport r = cutter.step({prev, cur, 2, {}}, x, v);
      prev = cur;
      if (!r.topology_changed) continue;
      ++steps_changed;
      tracker.update(cutter.mesh(), r.changed_tets);
      added += static_cast<int>(tracker.take_added_slots().size());
      ASSERT_EQ(canonical_sorted(tracker.tris()), canonical_sorted(boundary_faces(cutter.mesh()))) << "stroke " << stroke << " frame " << f;
      ASSERT_EQ(tracker.live_faces(), static_cast<int>(tracker.tris().size()));
      // Contact: the tracker's (updated hierarchy + overflow) against a fresh hierarchy.
      tracker.refit(x);
      const auto faces = tracker.tris();
      Bvh fresh;
      fresh.build(triangle_boxes(faces, x));
      const BladeSegment probe{Eigen::Vector3d(along(rng), u(rng), u(rng)), Eigen::Vector3d(along(rng), u(rng), u(rng))};
      const Contact a = tracker.contact(x, probe), b = blade_contact(fresh, faces, x, probe);
      ASSERT_EQ(a.touching, b.touching);
      ASSERT_EQ(a.tip_inside, b.tip_inside);
      if (a.touching) {
        ++contacts;
        EXPECT_LT((a.point_World_mm - b.point_World_mm).norm(), 1e-9);
        EXPECT_NEAR(a.depth_mm, b.depth_mm, 1e-9);
        EXPECT_EQ(canonical(tracker.slots()[static_cast<std::size_t>(a.triangle)]), canonical(faces[static_cast<std::size_t>(b.triangle)]));
      }
    }
  }
  EXPECT_GT(steps_changed, 20);
  EXPECT_GT(contacts, 10);
  EXPECT_GT(added, 0);
  EXPECT_GT(tracker.rebuilds(), 1);  // the overflow grew past its bound and the tree was rebuilt
  std::cout << "[surface tracker] " << steps_changed << " cut steps, " << tracker.live_faces() << " boundary faces, " << added
            << " faces added, " << tracker.rebuilds() << " hierarchy builds\n";
}
