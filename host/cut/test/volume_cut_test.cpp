// The volumetric cut on structured bars (issue 11 verification): a cut through at x = 50
// (plane between vertices and through vertices/faces), a slit, a second cut across the
// first, tilted cuts, and random blade sweeps keeping every invariant.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <functional>
#include <random>

#include "host/cut/mesh_checks.hpp"
#include "host/cut/tet_cutter.hpp"
#include "host/mesh/box_mesh.hpp"
#include "host/mesh/mesh_quality.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {

// Moves the blade linearly from `a` to `b` in `frames` steps, cutting every frame.
void sweep(TetCutter& cutter, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, const BladeSegment& a, const BladeSegment& b, int frames) {
  BladeSegment prev = a;
  for (int f = 1; f <= frames; ++f) {
    const double s = static_cast<double>(f) / frames;
    BladeSegment cur{(1 - s) * a.tip_World_mm + s * b.tip_World_mm, (1 - s) * a.heel_World_mm + s * b.heel_World_mm};
    cutter.step({prev, cur, 1, {}}, x, v);
    prev = cur;
  }
}

BladeSegment vertical(double x, double y, double z_tip, double z_heel) {
  return {Eigen::Vector3d(x, y, z_tip), Eigen::Vector3d(x, y, z_heel)};
}

// Paper 000's lesion on the 80 mm cube: a vertical blade (z 20-120) goes round the circle of
// radius 20 mm about (40, 40) from angle 0 through `chords` of its 48 chords, cutting every
// frame (50: a little past the start, the ring closes). `to_current` maps the blade from the
// rest shape into the current one (identity: the tissue at rest). Returns the edges refined.
int sweep_ring(TetCutter& cutter, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, int chords,
               const std::function<Eigen::Vector3d(const Eigen::Vector3d&)>& to_current = nullptr) {
  const auto on_ring = [&](double a) {
    const BladeSegment b = vertical(40 + 20 * std::cos(a), 40 + 20 * std::sin(a), 20, 120);
    return to_current ? BladeSegment{to_current(b.tip_World_mm), to_current(b.heel_World_mm)} : b;
  };
  BladeSegment prev = on_ring(0);
  int refined = 0;
  for (int k = 1; k <= chords; ++k) {
    const BladeSegment cur = on_ring(2 * M_PI * k / 48);
    refined += cutter.step({prev, cur, 4, {}}, x, v).edges_refined;
    prev = cur;
  }
  return refined;
}

// Distance of p from the wall sweep_ring's blade sweeps (the 48-gon prism about (40, 40),
// radius 20 mm), in the xy plane.
double ring_wall_distance_mm(const Eigen::Vector3d& p) {
  const auto on_ring = [](int k) { return Eigen::Vector2d(40 + 20 * std::cos(2 * M_PI * k / 48), 40 + 20 * std::sin(2 * M_PI * k / 48)); };
  double best = 1e300;
  for (int k = 0; k < 48; ++k) {
    const Eigen::Vector2d a = on_ring(k), b = on_ring(k + 1);
    const double s = std::clamp((p.head<2>() - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
    best = std::min(best, (p.head<2>() - (a + s * (b - a))).norm());
  }
  return best;
}

void expect_two_halves_at_x50(const TetMesh& mesh) {
  const CutMeshCheck c = check_cut_mesh(mesh);
  EXPECT_TRUE(c.valid()) << c.summary();
  ASSERT_EQ(c.piece_volume_mm3.size(), 2u) << c.summary();
  for (double vol : c.piece_volume_mm3) EXPECT_NEAR(vol / 20000.0, 1.0, 1e-9);
  // No tet straddles the plane; each piece lies on one side.
  for (int t = 0; t < mesh.num_tets(); ++t) {
    double lo = 1e300, hi = -1e300;
    for (int w : mesh.tets[static_cast<std::size_t>(t)]) {
      lo = std::min(lo, mesh.rest_positions_World_mm(0, w));
      hi = std::max(hi, mesh.rest_positions_World_mm(0, w));
    }
    EXPECT_TRUE(hi <= 50.0 + 1e-9 || lo >= 50.0 - 1e-9) << "tet " << t << " spans x " << lo << ".." << hi;
  }
}

}  // namespace

class BarCut : public ::testing::TestWithParam<int> {};

// nx = 9, 7: the plane crosses cells (every tet around it is split); nx = 10, 4: the plane
// runs through a layer of vertices and faces (nothing is split, the faces are separated).
TEST_P(BarCut, CutThroughAtX50GivesTwoExactHalves) {
  const int nx = GetParam();
  TetMesh mesh = make_box_tet_mesh(nx, 4, 4, Eigen::Vector3d(100, 20, 20));
  TetCutter cutter(mesh, CutSettings{});
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v = Eigen::Matrix3Xd::Zero(3, x.cols());
  sweep(cutter, x, v, vertical(50, -5, -5, 25), vertical(50, 25, -5, 25), 45);  // 0.67 mm per frame
  EXPECT_EQ(x.cols(), cutter.mesh().num_vertices());
  EXPECT_EQ(v.cols(), cutter.mesh().num_vertices());
  expect_two_halves_at_x50(cutter.mesh());
  // Positions follow the rest positions (no deformation here).
  EXPECT_LT((x - cutter.mesh().rest_positions_World_mm).cwiseAbs().maxCoeff(), 1e-12);
}
INSTANTIATE_TEST_SUITE_P(Meshes, BarCut, ::testing::Values(9, 7, 10, 4));

TEST(BarCut, DeformedBarIsCutInItsCurrentShape) {
  // The bar is bent (z += 0.002 x^2) when the blade passes: the cut is at x = 50 in World
  // and the material it separates is the material there (still x = 50 at rest).
  TetMesh mesh = make_box_tet_mesh(9, 4, 4, Eigen::Vector3d(100, 20, 20));
  TetCutter cutter(mesh, CutSettings{});
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
  for (int i = 0; i < x.cols(); ++i) x(2, i) += 0.002 * x(0, i) * x(0, i);
  sweep(cutter, x, v, vertical(50, -5, -10, 40), vertical(50, 25, -10, 40), 30);
  expect_two_halves_at_x50(cutter.mesh());
  EXPECT_EQ(v.cols(), 0);
}

TEST(BarCut, BladeOutsideTheOrganCutsNothing) {
  TetMesh mesh = make_box_tet_mesh(9, 4, 4, Eigen::Vector3d(100, 20, 20));
  TetCutter cutter(mesh, CutSettings{});
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
  sweep(cutter, x, v, vertical(120, -5, -5, 25), vertical(120, 25, -5, 25), 10);
  sweep(cutter, x, v, vertical(50, -5, 30, 60), vertical(50, 25, 30, 60), 10);  // above it
  EXPECT_EQ(cutter.mesh().num_tets(), mesh.num_tets());
  EXPECT_EQ(cutter.mesh().num_vertices(), mesh.num_vertices());
}

TEST(BarCut, SlitStaysOnePieceWithClosedSurfaceAndNewCutFaces) {
  TetMesh mesh = make_box_tet_mesh(9, 4, 4, Eigen::Vector3d(100, 20, 20));
  TetCutter cutter(mesh, CutSettings{});
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
  // Blade 12 mm deep into the top (z = 20) only.
  sweep(cutter, x, v, vertical(50, -5, 8, 30), vertical(50, 25, 8, 30), 30);
  const CutMeshCheck c = check_cut_mesh(cutter.mesh());
  EXPECT_TRUE(c.valid()) << c.summary();
  EXPECT_EQ(c.piece_volume_mm3.size(), 1u);
  EXPECT_NEAR(c.total_volume_mm3 / 40000.0, 1.0, 1e-12);
  // The slit adds two faces' worth of area; the crack front lags by at most one cell (5 mm)
  // behind the blade tip: between 2 x 20 x 7 and 2 x 20 x 12 mm^2.
  cutter.update_surface();
  double area = 0;
  for (const auto& f : cutter.mesh().surface_tris) {
    const Eigen::Vector3d a = x.col(f[0]), b = x.col(f[1]), cc = x.col(f[2]);
    area += 0.5 * (b - a).cross(cc - a).norm();
  }
  const double box_area = 2 * (100 * 20 + 100 * 20 + 20 * 20);
  EXPECT_GT(area - box_area, 2 * 20 * 7 - 1e-6);
  EXPECT_LT(area - box_area, 2 * 20 * 12 + 1e-6);
  // Continuing deeper later (same stroke) cuts the rest through: two halves.
  sweep(cutter, x, v, vertical(50, 25, 8, 30), vertical(50, 25, -5, 30), 5);
  sweep(cutter, x, v, vertical(50, 25, -5, 30), vertical(50, -5, -5, 30), 30);
  expect_two_halves_at_x50(cutter.mesh());
}

TEST(BarCut, SecondCutAcrossTheFirstGivesFourQuarters) {
  TetMesh mesh = make_box_tet_mesh(9, 3, 3, Eigen::Vector3d(100, 20, 20));
  TetCutter cutter(mesh, CutSettings{});
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v = Eigen::Matrix3Xd::Zero(3, x.cols());
  sweep(cutter, x, v, vertical(50, -5, -5, 25), vertical(50, 25, -5, 25), 30);
  cutter.begin_stroke();
  sweep(cutter, x, v, vertical(-5, 10, -5, 25), vertical(105, 10, -5, 25), 110);
  const CutMeshCheck c = check_cut_mesh(cutter.mesh());
  EXPECT_TRUE(c.valid()) << c.summary();
  ASSERT_EQ(c.piece_volume_mm3.size(), 4u) << c.summary();
  for (double vol : c.piece_volume_mm3) EXPECT_NEAR(vol / 10000.0, 1.0, 1e-9);
}

TEST(BarCut, TiltedCutsConserveVolumeAndKeepQuality) {
  // Planes not aligned with the mesh: crossings near vertices snap (no sliver below the
  // snap fraction), volumes stay exact in total.
  for (double tilt : {0.1, 0.37, 1.0, 2.5}) {
    TetMesh mesh = make_box_tet_mesh(10, 4, 4, Eigen::Vector3d(100, 20, 20));
    TetCutter cutter(mesh, CutSettings{});
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    const BladeSegment a{Eigen::Vector3d(50 - 15 * tilt, -5, -5), Eigen::Vector3d(50 + 15 * tilt, -5, 25)};
    const BladeSegment b{Eigen::Vector3d(50 - 15 * tilt + 3, 25, -5), Eigen::Vector3d(50 + 15 * tilt + 3, 25, 25)};
    sweep(cutter, x, v, a, b, 40);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << "tilt " << tilt << ": " << c.summary();
    EXPECT_EQ(c.piece_volume_mm3.size(), 2u) << "tilt " << tilt << ": " << c.summary();
    EXPECT_NEAR(c.total_volume_mm3 / 40000.0, 1.0, 1e-12);
    EXPECT_GT(c.min_tet_volume_mm3, 0.0);
  }
}

TEST(CutFuzz, RandomBladeSweepsKeepEveryInvariant) {
  std::mt19937 rng(20261125);
  std::uniform_real_distribution<double> u(-10, 50);
  std::uniform_int_distribution<int> frames(1, 12);
  int sweeps = 0, cut_steps = 0;
  for (int mesh_round = 0; mesh_round < 100; ++mesh_round) {
    TetMesh mesh = make_box_tet_mesh(3 + mesh_round % 3, 3, 2 + mesh_round % 2, Eigen::Vector3d(40, 30, 20 + mesh_round % 7));
    const double volume = check_cut_mesh(mesh).total_volume_mm3;
    TetCutter cutter(mesh, CutSettings{.snap_fraction = 0.02 + 0.4 * (mesh_round % 5) / 5.0});
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v = Eigen::Matrix3Xd::Zero(3, x.cols());
    for (int s = 0; s < 10; ++s, ++sweeps) {
      if (s % 3 == 0) {
        if (s > 0) cutter.finish_stroke(x, v);  // completes what the blade left
        cutter.begin_stroke();
      }
      BladeSegment a{Eigen::Vector3d(u(rng), u(rng), u(rng)), Eigen::Vector3d(u(rng), u(rng), u(rng))};
      BladeSegment b{Eigen::Vector3d(u(rng), u(rng), u(rng)), Eigen::Vector3d(u(rng), u(rng), u(rng))};
      if (s % 4 == 1) {  // exactly through grid vertices and planes
        for (int i = 0; i < 3; ++i) {
          a.tip_World_mm[i] = std::round(a.tip_World_mm[i] / 10) * 10;
          a.heel_World_mm[i] = a.tip_World_mm[i] + (i == 2 ? 40 : 0);
          b.tip_World_mm[i] = i == 1 ? a.tip_World_mm[i] + 60 : a.tip_World_mm[i];
          b.heel_World_mm[i] = b.tip_World_mm[i] + (i == 2 ? 40 : 0);
        }
        a.tip_World_mm.y() -= 20;
        a.heel_World_mm.y() -= 20;
      }
      const int n = frames(rng);
      sweep(cutter, x, v, a, b, n);
      cut_steps += n;
      const CutMeshCheck c = check_cut_mesh(cutter.mesh());
      ASSERT_TRUE(c.valid()) << "mesh round " << mesh_round << " sweep " << s << ": " << c.summary();
      ASSERT_NEAR(c.total_volume_mm3 / volume, 1.0, 1e-12) << "mesh round " << mesh_round << " sweep " << s;
      ASSERT_EQ(x.cols(), cutter.mesh().num_vertices());
    }
  }
  EXPECT_EQ(sweeps, 1000);
  EXPECT_GT(cut_steps, 1000);
}

TEST(RingCut, RingAndBottomCutSeparateThePlug) {
  // Paper 000's lesion on a cube: a vertical blade goes round a 20 mm circle (48 chords of
  // 2.6 mm, against 10 mm cells), then a horizontal blade cuts under it at z = 25: the plug
  // (a 48-gon prism of height 55 mm) comes out; volume, surface and pieces stay valid.
  for (int cells : {8, 11}) {
    TetMesh mesh = make_box_tet_mesh(cells, cells, cells, Eigen::Vector3d(80, 80, 80));
    TetCutter cutter(mesh, CutSettings{});
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    sweep_ring(cutter, x, v, 50);
    cutter.finish_stroke(x, v);
    EXPECT_EQ(check_cut_mesh(cutter.mesh()).piece_volume_mm3.size(), 1u);  // the ring ends at z = 20, inside
    cutter.begin_stroke();
    sweep(cutter, x, v, {Eigen::Vector3d(10, -10, 25), Eigen::Vector3d(70, -10, 25)}, {Eigen::Vector3d(10, 80, 25), Eigen::Vector3d(70, 80, 25)}, 60);
    cutter.finish_stroke(x, v);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << c.summary();
    EXPECT_NEAR(c.total_volume_mm3 / 512000.0, 1.0, 1e-12);
    ASSERT_EQ(c.piece_volume_mm3.size(), 2u) << c.summary();
    const double prism = 0.5 * 48 * 400 * std::sin(2 * M_PI / 48) * 55;
    const double plug = std::min(c.piece_volume_mm3[0], c.piece_volume_mm3[1]);
    EXPECT_NEAR(plug / prism, 1.0, 0.05) << cells << " cells";
  }
}

// Path fidelity on a curved cut (issue 20): the ring above, on the cube at rest, with cells
// (10-15 mm edges against a 20 mm radius) much coarser than its curvature. An edge inside the
// cut whose ends stay joined is split at its mid-point, which lies off the wall by the
// chord's sagitta (0.62 / 0.68 mm here when it stayed there); it is moved onto the swept
// wall, on the cut's lips, as far as its tets allow. Every vertex on the cut is measured
// against the swept wall (the 48-gon prism, analytic) in the material: inside the cube none
// is farther than 0.15 mm (0.04 / 0.00 measured); on the cube's faces, where a vertex may
// not move off the surface, the sagitta would remain (none there on these meshes).
TEST(PathFidelity, CurvedCutMidPointsLieOnTheSweptWall) {
  for (int cells : {7, 8}) {
    TetMesh mesh = make_box_tet_mesh(cells, cells, cells, Eigen::Vector3d(80, 80, 80));
    TetCutter cutter(mesh, CutSettings{});
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    sweep_ring(cutter, x, v, 50);
    cutter.finish_stroke(x, v);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << c.summary();
    EXPECT_NEAR(c.total_volume_mm3 / 512000.0, 1.0, 1e-12);
    double inside_max = 0.0, face_max = 0.0;
    int inside = 0;
    const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
    for (int w = 0; w < rest.cols(); ++w) {
      if (!cutter.on_cut(w) || rest(2, w) < 20.0 + 1e-6) continue;  // below the blade's tip: the crack front
      const bool on_face = rest.col(w).minCoeff() < 1e-6 || rest.col(w).maxCoeff() > 80.0 - 1e-6;
      (on_face ? face_max : inside_max) = std::max(on_face ? face_max : inside_max, ring_wall_distance_mm(rest.col(w)));
      inside += on_face ? 0 : 1;
    }
    std::printf("[curved cut] %d cells: %d vertices on the cut inside the cube, max %.3f mm off the swept wall; on the cube's faces max %.3f mm\n",
                cells, inside, inside_max, face_max);
    EXPECT_GT(inside, 20);
    EXPECT_LE(inside_max, 0.15) << cells << " cells";
  }
}

// The rule for the cutter's vertex moves (issue 20): an upright tet keeps a quarter of its
// volume; a tet the load has inverted (a demo log: the grasper's pull on the mass-spring
// model inverted two tets round a chord's mid-point, which then stayed 3.06 mm off the cut)
// may take a move that leaves it less inverted (not flipped through flat), and no other.
TEST(VertexMoves, AnInvertedTetTakesMovesThatLeaveItNoMoreInverted) {
  EXPECT_TRUE(keeps_a_quarter_of_volume(8.0, 2.0));
  EXPECT_FALSE(keeps_a_quarter_of_volume(8.0, 1.99));
  EXPECT_FALSE(keeps_a_quarter_of_volume(8.0, -1.0));
  EXPECT_TRUE(keeps_a_quarter_of_volume(0.0, 0.0));
  EXPECT_FALSE(keeps_a_quarter_of_volume(0.0, -1e-12));
  EXPECT_TRUE(keeps_a_quarter_of_volume(-0.49, -0.48));  // less inverted
  EXPECT_TRUE(keeps_a_quarter_of_volume(-0.49, -0.49));
  EXPECT_TRUE(keeps_a_quarter_of_volume(-0.49, 0.0));
  EXPECT_FALSE(keeps_a_quarter_of_volume(-0.49, 3.0));    // flipped through flat: refused
  EXPECT_FALSE(keeps_a_quarter_of_volume(-0.49, -0.50));  // more inverted
}

// The same ring cut with the tissue turned inside out: the current shape is the rest shape
// mirrored (x -> 80 - x), every tet inverted now, and the blade goes round the mirrored
// ring. In the material the cut is the same wall. The cut mesh is valid with its exact
// volume, every vertex the cut made or moved sits where the mirror puts its rest position
// (copies placed by their own tets' maps), and the cut lies on the wall within the chords'
// sagitta (0.62 / 0.68 mm on these meshes: a move that would deepen an inverted tet is
// refused, so some mid-points stay on their chords).
TEST(PathFidelity, TissueTurnedInsideOutIsCutConsistently) {
  const auto mirrored = [](const Eigen::Vector3d& p) { return Eigen::Vector3d(80.0 - p.x(), p.y(), p.z()); };
  for (int cells : {7, 8}) {
    TetMesh mesh = make_box_tet_mesh(cells, cells, cells, Eigen::Vector3d(80, 80, 80));
    TetCutter cutter(mesh, CutSettings{});
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    for (int w = 0; w < x.cols(); ++w) x.col(w) = mirrored(x.col(w));
    sweep_ring(cutter, x, v, 50, mirrored);
    cutter.finish_stroke(x, v);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << c.summary();
    EXPECT_NEAR(c.total_volume_mm3 / 512000.0, 1.0, 1e-12);
    double inside_max = 0.0, mirror_max = 0.0;
    int inside = 0;
    const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
    for (int w = 0; w < rest.cols(); ++w) {
      mirror_max = std::max(mirror_max, (x.col(w) - mirrored(rest.col(w))).norm());
      if (!cutter.on_cut(w) || rest(2, w) < 20.0 + 1e-6 || rest.col(w).minCoeff() < 1e-6 || rest.col(w).maxCoeff() > 80.0 - 1e-6) continue;
      inside_max = std::max(inside_max, ring_wall_distance_mm(rest.col(w)));
      ++inside;
    }
    std::printf("[curved cut, tissue inside out] %d cells: %d vertices on the cut inside the cube, max %.3f mm off the swept wall; "
                "current places off the mirror by %.1e mm\n", cells, inside, inside_max, mirror_max);
    EXPECT_GT(inside, 20);
    EXPECT_LE(mirror_max, 1e-9);
    EXPECT_LE(inside_max, 0.7) << cells << " cells";
  }
}

// Refinement ahead of the blade (CutSettings::chord_sagitta_mm) on the same ring through
// coarse cells (20 mm, edges up to 35 mm against the ring's 20 mm radius): tets the blade is
// about to enter are bisected (longest edge first) until a chord across them lies within the
// sagitta of the ring. The mesh stays valid with its exact volume, no tet is flattened by
// the bisections (every tet keeps a bounded shape: Rivara's longest-edge bisection), and the
// cut's vertices lie closer to the swept wall than without refinement. A straight cut
// refines nothing.
TEST(Refinement, CurvedCutIsRefinedAheadOfTheBladeAndLandsOnTheWall) {
  const auto wall_distance = [&](const Eigen::Vector3d& p) { return std::abs((p.head<2>() - Eigen::Vector2d(40, 40)).norm() - 20.0); };
  const auto cut_ring = [&](double sagitta_mm, int& refined, double& worst_mm, double& min_volume_ratio, double& min_dihedral_deg) {
    TetMesh mesh = make_box_tet_mesh(4, 4, 4, Eigen::Vector3d(80, 80, 80));
    const double input_min_volume = 80.0 * 80 * 80 / (4 * 4 * 4) / 6.0;  // the box's tets: a sixth of a cell each
    CutSettings settings;
    settings.chord_sagitta_mm = sagitta_mm;
    TetCutter cutter(mesh, settings);
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    refined = sweep_ring(cutter, x, v, 50);
    cutter.finish_stroke(x, v);
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << c.summary();
    EXPECT_NEAR(c.total_volume_mm3 / 512000.0, 1.0, 1e-12);
    const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
    worst_mm = 0.0;
    for (int w = 0; w < rest.cols(); ++w)
      if (cutter.on_cut(w) && rest(2, w) > 20.0 + 1e-6 && rest.col(w).minCoeff() > 1e-6 && rest.col(w).maxCoeff() < 80.0 - 1e-6)
        worst_mm = std::max(worst_mm, wall_distance(rest.col(w)));
    // The tets no cut vertex touches: only the refinement made them.
    min_volume_ratio = 1.0;
    min_dihedral_deg = 180.0;
    for (const auto& tet : cutter.mesh().tets) {
      if (std::any_of(tet.begin(), tet.end(), [&](int w) { return cutter.on_cut(w); })) continue;
      min_dihedral_deg = std::min(min_dihedral_deg, tet_dihedral_range_deg(rest.col(tet[0]), rest.col(tet[1]), rest.col(tet[2]), rest.col(tet[3])).first);
      Eigen::Matrix3d D;
      for (int k = 0; k < 3; ++k) D.col(k) = rest.col(tet[static_cast<std::size_t>(k + 1)]) - rest.col(tet[0]);
      min_volume_ratio = std::min(min_volume_ratio, D.determinant() / 6.0 / input_min_volume);
    }
  };
  int refined_off = 0, refined_on = 0;
  double worst_off = 0, worst_on = 0, ratio_off = 0, ratio_on = 0, dihedral_off = 0, dihedral_on = 0;
  cut_ring(0.0, refined_off, worst_off, ratio_off, dihedral_off);
  cut_ring(0.5, refined_on, worst_on, ratio_on, dihedral_on);
  std::printf("[refinement] ring r 20 mm on 20 mm cells: off: worst %.3f mm; sagitta 0.5 mm: %d edges bisected, worst %.3f mm, "
              "smallest tet away from the cut %.4f of the input's, smallest dihedral %.1f deg (input %.1f)\n",
              worst_off, refined_on, worst_on, ratio_on, dihedral_on, dihedral_off);
  EXPECT_EQ(refined_off, 0);
  EXPECT_GT(refined_on, 20);
  EXPECT_LE(worst_on, 0.15) << "on the wall as the unrefined cut at rest (PathFidelity above)";
  EXPECT_GE(ratio_on, 1.0 / 64) << "bisections stop after six halvings of the 20 mm cells (min_refined_edge_mm 6)";
  EXPECT_GE(dihedral_on, 0.5 * dihedral_off) << "longest-edge bisection keeps the tets' shapes";

  // A straight cut through the same cells: nothing to refine.
  TetMesh bar = make_box_tet_mesh(4, 4, 4, Eigen::Vector3d(80, 80, 80));
  CutSettings settings;
  settings.chord_sagitta_mm = 0.5;
  TetCutter cutter(bar, settings);
  Eigen::Matrix3Xd x = bar.rest_positions_World_mm, v;
  int refined_straight = 0;
  BladeSegment prev = vertical(30, -5, 20, 120);
  for (int k = 1; k <= 40; ++k) {
    const BladeSegment cur = vertical(30, -5 + 90.0 * k / 40, 20, 120);
    refined_straight += cutter.step({prev, cur, 4, {}}, x, v).edges_refined;
    prev = cur;
  }
  EXPECT_EQ(refined_straight, 0);
}

// Path fidelity, analytic: a blade translated across the bar sweeps the plane
// x = x0 + tilt (z - 10). Every cut face (boundary face not lying on a side of the bar) must
// lie on that plane to 1e-9, the step reports must say so, and the pieces are 400 x0 and
// 400 (100 - x0) mm^3. Planes near vertices (x0 = 44.9 is 0.46 mm from the layer at 44.44:
// interior vertices move onto it, surface vertices make a split), between them, through
// them, tilted.
TEST(PathFidelity, PlanarSweepCutFacesLieOnThePlane) {
  struct Case {
    int nx;
    double x0, tilt, tolerance_mm;
  };
  for (const Case& k : {Case{9, 44.9, 0.0, 0.1}, Case{9, 50.0, 0.0, 0.1}, Case{10, 50.0, 0.0, 0.1}, Case{9, 45.3, 0.0, 0.1},
                        Case{10, 47.0, 0.13, 0.0}, Case{9, 52.5, 0.37, 0.0}, Case{7, 49.0, 1.0, 0.0}}) {
    TetMesh mesh = make_box_tet_mesh(k.nx, 4, 4, Eigen::Vector3d(100, 20, 20));
    CutSettings settings;
    settings.path_tolerance_mm = k.tolerance_mm;
    settings.vertex_tolerance_mm = 1e-10;
    TetCutter cutter(mesh, settings);
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    const auto blade_at = [&](double y) {
      return BladeSegment{Eigen::Vector3d(k.x0 - 15 * k.tilt, y, -5), Eigen::Vector3d(k.x0 + 15 * k.tilt, y, 25)};
    };
    double deviation = 0.0, completion = 0.0;
    BladeSegment prev = blade_at(-5);
    for (int f = 1; f <= 45; ++f) {
      const BladeSegment cur = blade_at(-5 + 30.0 * f / 45);
      const CutStepReport r = cutter.step({prev, cur, 2, {}}, x, v);
      deviation = std::max(deviation, r.max_path_deviation_mm);
      completion = std::max(completion, r.max_completion_deviation_mm);
      prev = cur;
    }
    const CutStepReport r = cutter.finish_stroke(x, v);
    completion = std::max(completion, r.max_completion_deviation_mm);
    const std::string what = "nx " + std::to_string(k.nx) + " x0 " + std::to_string(k.x0) + " tilt " + std::to_string(k.tilt);
    EXPECT_LE(deviation, 1e-9) << what;
    EXPECT_LE(completion, 1e-9) << what;
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << what << ": " << c.summary();
    ASSERT_EQ(c.piece_volume_mm3.size(), 2u) << what << ": " << c.summary();
    const double left = 400.0 * k.x0;
    EXPECT_NEAR(std::min(c.piece_volume_mm3[0], c.piece_volume_mm3[1]) / std::min(left, 40000.0 - left), 1.0, 1e-9) << what;
    cutter.update_surface();
    const Eigen::Matrix3Xd& p = cutter.mesh().rest_positions_World_mm;
    const Eigen::Vector3d normal = Eigen::Vector3d(1, 0, -k.tilt).normalized();
    const Eigen::Vector3d on_plane(k.x0, 0, 10);
    int cut_faces = 0;
    double worst = 0.0;
    for (const auto& f : cutter.mesh().surface_tris) {
      bool on_side = false;
      for (int axis = 0; axis < 3; ++axis)
        for (double side : {0.0, axis == 0 ? 100.0 : 20.0}) {
          bool all = true;
          for (int w : f) all = all && std::abs(p(axis, w) - side) < 1e-9;
          on_side = on_side || all;
        }
      if (on_side) continue;
      ++cut_faces;
      for (int w : f) worst = std::max(worst, std::abs(normal.dot(p.col(w) - on_plane)));
    }
    EXPECT_GT(cut_faces, 2 * 4 * 4) << what;  // both lips, at least two triangles per cell
    EXPECT_LE(worst, 1e-9) << what;
  }
}

// With a tolerance, a vertex that cannot move onto the cut (on the surface) snaps only when
// it lies within the tolerance: the reported deviation never exceeds it.
TEST(PathFidelity, SnappedSurfaceVerticesStayWithinTheTolerance) {
  for (double x0 : {44.47, 44.5, 44.6, 55.4}) {
    TetMesh mesh = make_box_tet_mesh(9, 4, 4, Eigen::Vector3d(100, 20, 20));
    CutSettings settings;  // path_tolerance_mm 0.1
    TetCutter cutter(mesh, settings);
    Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
    double deviation = 0.0;
    BladeSegment prev = vertical(x0, -5, -5, 25);
    for (int f = 1; f <= 30; ++f) {
      const BladeSegment cur = vertical(x0, -5 + f, -5, 25);
      deviation = std::max(deviation, cutter.step({prev, cur, 1, {}}, x, v).max_path_deviation_mm);
      prev = cur;
    }
    EXPECT_LE(deviation, settings.path_tolerance_mm + 1e-12) << x0;
    const CutMeshCheck c = check_cut_mesh(cutter.mesh());
    EXPECT_TRUE(c.valid()) << c.summary();
    EXPECT_EQ(c.piece_volume_mm3.size(), 2u) << x0;
    EXPECT_NEAR(c.total_volume_mm3 / 40000.0, 1.0, 1e-12);
  }
}

TEST(CutSettingsCheck, EverySettingOutOfRangeIsRefusedWithItsValue) {
  const TetMesh mesh = make_box_tet_mesh(2, 2, 2, Eigen::Vector3d(20, 20, 20));
  const auto message = [&](const CutSettings& s) -> std::string {
    try {
      TetCutter cutter(mesh, s);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "accepted";
  };
  EXPECT_EQ(message(CutSettings{}), "accepted");
  EXPECT_NE(message(CutSettings{.snap_fraction = 0.7}).find("snap_fraction must lie in (0, 0.5), got 0.7"), std::string::npos);
  EXPECT_NE(message(CutSettings{.path_tolerance_mm = -1.0}).find("path_tolerance_mm must be finite and >= 0, got -1"), std::string::npos);
  EXPECT_NE(message(CutSettings{.path_tolerance_mm = std::nan("")}).find("path_tolerance_mm must be finite"), std::string::npos);
  EXPECT_NE(message(CutSettings{.vertex_tolerance_mm = std::numeric_limits<double>::infinity()}).find("vertex_tolerance_mm must be finite and >= 0"), std::string::npos);
  EXPECT_NE(message(CutSettings{.chord_sagitta_mm = -0.5}).find("chord_sagitta_mm must be finite and >= 0, got -0.5"), std::string::npos);
  EXPECT_NE(message(CutSettings{.min_refined_edge_mm = 0.0}).find("min_refined_edge_mm must be finite and > 0"), std::string::npos);
}

// The cut's area against the swept wall (issue 20: the demo's refined cut has 50-65 % more
// area than the unrefined one; which one is right?). Three quarters of the ring above, at
// rest, through cubes of 2-4 cells: the lips' area (boundary faces with every vertex on the
// cut, halved: two lips) against the 36-gon wall's 5651 mm^2. Unrefined, a coarse tet the ring
// crosses twice cannot carry the curved wall, and the cut leaves part of it uncut or cuts
// across: 6426 / 3213 / 5398 mm^2 (+14 / -43 / -4 %). Refined ahead of the blade (s = 3 and
// 1.5 mm) it stays within 15 % (-14 to +1 %).
TEST(Refinement, TheCutsAreaIsTheSweptWallsAsItCurves) {
  const double wall_mm2 = 36 * 2 * 20 * std::sin(M_PI / 48) * 60;  // 36 of 48 sides, z 20-80 inside the cube
  for (double sagitta_mm : {0.0, 3.0, 1.5}) {
    for (int cells : {2, 3, 4}) {
      TetMesh mesh = make_box_tet_mesh(cells, cells, cells, Eigen::Vector3d(80, 80, 80));
      CutSettings settings;
      settings.chord_sagitta_mm = sagitta_mm;
      TetCutter cutter(mesh, settings);
      Eigen::Matrix3Xd x = mesh.rest_positions_World_mm, v;
      sweep_ring(cutter, x, v, 36);
      cutter.finish_stroke(x, v);
      const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
      double lips_mm2 = 0.0;
      for (const auto& f : boundary_faces(cutter.mesh()))
        if (cutter.on_cut(f[0]) && cutter.on_cut(f[1]) && cutter.on_cut(f[2]))
          lips_mm2 += 0.5 * (rest.col(f[1]) - rest.col(f[0])).cross(rest.col(f[2]) - rest.col(f[0])).norm();
      const double area_mm2 = 0.5 * lips_mm2;
      std::printf("[cut area] sagitta %.1f mm, %d cells: %d tets, cut area %.0f mm^2 against the wall's %.0f (%+.1f %%)\n", sagitta_mm, cells,
                  cutter.mesh().num_tets(), area_mm2, wall_mm2, 100.0 * (area_mm2 / wall_mm2 - 1.0));
      if (sagitta_mm > 0.0) {
        EXPECT_NEAR(area_mm2 / wall_mm2, 1.0, 0.15) << "sagitta " << sagitta_mm << " mm, " << cells << " cells";
      }
    }
  }
}
