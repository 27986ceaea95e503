// The ring cut on the bundled liver (issue 11, paper 000's lesion): the bundled ring path
// round the tumour and its bottom cut, applied to the coarse liver volume at rest by the
// cutter alone (no model): the geometry of the cut on a mesh it was not developed on.
// Checked: the cut mesh stays valid (closed, 2-manifold, oriented boundary, positive tets),
// the volume is conserved, the cut points lie on the swept surface within the tolerance.
// Known limit (docs/cut.md, "Not done yet"): the tumour's block is not yet freed on the
// liver (holes remain in the ring's cylinder); ARNAV_RING_DEBUG=1 prints where the cut
// surface is pierced. The freeing check runs with --gtest_also_run_disabled_tests.
#include <gtest/gtest.h>

#include <cstdlib>
#include <map>
#include <set>

#include "host/cut/mesh_checks.hpp"
#include "host/cut/scalpel_path.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/scene/scene.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {
void ring_on_the_liver(bool expect_freed) {
  const std::string data = std::getenv("ARNAV_DATA_DIR") ? std::getenv("ARNAV_DATA_DIR") : "data";
  const Scene scene = load_scene(data + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  ASSERT_FALSE(scene.tumours.empty());
  const ScalpelPath path = load_scalpel_csv(data + "/liver/scalpel_ring.csv");
  CutSettings settings;
  settings.snap_fraction = scene.cutting->snap_fraction;
  settings.path_tolerance_mm = scene.cutting->path_tolerance_mm;
  TetCutter cutter(scene.problem.mesh, settings);
  Eigen::Matrix3Xd x = scene.problem.mesh.rest_positions_World_mm, v;
  const double volume = check_cut_mesh(scene.problem.mesh).total_volume_mm3;
  // The path is written for the organ hanging under gravity; at rest the tissue sits up to
  // 14 mm higher: the blade is lifted by the sag of the tumour centre (docs in the CSV).
  const Eigen::Vector3d lift(0, 0, 0);
  const int frames = static_cast<int>(path.samples.back().t_s / scene.time_step_s) + 1;
  bool previous_cutting = false;
  BladeSegment previous;
  double deviation = 0.0;
  for (int f = 1; f <= frames; ++f) {
    const ScalpelSample s = path.at(f * scene.time_step_s);
    BladeSegment blade{s.blade.tip_World_mm + lift, s.blade.heel_World_mm + lift};
    if (s.cutting && !previous_cutting) cutter.begin_stroke();
    if (s.cutting && previous_cutting) deviation = std::max(deviation, cutter.step({previous, blade, 8, {}}, x, v).max_path_deviation_mm);
    if (!s.cutting && previous_cutting) {
      cutter.finish_stroke(x, v);
      if (std::getenv("ARNAV_RING_DEBUG")) std::cout << "stroke end: pending crossings " << cutter.pending_crossings() << "\n" << cutter.describe_pending().substr(0, 3000) << "\n";
    }
    previous = blade;
    previous_cutting = s.cutting;
  }
  if (previous_cutting) cutter.finish_stroke(x, v);
  const TetMesh& mesh = cutter.mesh();
  const CutMeshCheck c = check_cut_mesh(mesh);
  EXPECT_TRUE(c.valid()) << c.summary();
  EXPECT_NEAR(c.total_volume_mm3 / volume, 1.0, 1e-12);
  EXPECT_LE(deviation, settings.path_tolerance_mm + 1e-9);
  // The tumour's vertices, re-embedded by rest position in the pieces of their input tets.
  std::set<int> tumour_pieces;
  for (const auto& tumour : scene.tumours) {
    const Eigen::Matrix3Xd& p = tumour.rest.positions_World_mm;
    for (int i = 0; i < p.cols(); ++i) {
      Eigen::Vector4d w;
      const int t = cutter.locate(p.col(i), mesh.rest_positions_World_mm, w);
      ASSERT_GE(t, 0);
      tumour_pieces.insert(c.piece_of_tet[static_cast<std::size_t>(t)]);
    }
  }
  std::cout << "[liver ring] pieces " << c.piece_volume_mm3.size() << ", tumour in " << tumour_pieces.size() << " piece(s), tets " << mesh.num_tets()
            << ", path deviation " << deviation << " mm\n";
  if (std::getenv("ARNAV_RING_DEBUG")) {
    // Interior faces joining a tet inside the ring's cylinder above the bottom cut to one outside.
    auto inside = [&](int t) {
      Eigen::Vector3d m = Eigen::Vector3d::Zero();
      for (int w : mesh.tets[static_cast<std::size_t>(t)]) m += 0.25 * mesh.rest_positions_World_mm.col(w);
      return std::hypot(m.x() - 71, m.y() - 156) < 25 && m.z() > 106;
    };
    std::map<std::array<int, 3>, int> faces;
    for (int t = 0; t < mesh.num_tets(); ++t) {
      const auto& q = mesh.tets[static_cast<std::size_t>(t)];
      for (int k = 0; k < 4; ++k) {
        std::array<int, 3> f{q[static_cast<std::size_t>(k)], q[static_cast<std::size_t>((k + 1) % 4)], q[static_cast<std::size_t>((k + 2) % 4)]};
        std::sort(f.begin(), f.end());
        auto it = faces.find(f);
        if (it == faces.end()) { faces[f] = t; continue; }
        if (inside(it->second) != inside(t)) {
          Eigen::Vector3d m = Eigen::Vector3d::Zero();
          for (int w : f) m += mesh.rest_positions_World_mm.col(w) / 3.0;
          std::cout << "bridge face at " << m.transpose() << " r " << std::hypot(m.x() - 71, m.y() - 156) << "\n";
        }
      }
    }
  }
  ASSERT_EQ(tumour_pieces.size(), 1u) << c.summary();
  if (!expect_freed) return;
  const int piece = *tumour_pieces.begin();
  std::vector<char> fixed(static_cast<std::size_t>(mesh.num_vertices()), 0);
  for (int w : scene.problem.fixed_vertices) fixed[static_cast<std::size_t>(w)] = 1;
  bool holds_fixed = false;
  for (int t = 0; t < mesh.num_tets(); ++t)
    if (c.piece_of_tet[static_cast<std::size_t>(t)] == piece)
      for (int w : mesh.tets[static_cast<std::size_t>(t)]) holds_fixed = holds_fixed || (w < static_cast<int>(fixed.size()) && fixed[static_cast<std::size_t>(w)]);
  EXPECT_FALSE(holds_fixed) << "the tumour's piece is still held";
  // A block round the tumour, not the liver: well below the organ's volume.
  EXPECT_LT(c.piece_volume_mm3[static_cast<std::size_t>(piece)], 0.2 * volume);
  std::cout << "[liver ring] tumour block " << c.piece_volume_mm3[static_cast<std::size_t>(piece)] << " mm^3 of " << volume << " mm^3\n";
}
}  // namespace

TEST(LiverRing, RingAndBottomCutKeepTheInvariants) { ring_on_the_liver(false); }
TEST(LiverRing, DISABLED_RingAndBottomCutFreeTheTumourBlock) { ring_on_the_liver(true); }
