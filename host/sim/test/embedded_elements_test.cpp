// Embedded treatment of tets below the quality bound (host/sim/embedded_elements.hpp,
// docs/cut.md "Element quality"): a flat sliver next to good tets, a piece made only of a
// sliver, for every model variant.
#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <vector>
#include <cmath>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/embedded_elements.hpp"
#include "host/sim/model_factory.hpp"
#include "host/sim/tet_geometry.hpp"

namespace arnav::host {
namespace {

constexpr double kBound_deg = 5.0;

// A 40 x 20 x 20 mm bar clamped at x = 0 with a flat tet (a cap: its apex `height_mm` above
// a boundary triangle of the free end) glued on its face x = 40. Returns the apex vertex.
int add_cap_sliver(SimProblem& p, double height_mm) {
  const auto faces = boundary_faces(p.mesh);
  const Eigen::Matrix3Xd& X = p.mesh.rest_positions_World_mm;
  for (const auto& f : faces) {
    if (std::abs(X(0, f[0]) - 40) > 1e-9 || std::abs(X(0, f[1]) - 40) > 1e-9 || std::abs(X(0, f[2]) - 40) > 1e-9) continue;
    const Eigen::Vector3d a = X.col(f[0]), b = X.col(f[1]), c = X.col(f[2]);
    const Eigen::Vector3d n = (b - a).cross(c - a).normalized();
    const Eigen::Vector3d apex = (a + b + c) / 3.0 + height_mm * n;
    const int v = p.mesh.num_vertices();
    p.mesh.rest_positions_World_mm.conservativeResize(Eigen::NoChange, v + 1);
    p.mesh.rest_positions_World_mm.col(v) = apex;
    p.mesh.tets.push_back({f[0], f[1], f[2], v});
    p.mesh.tet_region.push_back(0);
    return v;
  }
  return -1;
}

SimProblem bar_problem() {
  SimProblem p;
  p.mesh = make_box_tet_mesh(4, 2, 2, {40, 20, 20});
  p.mesh.tet_region.assign(p.mesh.tets.size(), 0);
  p.region_materials = {Material{.youngs_modulus_kPa = 5.0, .poisson_ratio = 0.45, .damping_mass_per_s = 2.0}};
  for (int v = 0; v < p.mesh.num_vertices(); ++v)
    if (p.mesh.rest_positions_World_mm(0, v) < 1e-9) p.fixed_vertices.push_back(v);
  return p;
}

ModelConfig stepping_config(const ModelVariant& variant) {
  ModelConfig c = variant.config;
  if (c.kind == "mass_spring" && c.integrator == "explicit") c.substeps = std::max(c.substeps, 200);
  return c;
}

TEST(EmbeddedElements, DihedralAngleOfRegularAndFlatTets) {
  const double regular = tet_min_dihedral_deg(Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, -1, -1), Eigen::Vector3d(-1, 1, -1),
                                              Eigen::Vector3d(-1, -1, 1));
  EXPECT_NEAR(regular, std::acos(1.0 / 3.0) * 180.0 / M_PI, 1e-9);
  // Cap: apex h above the centroid of a right triangle with legs 10: the smallest angle is
  // at the edges farthest from the centroid (the legs, 10/3 away), atan(h / (10 / 3)).
  const double h = 1e-3;
  const double cap = tet_min_dihedral_deg(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(10, 0, 0), Eigen::Vector3d(0, 10, 0),
                                          Eigen::Vector3d(10.0 / 3, 10.0 / 3, h));
  EXPECT_NEAR(cap, std::atan(h / (10.0 / 3.0)) * 180.0 / M_PI, 1e-9);
  EXPECT_EQ(tet_min_dihedral_deg(Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0), Eigen::Vector3d(1, 1, 0)), 0.0);
  EXPECT_THROW(EmbeddedElementTracker(-1.0), std::invalid_argument);
  EXPECT_THROW(EmbeddedElementTracker(71.0), std::invalid_argument);
}

TEST(EmbeddedElements, TrackerFindsTheSliverAndItsDriverAndUpdatesLikeABuild) {
  SimProblem p = bar_problem();
  const int nt0 = p.mesh.num_tets();
  EmbeddedElementTracker incremental(kBound_deg);
  EmbeddedElements inc;
  incremental.build(p.mesh, p.fixed_vertices, inc);
  EXPECT_EQ(inc.passive_count(), 0);  // the Kuhn box: 45 degrees at least
  EXPECT_TRUE(inc.driven.empty());
  const int apex = add_cap_sliver(p, 4e-4);
  ASSERT_GE(apex, 0);
  const int sliver = p.mesh.num_tets() - 1;
  EXPECT_LT(tet_min_dihedral_deg(p.mesh.rest_positions_World_mm, p.mesh.tets.back()), 0.02);  // ~0.01 degrees
  incremental.update(p.mesh, {sliver}, p.fixed_vertices, inc);
  EmbeddedElementTracker fresh(kBound_deg);
  EmbeddedElements built;
  fresh.build(p.mesh, p.fixed_vertices, built);
  for (const EmbeddedElements* e : {&inc, &built}) {
    ASSERT_EQ(e->passive.size(), static_cast<std::size_t>(nt0 + 1));
    EXPECT_EQ(e->passive_count(), 1);
    EXPECT_TRUE(e->is_passive(sliver));
    ASSERT_EQ(e->driven.size(), 1u);
    EXPECT_TRUE(e->rigid_groups.empty());
    const DrivenVertex& d = e->driven[0];
    EXPECT_EQ(d.vertex, apex);
    EXPECT_FALSE(e->is_passive(d.driver_tet));
    double sum = 0.0;
    Eigen::Vector3d at = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) {
      sum += d.weights[static_cast<std::size_t>(k)];
      at += d.weights[static_cast<std::size_t>(k)] * p.mesh.rest_positions_World_mm.col(d.drivers[static_cast<std::size_t>(k)]);
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_LT((at - p.mesh.rest_positions_World_mm.col(apex)).norm(), 1e-9);  // reproduces its rest position
  }
  EXPECT_EQ(inc.driven[0].driver_tet, built.driven[0].driver_tet);
  // Off: nothing passive.
  EmbeddedElementTracker off(0.0);
  EmbeddedElements none;
  off.build(p.mesh, p.fixed_vertices, none);
  EXPECT_FALSE(none.any());
}

// A cluster of well-shaped tets (3 x 3 x 3 cubes of 0.5 mm, 162 Kuhn tets, >= 35 degrees)
// sharing one vertex with the bar's free corner, next to the bar's 167 mm^3 tets: far below
// the mesh's resolution where it meets the bar (the ring cut on the bundled liver left such
// tets, 0.01-1 mm^3 next to 100-2,000 mm^3 ones, and the mass-spring runs stopped on them).
// More than kMaxIslandTets tets: not an island. Returns the tets at the shared vertex.
std::vector<int> add_tiny_cluster(SimProblem& p) {
  const Eigen::Vector3d c(40, 20, 20);
  int corner = -1;
  for (int v = 0; v < p.mesh.num_vertices(); ++v)
    if ((p.mesh.rest_positions_World_mm.col(v) - c).norm() < 1e-9) corner = v;
  if (corner < 0) return {};
  const TetMesh cluster = make_box_tet_mesh(3, 3, 3, {1.5, 1.5, 1.5});
  std::vector<int> index(static_cast<std::size_t>(cluster.num_vertices()));
  for (int v = 0; v < cluster.num_vertices(); ++v) {
    if (cluster.rest_positions_World_mm.col(v).norm() < 1e-12) {
      index[static_cast<std::size_t>(v)] = corner;
      continue;
    }
    const int w = p.mesh.num_vertices();
    p.mesh.rest_positions_World_mm.conservativeResize(Eigen::NoChange, w + 1);
    p.mesh.rest_positions_World_mm.col(w) = c + cluster.rest_positions_World_mm.col(v);
    index[static_cast<std::size_t>(v)] = w;
  }
  std::vector<int> at_corner;
  for (const auto& tet : cluster.tets) {
    std::array<int, 4> t;
    for (int k = 0; k < 4; ++k) t[static_cast<std::size_t>(k)] = index[static_cast<std::size_t>(tet[static_cast<std::size_t>(k)])];
    if (std::find(t.begin(), t.end(), corner) != t.end()) at_corner.push_back(p.mesh.num_tets());
    p.mesh.tets.push_back(t);
    p.mesh.tet_region.push_back(0);
  }
  return at_corner;
}

TEST(EmbeddedElements, TinyWellShapedTetsNextToLargeOnesArePassiveAndUpdateLikeABuild) {
  SimProblem p = bar_problem();
  const int nt0 = p.mesh.num_tets();
  EmbeddedElementTracker incremental(kBound_deg);
  EmbeddedElements inc;
  incremental.build(p.mesh, p.fixed_vertices, inc);
  const std::vector<int> at_corner = add_tiny_cluster(p);
  ASSERT_FALSE(at_corner.empty());
  std::vector<int> added;
  for (int t = nt0; t < p.mesh.num_tets(); ++t) {
    EXPECT_GT(tet_min_dihedral_deg(p.mesh.rest_positions_World_mm, p.mesh.tets[static_cast<std::size_t>(t)]), 30.0);  // well shaped
    added.push_back(t);
  }
  incremental.update(p.mesh, added, p.fixed_vertices, inc);
  EmbeddedElementTracker fresh(kBound_deg);
  EmbeddedElements built;
  fresh.build(p.mesh, p.fixed_vertices, built);
  for (const EmbeddedElements* e : {&inc, &built}) {
    // Exactly the cluster's tets at the shared vertex (0.02 mm^3 against 167: below 1e-3);
    // the rest of the cluster sees only its own size and stays elastic.
    EXPECT_EQ(e->passive_count(), static_cast<int>(at_corner.size()));
    for (int t : at_corner) EXPECT_TRUE(e->is_passive(t));
    EXPECT_TRUE(e->rigid_groups.empty());
    for (const DrivenVertex& d : e->driven) EXPECT_FALSE(e->is_passive(d.driver_tet));
  }
  EXPECT_EQ(inc.passive, built.passive);
  ASSERT_EQ(inc.driven.size(), built.driven.size());
  for (std::size_t k = 0; k < inc.driven.size(); ++k) EXPECT_EQ(inc.driven[k].driver_tet, built.driven[k].driver_tet);
  // Off (min_relative_volume 0): only the dihedral bound, nothing passive.
  EmbeddedElements shape_only;
  EmbeddedElementTracker(kBound_deg, 0.0).build(p.mesh, p.fixed_vertices, shape_only);
  EXPECT_EQ(shape_only.passive_count(), 0);
  EXPECT_THROW(EmbeddedElementTracker(kBound_deg, -1e-3), std::invalid_argument);
  EXPECT_THROW(EmbeddedElementTracker(kBound_deg, 1.0), std::invalid_argument);
}

// The size flag of a tet depends on the tets at its vertices: when they change, its flag
// changes without the tet itself being touched, and the update follows a build.
TEST(EmbeddedElements, SizeFlagOfAnUntouchedTetFollowsItsNeighbours) {
  SimProblem p = bar_problem();
  const int nt0 = p.mesh.num_tets(), nv0 = p.mesh.num_vertices();
  const Eigen::Vector3d c(40, 20, 20);
  // The bar shrunk to 1/100 about the corner: its tets (0.17e-3 mm^3) are no larger than
  // the cluster's (0.02 mm^3), nothing is tiny.
  for (int v = 0; v < nv0; ++v) p.mesh.rest_positions_World_mm.col(v) = c + 0.01 * (p.mesh.rest_positions_World_mm.col(v) - c);
  const std::vector<int> at_corner = add_tiny_cluster(p);
  ASSERT_FALSE(at_corner.empty());
  EmbeddedElementTracker incremental(kBound_deg);
  EmbeddedElements inc;
  incremental.build(p.mesh, p.fixed_vertices, inc);
  EXPECT_EQ(inc.passive_count(), 0);
  // A change that grows every bar tet back to full size (all of them "changed"); the
  // cluster's tets are untouched but now lie next to tets 8,000 times larger.
  std::vector<int> changed;
  for (int t = 0; t < nt0; ++t) changed.push_back(t);
  for (int v = 0; v < nv0; ++v) p.mesh.rest_positions_World_mm.col(v) = c + 100.0 * (p.mesh.rest_positions_World_mm.col(v) - c);
  incremental.update(p.mesh, changed, p.fixed_vertices, inc);
  EmbeddedElements built;
  EmbeddedElementTracker(kBound_deg).build(p.mesh, p.fixed_vertices, built);
  EXPECT_EQ(built.passive_count(), static_cast<int>(at_corner.size()));
  EXPECT_EQ(inc.passive, built.passive);
  ASSERT_EQ(inc.driven.size(), built.driven.size());
}

// The flat cap (0.01 degrees) glued to the free end of a sagging bar: every model runs
// healthy and the cap's apex follows its driver tet exactly.
TEST(EmbeddedElements, FlatSliverNextToGoodTetsRunsHealthyInEveryModel) {
  SimProblem p = bar_problem();
  const int apex = add_cap_sliver(p, 4e-4);
  ASSERT_GE(apex, 0);
  EmbeddedElementTracker tracker(kBound_deg);
  tracker.build(p.mesh, p.fixed_vertices, p.embedded);
  ASSERT_EQ(p.embedded.driven.size(), 1u);
  const DrivenVertex d = p.embedded.driven[0];
  for (const ModelVariant& variant : model_variants()) {
    SCOPED_TRACE(variant.label);
    auto model = make_tissue_model(p, stepping_config(variant));
    const double dt = 1.0 / 60.0;
    double worst = 0.0;
    for (int f = 0; f < 30; ++f) {
      const StepSummary s = model->step(dt);
      ASSERT_TRUE(s.healthy) << "frame " << f << ": " << s.warning;
      EXPECT_EQ(s.inverted_elements, 0) << "frame " << f;
      const Eigen::Matrix3Xd& x = model->positions_World_mm();
      ASSERT_TRUE(x.allFinite());
      Eigen::Vector3d driven = Eigen::Vector3d::Zero();
      for (int k = 0; k < 4; ++k) driven += d.weights[static_cast<std::size_t>(k)] * x.col(d.drivers[static_cast<std::size_t>(k)]);
      worst = std::max(worst, (x.col(apex) - driven).norm());
    }
    EXPECT_LT(worst, 1e-9);
    // The bar sags and the apex goes with it.
    const double sag = p.mesh.rest_positions_World_mm(2, apex) - model->positions_World_mm()(2, apex);
    EXPECT_GT(sag, 0.05) << "apex sag " << sag << " mm";
  }
}

// The apex's mass moves to its drivers (gravity stays right): a thick cap (40 degrees)
// made passive by a bound above it (42; the Kuhn box tets have 45 at least) loads the bar
// like the same cap kept elastic, and more than the bare bar.
TEST(EmbeddedElements, MassOfTheDrivenVertexStaysInTheModel) {
  SimProblem bare = bar_problem();
  SimProblem elastic = bar_problem();
  const int apex = add_cap_sliver(elastic, 2.0);
  ASSERT_GE(apex, 0);
  SimProblem embedded = elastic;
  EmbeddedElementTracker tracker(42.0);
  tracker.build(embedded.mesh, embedded.fixed_vertices, embedded.embedded);
  ASSERT_EQ(embedded.embedded.passive_count(), 1);
  ASSERT_EQ(embedded.embedded.driven.size(), 1u);
  const int tip = box_vertex_index(4, 2, 4, 1, 2);
  for (const ModelVariant& variant : model_variants()) {
    if (variant.label == "mass_spring/explicit") continue;  // the bound needs hundreds of substeps; the others cover it
    SCOPED_TRACE(variant.label);
    double sag[3];
    int k = 0;
    for (const SimProblem* p : {&bare, &elastic, &embedded}) {
      auto model = make_tissue_model(*p, stepping_config(variant));
      for (int f = 0; f < 60; ++f) ASSERT_TRUE(model->step(1.0 / 60).healthy);
      sag[k++] = p->mesh.rest_positions_World_mm(2, tip) - model->positions_World_mm()(2, tip);
    }
    EXPECT_GT(sag[1], sag[0]);
    EXPECT_GT(sag[2], sag[0]) << "the cap's mass must still load the bar";
    EXPECT_LT(std::abs(sag[2] - sag[1]), 0.3 * (sag[1] - sag[0])) << "bare " << sag[0] << ", elastic cap " << sag[1] << ", embedded cap " << sag[2];
  }
}

// A piece made only of a sliver (a tet cut off on its own, 0.006 degrees): it moves as one
// rigid body, keeping its shape, its momentum (falling freely) and its angular momentum.
TEST(EmbeddedElements, SliverOnlyPieceMovesRigidlyInEveryModel) {
  SimProblem p = bar_problem();
  const int n0 = p.mesh.num_vertices();
  p.mesh.rest_positions_World_mm.conservativeResize(Eigen::NoChange, n0 + 4);
  p.mesh.rest_positions_World_mm.col(n0 + 0) = Eigen::Vector3d(60, 0, 0);
  p.mesh.rest_positions_World_mm.col(n0 + 1) = Eigen::Vector3d(70, 0, 0);
  p.mesh.rest_positions_World_mm.col(n0 + 2) = Eigen::Vector3d(60, 10, 0);
  p.mesh.rest_positions_World_mm.col(n0 + 3) = Eigen::Vector3d(60 + 10.0 / 3, 10.0 / 3, 2.5e-4);
  p.mesh.tets.push_back({n0, n0 + 1, n0 + 2, n0 + 3});
  p.mesh.tet_region.push_back(0);
  ASSERT_LT(tet_min_dihedral_deg(p.mesh.rest_positions_World_mm, p.mesh.tets.back()), 0.01);
  EmbeddedElementTracker tracker(kBound_deg);
  tracker.build(p.mesh, p.fixed_vertices, p.embedded);
  ASSERT_EQ(p.embedded.rigid_groups.size(), 1u);
  EXPECT_EQ(p.embedded.rigid_groups[0].vertices, (std::vector<int>{n0, n0 + 1, n0 + 2, n0 + 3}));
  EXPECT_FALSE(p.embedded.rigid_groups[0].held);
  EXPECT_TRUE(p.embedded.driven.empty());
  const double dt = 1.0 / 60.0;
  const int frames = 30;
  for (const ModelVariant& variant : model_variants()) {
    SCOPED_TRACE(variant.label);
    auto model = make_tissue_model(p, stepping_config(variant));
    // Thrown and spinning: V0 = (0, 0, 100) mm/s, omega = (0, 2, 3) rad/s about the centroid.
    Eigen::Matrix3Xd x = p.mesh.rest_positions_World_mm, v = Eigen::Matrix3Xd::Zero(3, x.cols());
    Eigen::Vector3d c0 = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) c0 += x.col(n0 + k) / 4.0;  // equal lumped masses: the centroid
    const Eigen::Vector3d V0(0, 0, 100), omega(0, 2, 3);
    for (int k = 0; k < 4; ++k) v.col(n0 + k) = V0 + omega.cross(Eigen::Vector3d(x.col(n0 + k)) - c0);
    model->set_state(x, v);
    auto angular = [&](const Eigen::Matrix3Xd& xs, const Eigen::Matrix3Xd& vs) {
      Eigen::Vector3d c = Eigen::Vector3d::Zero(), V = Eigen::Vector3d::Zero(), L = Eigen::Vector3d::Zero();
      for (int k = 0; k < 4; ++k) {
        c += xs.col(n0 + k) / 4.0;
        V += vs.col(n0 + k) / 4.0;
      }
      for (int k = 0; k < 4; ++k) L += (Eigen::Vector3d(xs.col(n0 + k)) - c).cross(Eigen::Vector3d(vs.col(n0 + k)) - V);
      return L;
    };
    const Eigen::Vector3d L0 = angular(x, v);
    for (int f = 1; f <= frames; ++f) {
      const StepSummary s = model->step(dt);
      ASSERT_TRUE(s.healthy) << "frame " << f << ": " << s.warning;
    }
    const Eigen::Matrix3Xd& xe = model->positions_World_mm();
    const Eigen::Matrix3Xd& ve = model->velocities_World_mm_s();
    // Shape kept (every pairwise distance).
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        EXPECT_NEAR((xe.col(n0 + a) - xe.col(n0 + b)).norm(), (x.col(n0 + a) - x.col(n0 + b)).norm(), 1e-9);
    // Centre: free fall from V0 (semi-implicit Euler: c_n = c0 + n dt V0 + g dt^2 n (n + 1) / 2).
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int k = 0; k < 4; ++k) c += xe.col(n0 + k) / 4.0;
    const Eigen::Vector3d expected = c0 + frames * dt * V0 + p.gravity_World_mm_s2 * dt * dt * frames * (frames + 1) / 2.0;
    EXPECT_LT((c - expected).norm(), 1e-6);
    EXPECT_LT((angular(xe, ve) - L0).norm(), 1e-6 * L0.norm());
  }
  // Held: a fixed vertex in the piece keeps it where it is.
  p.fixed_vertices.push_back(n0);
  tracker.build(p.mesh, p.fixed_vertices, p.embedded);
  ASSERT_EQ(p.embedded.rigid_groups.size(), 1u);
  EXPECT_TRUE(p.embedded.rigid_groups[0].held);
  for (const ModelVariant& variant : model_variants()) {
    SCOPED_TRACE(variant.label);
    auto model = make_tissue_model(p, stepping_config(variant));
    for (int f = 0; f < 10; ++f) ASSERT_TRUE(model->step(dt).healthy);
    for (int k = 0; k < 4; ++k)
      EXPECT_LT((model->positions_World_mm().col(n0 + k) - p.mesh.rest_positions_World_mm.col(n0 + k)).norm(), 1e-12);
  }
}

}  // namespace
}  // namespace arnav::host
