// Tumour surfaces and vessel centerlines split along the cut (issue 11 item 3,
// host/cut/structure_split.hpp): a sphere tumour in a bar cut by a plane gives two closed,
// consistently oriented halves whose volumes are the sphere polyhedron clipped by the plane
// (and the analytic spherical caps to the discretisation); a vessel line crossed becomes two
// segments whose ends separate when the cut opens under gravity; the bundled liver's tumour
// cut through.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>

#include "host/cut/cut_session.hpp"
#include "host/cut/mesh_checks.hpp"
#include "host/cut/structure_split.hpp"
#include "host/mesh/box_mesh.hpp"
#include "host/sim/test/box_problem.hpp"
#include "host/scene/scene.hpp"
#include "host/mesh/surface_shapes.hpp"
#include "host/sim/model_factory.hpp"

using namespace arnav::host;
using namespace arnav::host::cut;

namespace {

ModelConfig variant(const std::string& label) {
  for (const auto& v : model_variants())
    if (v.label == label) return v.config;
  throw std::runtime_error("no model variant " + label);
}

SimProblem bar_problem(const Eigen::Vector3d& size, int nx, int ny, int nz) {
  return test::box_problem(nx, ny, nz, size, test::soft_tissue(10.0));
}

// A 20 x 20 x 100 mm column hanging from its top face, a tumour sphere (r 6 mm) on its axis at
// height z_tumour_mm and a vessel line of 9 nodes along it, both embedded at rest.
struct HangingColumn {
  SimProblem problem;
  TriMesh sphere;
  CarriedPoints tumour;
  CarriedPoints vessel;
  std::vector<std::array<int, 2>> segments;
  // An XPBD cut session on the column carrying both.
  CutSession session(const CutSessionSettings& settings) const {
    return CutSession(problem, variant("xpbd"), settings, {tumour}, {sphere.tris}, vessel, segments);
  }
};

HangingColumn hanging_column(double z_tumour_mm) {
  HangingColumn c;
  c.problem = bar_problem(Eigen::Vector3d(20, 20, 100), 3, 3, 9);
  for (int v = 0; v < c.problem.mesh.num_vertices(); ++v)
    if (c.problem.mesh.rest_positions_World_mm(2, v) > 100 - 1e-9) c.problem.fixed_vertices.push_back(v);
  c.sphere = make_ellipsoid_surface(Eigen::Vector3d(10, 10, z_tumour_mm), Eigen::Vector3d::Constant(6.0), 2);
  c.tumour = {"tumour", c.sphere.positions_World_mm, embed_points(c.problem.mesh, c.sphere.positions_World_mm, 0.0, "tumour")};
  c.vessel = {"vessel", Eigen::Matrix3Xd(3, 9), {}};
  for (int i = 0; i < 9; ++i) {
    c.vessel.rest_World_mm.col(i) = Eigen::Vector3d(12.3, 8.1, 10.0 + 10.0 * i);
    if (i > 0) c.segments.push_back({i - 1, i});
  }
  c.vessel.embedding = embed_points(c.problem.mesh, c.vessel.rest_World_mm, 0.0, "vessel");
  return c;
}

struct SurfaceCheck {
  int open_edges = 0, misoriented_edges = 0, nonmanifold_edges = 0;
  std::vector<int> component;  // per triangle
  int components = 0;
  bool closed_manifold() const { return open_edges == 0 && misoriented_edges == 0 && nonmanifold_edges == 0; }
};

// Every directed edge once and its opposite once: closed, 2-manifold, consistently oriented.
SurfaceCheck check_surface(const std::vector<std::array<int, 3>>& tris) {
  SurfaceCheck c;
  std::map<std::pair<int, int>, std::vector<int>> directed;
  for (std::size_t t = 0; t < tris.size(); ++t)
    for (int k = 0; k < 3; ++k) directed[{tris[t][static_cast<std::size_t>(k)], tris[t][static_cast<std::size_t>((k + 1) % 3)]}].push_back(static_cast<int>(t));
  std::vector<int> parent(tris.size());
  for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
  std::function<int(int)> find = [&](int i) { return parent[static_cast<std::size_t>(i)] == i ? i : parent[static_cast<std::size_t>(i)] = find(parent[static_cast<std::size_t>(i)]); };
  for (const auto& [e, ts] : directed) {
    if (ts.size() > 1) ++c.misoriented_edges;
    const auto opp = directed.find({e.second, e.first});
    if (opp == directed.end()) {
      ++c.open_edges;
      continue;
    }
    if (opp->second.size() > 1) ++c.nonmanifold_edges;
    for (int a : ts)
      for (int b : opp->second) parent[static_cast<std::size_t>(find(a))] = find(b);
  }
  std::map<int, int> ids;
  for (std::size_t t = 0; t < tris.size(); ++t) {
    const auto [it, fresh] = ids.emplace(find(static_cast<int>(t)), static_cast<int>(ids.size()));
    c.component.push_back(it->second);
  }
  c.components = static_cast<int>(ids.size());
  return c;
}

double signed_volume(const Eigen::Matrix3Xd& p, const std::vector<std::array<int, 3>>& tris, const std::vector<int>& component, int which) {
  double v = 0;
  for (std::size_t t = 0; t < tris.size(); ++t)
    if (which < 0 || component[t] == which)
      v += p.col(tris[t][0]).dot(Eigen::Vector3d(p.col(tris[t][1])).cross(Eigen::Vector3d(p.col(tris[t][2])))) / 6.0;
  return v;
}

// Volume of the closed surface clipped to x < c (side -1) or x > c (side +1): each
// triangle clipped to the half space, the divergence theorem about a point on the plane
// (the plane's cap then adds nothing).
double clipped_volume(const TriMesh& s, double c, int side) {
  const Eigen::Vector3d o(c, 0, 0);
  double v = 0;
  for (const auto& t : s.tris) {
    std::vector<Eigen::Vector3d> poly;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d a = s.positions_World_mm.col(t[static_cast<std::size_t>(k)]), b = s.positions_World_mm.col(t[static_cast<std::size_t>((k + 1) % 3)]);
      const double da = side * (a.x() - c), db = side * (b.x() - c);
      if (da >= 0) poly.push_back(a);
      if ((da >= 0) != (db >= 0)) poly.push_back(a + da / (da - db) * (b - a));
    }
    for (std::size_t i = 1; i + 1 < poly.size(); ++i) v += (poly[0] - o).dot((poly[i] - o).cross(poly[i + 1] - o)) / 6.0;
  }
  return v;
}

double cap_volume(double r, double h) { return M_PI * h * h * (3 * r - h) / 3.0; }

// Pieces (face-connected components of the cut mesh) holding a structure's points, per component of the structure.
std::vector<std::set<int>> pieces_per_component(const CutMeshCheck& mc, const Embedding& e, const std::vector<std::array<int, 3>>& tris,
                                                const SurfaceCheck& sc) {
  std::vector<std::set<int>> out(static_cast<std::size_t>(sc.components));
  for (std::size_t t = 0; t < tris.size(); ++t)
    for (int v : tris[t]) out[static_cast<std::size_t>(sc.component[t])].insert(mc.piece_of_tet[static_cast<std::size_t>(e.tet[static_cast<std::size_t>(v)])]);
  return out;
}


// Pairs of triangles of a surface (rest points p) that intersect other than where they meet:
// an edge of one crossing the other, for triangles with no point in common (points at the
// same place count as one: the two copies of a crossing, the two sides of a closed slit).
int self_intersections(const Eigen::Matrix3Xd& p, const std::vector<std::array<int, 3>>& tris) {
  std::vector<int> id(static_cast<std::size_t>(p.cols()));
  std::map<std::array<long long, 3>, int> where;
  for (int i = 0; i < p.cols(); ++i) {
    const std::array<long long, 3> k{std::llround(p(0, i) * 1e6), std::llround(p(1, i) * 1e6), std::llround(p(2, i) * 1e6)};
    id[static_cast<std::size_t>(i)] = where.emplace(k, static_cast<int>(where.size())).first->second;
  }
  int hits = 0;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const Triangle ti{p.col(tris[i][0]), p.col(tris[i][1]), p.col(tris[i][2])};
    const Eigen::Vector3d lo_i = ti.a.cwiseMin(ti.b).cwiseMin(ti.c), hi_i = ti.a.cwiseMax(ti.b).cwiseMax(ti.c);
    for (std::size_t j = i + 1; j < tris.size(); ++j) {
      bool shared = false;
      for (int a : tris[i])
        for (int b : tris[j]) shared |= id[static_cast<std::size_t>(a)] == id[static_cast<std::size_t>(b)];
      if (shared) continue;
      const Triangle tj{p.col(tris[j][0]), p.col(tris[j][1]), p.col(tris[j][2])};
      const Eigen::Vector3d lo_j = tj.a.cwiseMin(tj.b).cwiseMin(tj.c), hi_j = tj.a.cwiseMax(tj.b).cwiseMax(tj.c);
      if ((hi_i.array() < lo_j.array()).any() || (hi_j.array() < lo_i.array()).any()) continue;
      bool hit = false;
      double s = 0;
      for (const auto& [x, y] : {std::pair{ti.a, ti.b}, std::pair{ti.b, ti.c}, std::pair{ti.c, ti.a}}) hit |= segment_triangle_intersection(x, y, tj, s);
      for (const auto& [x, y] : {std::pair{tj.a, tj.b}, std::pair{tj.b, tj.c}, std::pair{tj.c, tj.a}}) hit |= segment_triangle_intersection(x, y, ti, s);
      hits += hit ? 1 : 0;
    }
  }
  return hits;
}
}  // namespace

// A sphere (r 7 mm, 1,280 triangles) in a 100 x 20 x 20 mm bar, no load, cut through by a
// vertical blade swept across the bar at x = 52.3 (between vertex layers, off the centre).
TEST(StructureSplit, SphereTumourCutByAPlaneGivesTwoClosedHalves) {
  SimProblem problem = bar_problem(Eigen::Vector3d(100, 20, 20), 10, 4, 4);
  problem.gravity_World_mm_s2.setZero();
  for (int v = 0; v < problem.mesh.num_vertices(); ++v)
    if (problem.mesh.rest_positions_World_mm(0, v) < 1e-9) problem.fixed_vertices.push_back(v);
  const double r = 7.0, c = 52.3;
  const TriMesh sphere = make_ellipsoid_surface(Eigen::Vector3d(50, 10, 10), Eigen::Vector3d::Constant(r), 3);
  CarriedPoints tumour{"tumour", sphere.positions_World_mm, embed_points(problem.mesh, sphere.positions_World_mm, 0.0, "tumour")};
  CutSession session(problem, variant("xpbd"), CutSessionSettings{}, {tumour}, {sphere.tris});
  int events_cut = 0;
  for (int f = 0; f <= 30; ++f) {
    const CutFrameReport rep = session.apply_blade({Eigen::Vector3d(c, -5 + f, -5), Eigen::Vector3d(c, -5 + f, 25)}, true);
    for (const auto& e : rep.events)
      if (e.kind == "tumour_cut") {
        ++events_cut;
        EXPECT_EQ(e.distance_mm, 0.0);
        EXPECT_NEAR(e.location_World_mm.x(), c, 1e-6);  // on the blade
        EXPECT_LE((e.location_World_mm - Eigen::Vector3d(50, 10, 10)).norm(), r + 1e-6);
      }
    ASSERT_TRUE(session.step(1.0 / 60.0).healthy);
  }
  EXPECT_EQ(events_cut, 1);
  const CutMeshCheck mc = check_cut_mesh(session.mesh());
  ASSERT_TRUE(mc.valid()) << mc.summary();
  ASSERT_EQ(mc.piece_volume_mm3.size(), 2u);
  const auto& tris = session.tumour_tris()[0];
  const CarriedPoints& t = session.tumours()[0];
  const SurfaceCheck sc = check_surface(tris);
  EXPECT_TRUE(sc.closed_manifold()) << sc.open_edges << " open, " << sc.misoriented_edges << " misoriented, " << sc.nonmanifold_edges << " non-manifold";
  ASSERT_EQ(sc.components, 2);
  // The new points lie on the plane, the embedding reproduces every rest point.
  const Eigen::Matrix3Xd again = t.embedding.apply(session.mesh(), session.mesh().rest_positions_World_mm);
  EXPECT_LT((again - t.rest_World_mm).cwiseAbs().maxCoeff(), 1e-9);
  for (int i = static_cast<int>(sphere.positions_World_mm.cols()); i < t.rest_World_mm.cols(); ++i) EXPECT_NEAR(t.rest_World_mm(0, i), c, 1e-9);
  // Volumes: the polyhedron clipped by the plane (exact), the spherical caps (discretisation).
  const double whole = signed_volume(sphere.positions_World_mm, sphere.tris, {}, -1);
  double halves[2];
  for (int k = 0; k < 2; ++k) halves[k] = signed_volume(t.rest_World_mm, tris, sc.component, k);
  const bool first_left = halves[0] > halves[1];  // the larger one holds the centre (x = 50 < c)
  const double left = first_left ? halves[0] : halves[1], right = first_left ? halves[1] : halves[0];
  EXPECT_NEAR(left / clipped_volume(sphere, c, -1), 1.0, 1e-9);
  EXPECT_NEAR(right / clipped_volume(sphere, c, +1), 1.0, 1e-9);
  EXPECT_NEAR((left + right) / whole, 1.0, 1e-12);
  const double h_right = r - (c - 50);
  const double sphere_volume = 4.0 / 3.0 * M_PI * r * r * r;
  EXPECT_NEAR(right / whole, cap_volume(r, h_right) / sphere_volume, 2e-3);
  EXPECT_NEAR(left / whole, 1.0 - cap_volume(r, h_right) / sphere_volume, 2e-3);
  // Each half rides one piece, the two halves different ones.
  const auto pieces = pieces_per_component(mc, t.embedding, tris, sc);
  ASSERT_EQ(pieces[0].size(), 1u);
  ASSERT_EQ(pieces[1].size(), 1u);
  EXPECT_NE(*pieces[0].begin(), *pieces[1].begin());
}

// A 20 x 20 x 100 mm column hanging from its top face, a tumour sphere and a vessel line
// along its axis; cut through at z = 52 by a quick horizontal stroke: the lower piece falls
// with its half of the tumour and its part of the vessel; nothing stretches over the gap.
TEST(StructureSplit, HalvesAndVesselEndsSeparateWhenTheCutOpensUnderGravity) {
  // The column hangs and stretches while the blade crosses it at z = 52: the cut lies at
  // rest z ~ 58 (the vessel's crossing), so the sphere sits there.
  const HangingColumn c = hanging_column(57.0);
  CutSession session = c.session(CutSessionSettings{});
  const double dt = 1.0 / 60.0;
  int crossed_events = 0;
  for (int f = 0; f <= 15; ++f) {
    const CutFrameReport rep = session.apply_blade({Eigen::Vector3d(-10, -5 + 3 * f, 52), Eigen::Vector3d(30, -5 + 3 * f, 52)}, true);
    for (const auto& e : rep.events)
      if (e.kind == "vessel_crossed") {
        ++crossed_events;
        EXPECT_EQ(e.distance_mm, 0.0);
        EXPECT_NEAR(e.location_World_mm.x(), 12.3, 2.0);  // where the blade met the (slightly stretched) line
        EXPECT_NEAR(e.location_World_mm.z(), 52, 2.0);
      }
    ASSERT_TRUE(session.step(dt).healthy);
  }
  EXPECT_EQ(crossed_events, 1);
  ASSERT_EQ(session.vessel_segments().size(), 9u);  // the crossed segment is now two
  const CutMeshCheck mc = check_cut_mesh(session.mesh());
  ASSERT_TRUE(mc.valid()) << mc.summary();
  ASSERT_EQ(mc.piece_volume_mm3.size(), 2u);
  const SurfaceCheck sc = check_surface(session.tumour_tris()[0]);
  EXPECT_TRUE(sc.closed_manifold());
  ASSERT_EQ(sc.components, 2);
  // The two new vessel ends (the last two nodes) start together and part as the lower piece falls.
  const int n = static_cast<int>(session.vessels()->rest_World_mm.cols());
  ASSERT_EQ(n, 11);
  const auto ends = [&] {
    const Eigen::Matrix3Xd p = session.vessels()->embedding.apply(session.mesh(), session.positions_World_mm());
    return (p.col(n - 1) - p.col(n - 2)).norm();
  };
  // Together in the rest shape (one point on each lip); the lower piece has started falling
  // since the stroke went through.
  EXPECT_LT((session.vessels()->rest_World_mm.col(n - 1) - session.vessels()->rest_World_mm.col(n - 2)).norm(), 1e-12);
  const double parted = ends();
  for (int f = 0; f < 24; ++f) {
    session.apply_blade({Eigen::Vector3d(-10, 60, 52), Eigen::Vector3d(30, 60, 52)}, false);
    ASSERT_TRUE(session.step(dt).healthy);
  }
  EXPECT_GT(ends(), parted + 100.0);  // 0.4 s more of (damped) free fall
  // No vessel segment and no tumour edge spans the gap: lengths stay near their rest lengths.
  const Eigen::Matrix3Xd pv = session.vessels()->embedding.apply(session.mesh(), session.positions_World_mm());
  for (const auto& [a, b] : session.vessel_segments())
    EXPECT_LT((pv.col(a) - pv.col(b)).norm(), 1.5 * (session.vessels()->rest_World_mm.col(a) - session.vessels()->rest_World_mm.col(b)).norm() + 1.0);
  const Eigen::Matrix3Xd pt = session.tumours()[0].embedding.apply(session.mesh(), session.positions_World_mm());
  double longest = 0;
  for (const auto& t : session.tumour_tris()[0])
    for (int k = 0; k < 3; ++k) longest = std::max(longest, (pt.col(t[static_cast<std::size_t>(k)]) - pt.col(t[static_cast<std::size_t>((k + 1) % 3)])).norm());
  EXPECT_LT(longest, 15.0);  // the sphere is 12 mm across; a triangle across the gap would be > 20 mm
  // Each half of the tumour rides one piece, the vessel parts theirs.
  const auto pieces = pieces_per_component(mc, session.tumours()[0].embedding, session.tumour_tris()[0], sc);
  EXPECT_EQ(pieces[0].size(), 1u);
  EXPECT_EQ(pieces[1].size(), 1u);
  EXPECT_NE(*pieces[0].begin(), *pieces[1].begin());
}

// A cut that ends inside the tumour (crack tip inside): the surface is split where the cut
// crosses it and stays one closed, consistently oriented surface.
TEST(StructureSplit, PartialCutIntoTheTumourKeepsItClosed) {
  SimProblem problem = bar_problem(Eigen::Vector3d(100, 20, 20), 10, 4, 4);
  problem.gravity_World_mm_s2.setZero();
  for (int v = 0; v < problem.mesh.num_vertices(); ++v)
    if (problem.mesh.rest_positions_World_mm(0, v) < 1e-9) problem.fixed_vertices.push_back(v);
  const TriMesh sphere = make_ellipsoid_surface(Eigen::Vector3d(50, 10, 10), Eigen::Vector3d::Constant(7.0), 3);
  CarriedPoints tumour{"tumour", sphere.positions_World_mm, embed_points(problem.mesh, sphere.positions_World_mm, 0.0, "tumour")};
  CutSession session(problem, variant("xpbd"), CutSessionSettings{}, {tumour}, {sphere.tris});
  for (int f = 0; f <= 15; ++f) {  // the blade stops at y = 10, the tumour's middle
    session.apply_blade({Eigen::Vector3d(52.3, -5 + f, -5), Eigen::Vector3d(52.3, -5 + f, 25)}, true);
    ASSERT_TRUE(session.step(1.0 / 60.0).healthy);
  }
  const auto& tris = session.tumour_tris()[0];
  EXPECT_GT(tris.size(), sphere.tris.size());  // split where crossed
  const SurfaceCheck sc = check_surface(tris);
  EXPECT_TRUE(sc.closed_manifold()) << sc.open_edges << " open, " << sc.misoriented_edges << " misoriented, " << sc.nonmanifold_edges << " non-manifold";
  EXPECT_EQ(sc.components, 1);
  const CarriedPoints& t = session.tumours()[0];
  EXPECT_NEAR(signed_volume(t.rest_World_mm, tris, sc.component, -1) / signed_volume(sphere.positions_World_mm, sphere.tris, {}, -1), 1.0, 1e-9);
  // The slit is closed side by side: each side by the cut's own plane between its copies and
  // the chord between the crack ends (the copies on the plane x = 52.3, the crack ends, the
  // vertices opposite the crossed edge of the triangles where the cut ends, within a tumour
  // edge of it), not a fan.
  double edge = 0.0;
  for (const auto& tri : sphere.tris)
    for (int k = 0; k < 3; ++k) edge = std::max(edge, (sphere.positions_World_mm.col(tri[static_cast<std::size_t>(k)]) - sphere.positions_World_mm.col(tri[static_cast<std::size_t>((k + 1) % 3)])).norm());
  const int n = static_cast<int>(sphere.positions_World_mm.cols());
  Embedding input;
  input.tet.assign(t.embedding.tet.begin(), t.embedding.tet.begin() + n);
  input.weights = t.embedding.weights.leftCols(n);
  std::vector<int> all(static_cast<std::size_t>(session.mesh().num_tets()));
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  const SplitStructure split = split_surface(session.mesh(), CutLips(session.mesh(), all), sphere.positions_World_mm, input, sphere.tris);
  EXPECT_EQ(split.tris, tris);
  EXPECT_EQ(split.slits, 1);
  EXPECT_EQ(split.ragged_slits, 0);
  EXPECT_EQ(split.caps, 1);
  for (std::size_t k = static_cast<std::size_t>(split.first_cap_tri); k < split.tris.size(); ++k)
    for (int v : split.tris[k]) EXPECT_NEAR(split.rest_World_mm(0, v), 52.3, v >= n ? 0.1 + 1e-9 : edge);  // path_tolerance_mm
  EXPECT_EQ(self_intersections(split.rest_World_mm, split.tris), 0);
}

// A long curved slit ending inside the tumour: a banana-shaped tumour (an ellipsoid 44 mm
// long, 5 mm thick, bent along a parabola of radius 20 mm at its vertex) in a bar; a
// vertical blade follows the bend into it and stops 6 mm before its far end. The slit runs
// across 85 of the tumour's edges, with pockets where it passes tumour vertices; it is
// closed along the cut (structure_split.hpp: least-area triangulation), not by a fan from
// one point: the surface is closed, 2-manifold, consistently oriented, does not intersect
// itself, keeps its volume, and the closure lies on the cut (a fan's centre lies ~3 mm off
// the bent cut, outside the thin tumour: its triangles cross the tumour's surface).
TEST(StructureSplit, LongCurvedSlitEndingInsideTheTumourIsClosedAlongTheCut) {
  SimProblem problem = bar_problem(Eigen::Vector3d(80, 60, 40), 24, 18, 12);
  problem.gravity_World_mm_s2.setZero();
  for (int v = 0; v < problem.mesh.num_vertices(); ++v)
    if (problem.mesh.rest_positions_World_mm(0, v) < 1e-9) problem.fixed_vertices.push_back(v);
  const double bend = 20.0, y0 = 30.0;
  const auto centre_x = [&](double y) { return 30.0 + (y - y0) * (y - y0) / (2 * bend); };  // the bend (and the blade's path)
  TriMesh tumour_surface = make_ellipsoid_surface(Eigen::Vector3d(30, y0, 20), Eigen::Vector3d(2.5, 22, 6), 3);
  for (int i = 0; i < tumour_surface.positions_World_mm.cols(); ++i) tumour_surface.positions_World_mm(0, i) += centre_x(tumour_surface.positions_World_mm(1, i)) - 30.0;
  const Eigen::Matrix3Xd& rest = tumour_surface.positions_World_mm;
  ASSERT_EQ(self_intersections(rest, tumour_surface.tris), 0) << "the bent tumour itself";
  CarriedPoints tumour{"tumour", rest, embed_points(problem.mesh, rest, 0.0, "tumour")};
  CutSessionSettings settings;
  settings.cut.side_distance_mm = 20.0;  // about the cut's smallest radius of curvature (tet_cutter.hpp)
  CutSession session(problem, variant("xpbd"), settings, {tumour}, {tumour_surface.tris});
  // From y = 4 (outside: the tumour starts at y = 8) to y = 46 (it ends at 52), 0.5 mm per frame.
  for (double y = y0 - 26.0; y <= y0 + 16.0 + 1e-9; y += 0.5) {
    session.apply_blade({Eigen::Vector3d(centre_x(y), y, -5), Eigen::Vector3d(centre_x(y), y, 45)}, true);
    ASSERT_TRUE(session.step(1.0 / 60.0).healthy);
  }
  const CutMeshCheck mc = check_cut_mesh(session.mesh());
  ASSERT_TRUE(mc.valid()) << mc.summary();
  // The split, again from the input against the cut mesh, to see its caps.
  const CarriedPoints& t = session.tumours()[0];
  const int n = static_cast<int>(rest.cols());
  Embedding input;
  input.tet.assign(t.embedding.tet.begin(), t.embedding.tet.begin() + n);
  input.weights = t.embedding.weights.leftCols(n);
  std::vector<int> all(static_cast<std::size_t>(session.mesh().num_tets()));
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<int>(i);
  const CutLips lips(session.mesh(), all);
  const SplitStructure split = split_surface(session.mesh(), lips, rest, input, tumour_surface.tris);
  EXPECT_EQ(split.tris, session.tumour_tris()[0]);
  EXPECT_GT(split.crossed_edges, 60) << "a long slit";
  // One slit; the other loops are the middles of tumour triangles the bent cut crosses on
  // all three edges (fans around a centre on the cut, 1 mm across).
  EXPECT_EQ(split.slits, 1) << "closed along the cut, not by a fan";
  EXPECT_EQ(split.ragged_slits, 1) << "pockets where the slit passes tumour vertices: sewn";
  EXPECT_GE(split.caps, 1);
  const SurfaceCheck sc = check_surface(split.tris);
  EXPECT_TRUE(sc.closed_manifold()) << sc.open_edges << " open, " << sc.misoriented_edges << " misoriented, " << sc.nonmanifold_edges << " non-manifold";
  // One part holds the tumour; where the ragged crack front passes round a tumour vertex the
  // cut encloses it, and its few triangles become a flat part of no volume (as before).
  const double whole = signed_volume(rest, tumour_surface.tris, {}, -1);
  int main_parts = 0;
  for (int c = 0; c < sc.components; ++c) {
    const double v = signed_volume(split.rest_World_mm, split.tris, sc.component, c);
    if (std::abs(v) > 1e-9 * whole) {
      ++main_parts;
      EXPECT_NEAR(v / whole, 1.0, 1e-9);
    }
  }
  EXPECT_EQ(main_parts, 1);
  EXPECT_NEAR(signed_volume(split.rest_World_mm, split.tris, sc.component, -1) / whole, 1.0, 1e-9);
  EXPECT_EQ(self_intersections(split.rest_World_mm, split.tris), 0);
  // The closure on the cut: every cap point within the chord error of the bent sheet the
  // blade swept, x = centre_x(y) (the caps' triangles are ~1 mm across a bend of 8 mm).
  double off = 0.0;
  for (std::size_t k = static_cast<std::size_t>(split.first_cap_tri); k < split.tris.size(); ++k) {
    const auto& tri = split.tris[k];
    const Eigen::Vector3d c = (split.rest_World_mm.col(tri[0]) + split.rest_World_mm.col(tri[1]) + split.rest_World_mm.col(tri[2])) / 3.0;
    const double slope = (c.y() - y0) / bend;
    off = std::max(off, std::abs(c.x() - centre_x(c.y())) / std::sqrt(1 + slope * slope));
  }
  EXPECT_LT(off, 0.5) << "cap triangles off the cut";
  // Opened: the cut mesh's vertices moved 0.5 mm away from the bent sheet on their side
  // (a vertex on the cut by the side of its tets; 0 where its tets lie on both sides: the
  // crack front), the tumour carried by its embedding: the slit gapes, the volume grows.
  // Printed, not asserted: the triangle pairs that then intersect (where the ragged slit's
  // pockets are sewn; a fan crosses the thin tumour far more often).
  const TetMesh& mesh = session.mesh();
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm;
  const auto side_of = [&](const Eigen::Vector3d& q) { return q.x() - centre_x(q.y()) > 0 ? 1 : -1; };
  std::vector<int> tet_sides(static_cast<std::size_t>(mesh.num_vertices()), 0), tet_count(static_cast<std::size_t>(mesh.num_vertices()), 0);
  for (const auto& tet : mesh.tets) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int w : tet) c += mesh.rest_positions_World_mm.col(w) / 4.0;
    for (int w : tet) {
      tet_sides[static_cast<std::size_t>(w)] += side_of(c);
      ++tet_count[static_cast<std::size_t>(w)];
    }
  }
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    const int around = tet_count[static_cast<std::size_t>(v)], sum = tet_sides[static_cast<std::size_t>(v)];
    if (around == 0 || std::abs(sum) != around) continue;  // tets on both sides
    const Eigen::Vector3d q = x.col(v);
    const double slope = (q.y() - y0) / bend;
    x.col(v) += 0.5 * (sum > 0 ? 1.0 : -1.0) * Eigen::Vector3d(1, -slope, 0).normalized();
  }
  const Eigen::Matrix3Xd opened = split.embedding.apply(mesh, x);
  std::cerr << "[structure split] long curved slit: " << split.crossed_edges << " crossed edges, " << split.slits << " slit(s) closed, "
            << self_intersections(opened, split.tris) << " intersecting triangle pairs once opened 0.5 mm per side (not asserted)\n";
  EXPECT_GT(signed_volume(opened, split.tris, sc.component, -1), signed_volume(rest, tumour_surface.tris, {}, -1));
}

// The bundled coarse liver at rest: a vertical blade swept through its tumour at x = 71.3.
TEST(StructureSplit, BundledLiverTumourCutThrough) {
  const std::string data = std::getenv("ARNAV_DATA_DIR") ? std::getenv("ARNAV_DATA_DIR") : "data";
  Scene scene = load_scene(data + "/liver/liver_coarse_cut.scene.yaml");
  scene.problem.gravity_World_mm_s2.setZero();
  const std::unique_ptr<CutSession> session = make_cut_session(scene, scene.model, CutSessionSettings{});
  const double x_cut = 71.3;
  std::vector<double> split_ms;
  for (int f = 0; f <= 45; ++f) {  // y 125 .. 215 at 2 mm per frame, z 100 .. 200
    const CutFrameReport r = session->apply_blade({Eigen::Vector3d(x_cut, 125 + 2 * f, 100), Eigen::Vector3d(x_cut, 125 + 2 * f, 200)}, true);
    if (r.cut.topology_changed) split_ms.push_back(r.reembed_ms);
    ASSERT_TRUE(session->step(scene.time_step_s).healthy);
  }
  std::sort(split_ms.begin(), split_ms.end());
  ASSERT_FALSE(split_ms.empty());
  std::cerr << "[structure split] bundled coarse liver: re-embed + split per topology change, median " << split_ms[split_ms.size() / 2]
            << " ms, max " << split_ms.back() << " ms over " << split_ms.size() << " changes (not asserted)\n";
  const CutMeshCheck mc = check_cut_mesh(session->mesh());
  ASSERT_TRUE(mc.valid()) << mc.summary();
  const auto& tris = session->tumour_tris()[0];
  const CarriedPoints& t = session->tumours()[0];
  const SurfaceCheck sc = check_surface(tris);
  EXPECT_TRUE(sc.closed_manifold()) << sc.open_edges << " open, " << sc.misoriented_edges << " misoriented, " << sc.nonmanifold_edges << " non-manifold";
  ASSERT_EQ(sc.components, 2);
  const Eigen::Matrix3Xd again = t.embedding.apply(session->mesh(), session->mesh().rest_positions_World_mm);
  EXPECT_LT((again - t.rest_World_mm).cwiseAbs().maxCoeff(), 1e-9);
  const double whole = signed_volume(scene.tumours[0].rest.positions_World_mm, scene.tumours[0].rest.tris, {}, -1);
  const double v0 = signed_volume(t.rest_World_mm, tris, sc.component, 0), v1 = signed_volume(t.rest_World_mm, tris, sc.component, 1);
  EXPECT_NEAR((v0 + v1) / whole, 1.0, 1e-9);
  EXPECT_NEAR(std::min(v0, v1) / clipped_volume(scene.tumours[0].rest, x_cut, +1), 1.0, 1e-6);  // the cut is on the plane to path_tolerance_mm
  // The halves' points are embedded on their own side of the cut: every tet holding a point
  // of the smaller (x > 71.3) half lies at x >= 71.3 - path_tolerance_mm.
  const int small = v0 < v1 ? 0 : 1;
  for (std::size_t k = 0; k < tris.size(); ++k) {
    if (sc.component[k] != small) continue;
    for (int v : tris[k])
      for (int w : session->mesh().tets[static_cast<std::size_t>(t.embedding.tet[static_cast<std::size_t>(v)])])
        EXPECT_GE(session->mesh().rest_positions_World_mm(0, w), x_cut - 0.1 - 1e-9);
  }
  // Vessels crossed by the blade were split (one more segment per crossing).
  ASSERT_TRUE(session->vessels());
  EXPECT_EQ(session->vessel_segments().size() - scene.vessels->rest.segments.size(),
            static_cast<std::size_t>(session->vessels()->rest_World_mm.cols() - scene.vessels->rest.nodes_World_mm.cols()) / 2);
}

namespace {

// The split the session keeps equals the split made again from the uncut structure.
void expect_split_as_from_input(const CutSession& session, int frame) {
  for (int k = 0; k < static_cast<int>(session.tumours().size()); ++k) {
    const SplitStructure again = session.tumour_split_from_input(k);
    const auto i = static_cast<std::size_t>(k);
    ASSERT_EQ(again.tris, session.tumour_tris()[i]) << "frame " << frame;
    ASSERT_TRUE(again.rest_World_mm == session.tumours()[i].rest_World_mm) << "frame " << frame;
    ASSERT_EQ(again.embedding.tet, session.tumours()[i].embedding.tet) << "frame " << frame;
    ASSERT_TRUE(again.embedding.weights == session.tumours()[i].embedding.weights) << "frame " << frame;
  }
  const SplitStructure again = session.vessel_split_from_input();
  ASSERT_EQ(again.segments, session.vessel_segments()) << "frame " << frame;
  ASSERT_TRUE(again.rest_World_mm == session.vessels()->rest_World_mm) << "frame " << frame;
  ASSERT_EQ(again.embedding.tet, session.vessels()->embedding.tet) << "frame " << frame;
  ASSERT_TRUE(again.embedding.weights == session.vessels()->embedding.weights) << "frame " << frame;
}

}  // namespace

// The session splits a structure again only when a step's cut can change its split (a new cut
// face one of its edges passes through, or a lip a point of the split sits on); every other
// step only carries the split's embedding over. Checked against the split made from scratch
// after every frame of: a curved stroke refined ahead of the blade through the tumour's tets
// under the tumour (touching them, crossing none of its edges) and across the vessel, then a
// second stroke through the tumour (caps: split again at every step after), the column
// hanging and moving under gravity.
TEST(StructureSplit, SplitKeptAcrossStepsEqualsTheSplitMadeAgain) {
  const HangingColumn c = hanging_column(60.0);
  CutSessionSettings settings;
  settings.cut.chord_sagitta_mm = 1.0;
  settings.cut.min_refined_edge_mm = 3.0;
  CutSession session = c.session(settings);
  const double dt = 1.0 / 60.0;
  int refined = 0, vessel_cut_at = -1, tumour_cut_at = -1, frame = 0;
  const auto run = [&](double z0, double bend, bool cutting, int frames) {
    for (int f = 0; f <= frames; ++f, ++frame) {
      const double y = -5 + 2 * f, z = z0 + bend * (y - 10) * (y - 10);
      const CutFrameReport rep = session.apply_blade({Eigen::Vector3d(-10, y, z), Eigen::Vector3d(30, y, z)}, cutting);
      refined += rep.cut.edges_refined;
      if (vessel_cut_at < 0 && session.vessel_segments().size() > c.segments.size()) vessel_cut_at = frame;
      if (tumour_cut_at < 0 && !session.tumour_tris()[0].empty() && session.tumour_tris()[0].size() > c.sphere.tris.size()) tumour_cut_at = frame;
      ASSERT_TRUE(session.step(dt).healthy);
      ASSERT_NO_FATAL_FAILURE(expect_split_as_from_input(session, frame));
    }
  };
  run(44.0, 0.02, true, 15);   // under the tumour (bottom at z 54), across the vessel
  run(44.0, 0.02, false, 3);   // the stroke ends
  run(60.0, 0.0, true, 15);    // through the tumour
  run(60.0, 0.0, false, 3);
  EXPECT_GT(refined, 0);
  EXPECT_GE(vessel_cut_at, 0);
  EXPECT_GT(tumour_cut_at, vessel_cut_at);
  const SurfaceCheck sc = check_surface(session.tumour_tris()[0]);
  EXPECT_TRUE(sc.closed_manifold());
  EXPECT_EQ(sc.components, 2);
}
