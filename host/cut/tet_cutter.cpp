#include "host/cut/tet_cutter.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <optional>
#include <queue>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>

#include "host/mesh/box_mesh.hpp"

namespace arnav::host::cut {

namespace {
constexpr const auto& kEdges = kTetEdges;
constexpr const auto& kFaces = kTetFaces;
// Smallest split parameter: a crossing closer to a vertex snaps whatever the tolerance
// (no degenerate tets).
constexpr double kMinSplitFraction = 1e-6;
// Sides from the stroke's surface (stroke_side): the vertex's distance to the nearest triangle
// at most this times its distance to the triangle's plane (27 and 45 degrees off the normal).
constexpr double kEagerCone = 1.118;
constexpr double kLazyCone = 1.415;

double sweep_distance(const std::vector<Triangle>& tris, const Eigen::Vector3d& p, int* nearest = nullptr) {
  double d = 1e300;
  for (std::size_t i = 0; i < tris.size(); ++i) {
    const double di = point_triangle_distance(p, tris[i]);
    if (di < d) {
      d = di;
      if (nearest) *nearest = static_cast<int>(i);
    }
  }
  return d;
}

Eigen::Vector3d unit_normal(const Triangle& t) { return (t.b - t.a).cross(t.c - t.a).normalized(); }

// Barycentric weights of p in tet (vertex positions pos); outside the tet some are negative.
Eigen::Vector4d tet_weights(const Eigen::Matrix3Xd& pos, const std::array<int, 4>& tet, const Eigen::Vector3d& p) {
  // Cramer's rule on the edge vectors from vertex 0: each weight is the signed volume of the
  // tet with that vertex replaced by p over the tet's (a flat tet: non-finite weights).
  const Eigen::Vector3d e1 = pos.col(tet[1]) - pos.col(tet[0]), e2 = pos.col(tet[2]) - pos.col(tet[0]),
                        e3 = pos.col(tet[3]) - pos.col(tet[0]), q = p - pos.col(tet[0]);
  const Eigen::Vector3d c23 = e2.cross(e3);
  const double inv = 1.0 / e1.dot(c23);
  const double l1 = q.dot(c23) * inv, l2 = e1.dot(q.cross(e3)) * inv, l3 = e1.dot(e2.cross(q)) * inv;
  return {1.0 - l1 - l2 - l3, l1, l2, l3};
}

// Six times the volume of tet (positions pos) with its vertex w at pw.
double volume6_with(const Eigen::Matrix3Xd& pos, const std::array<int, 4>& tet, int w, const Eigen::Vector3d& pw) {
  Eigen::Vector3d q[4];
  for (int k = 0; k < 4; ++k) q[k] = tet[static_cast<std::size_t>(k)] == w ? pw : Eigen::Vector3d(pos.col(tet[static_cast<std::size_t>(k)]));
  return (q[1] - q[0]).cross(q[2] - q[0]).dot(q[3] - q[0]);
}
}  // namespace

TetCutter::EdgeKey TetCutter::edge_key(int a, int b) { return arnav::host::edge_key(a, b); }

std::pair<int, int> TetCutter::edge_ends(EdgeKey key) {
  return {static_cast<int>(key >> 32), static_cast<int>(key & 0xffffffffu)};
}

std::array<int, 3> TetCutter::face_key(int a, int b, int c) {
  std::array<int, 3> f{a, b, c};
  std::sort(f.begin(), f.end());
  return f;
}

TetCutter::TetCutter(const TetMesh& mesh, const CutSettings& settings) : mesh_(mesh), settings_(settings) {
  // Each setting checked with its value in the message (a NaN fails every comparison).
  const auto require = [](bool ok, const char* what, double value) {
    if (!ok) throw std::invalid_argument(std::string("cut settings: ") + what + ", got " + std::to_string(value));
  };
  require(settings_.snap_fraction > 0.0 && settings_.snap_fraction < 0.5, "snap_fraction must lie in (0, 0.5)", settings_.snap_fraction);
  require(settings_.vertex_tolerance_mm >= 0.0 && std::isfinite(settings_.vertex_tolerance_mm), "vertex_tolerance_mm must be finite and >= 0",
          settings_.vertex_tolerance_mm);
  require(settings_.path_tolerance_mm >= 0.0 && std::isfinite(settings_.path_tolerance_mm), "path_tolerance_mm must be finite and >= 0",
          settings_.path_tolerance_mm);
  require(settings_.side_distance_mm > 0.0, "side_distance_mm must be > 0", settings_.side_distance_mm);
  require(settings_.chord_sagitta_mm >= 0.0 && std::isfinite(settings_.chord_sagitta_mm), "chord_sagitta_mm must be finite and >= 0",
          settings_.chord_sagitta_mm);
  require(settings_.min_refined_edge_mm > 0.0 && std::isfinite(settings_.min_refined_edge_mm), "min_refined_edge_mm must be finite and > 0",
          settings_.min_refined_edge_mm);
  require(settings_.max_refinements_per_step >= 0, "max_refinements_per_step must be >= 0", settings_.max_refinements_per_step);
  const int nv = mesh_.num_vertices();
  vertex_tets_.assign(static_cast<std::size_t>(nv), {});
  for (int t = 0; t < mesh_.num_tets(); ++t)
    for (int v : mesh_.tets[static_cast<std::size_t>(t)]) {
      if (v < 0 || v >= nv) throw std::invalid_argument("cut: tet " + std::to_string(t) + " has a vertex index out of range");
      vertex_tets_[static_cast<std::size_t>(v)].push_back(t);
    }
  if (mesh_.tet_region.size() != mesh_.tets.size()) mesh_.tet_region.assign(mesh_.tets.size(), 0);
  on_cut_.assign(static_cast<std::size_t>(nv), 0);
  side_.assign(static_cast<std::size_t>(nv), 0);
  cut_normal_.assign(static_cast<std::size_t>(nv), Eigen::Vector3d::Zero());
  tip_tet_.assign(mesh_.tets.size(), 0);
  flat_side_.assign(mesh_.tets.size(), 0);
  origin_.resize(mesh_.tets.size());
  std::iota(origin_.begin(), origin_.end(), 0);
  family_.resize(mesh_.tets.size());
  for (int t = 0; t < mesh_.num_tets(); ++t) family_[static_cast<std::size_t>(t)] = {t};
  bvh_.build(family_boxes(mesh_.rest_positions_World_mm));
}

int TetCutter::locate(const Eigen::Vector3d& p, const Eigen::Matrix3Xd& x, Eigen::Vector4d& weights, bool refit) {
  if (refit) bvh_.refit(family_boxes(x));
  Aabb box;
  box.extend(p);
  int best_tet = -1;
  double best = -1e300;
  bvh_.query(box, [&](int fam) {
    const std::vector<int>& family = family_[static_cast<std::size_t>(fam)];
    for (int t : family) {
      const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
      if (family.size() > 1) {  // a refined or cut input tet: only its children whose box holds p
        Aabb b;
        for (int w : tet) b.extend(Eigen::Vector3d(x.col(w)));
        if (!b.inflated(1e-4).contains(p)) continue;
      }
      const Eigen::Vector4d w = tet_weights(x, tet, p);
      if (w.allFinite() && w.minCoeff() > best) {
        best = w.minCoeff();
        best_tet = t;
        weights = w;
      }
    }
  });
  return best_tet;
}

std::vector<Triangle> TetCutter::sweep_in_material(const SweptSurface& sweep, const Eigen::Matrix3Xd& x, bool refit) {
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  const int strips = std::max(1, sweep.strips);
  const double length = (sweep.to.heel_World_mm - sweep.to.tip_World_mm).norm();
  const int n = std::clamp(static_cast<int>(std::ceil(length / 1.0)), strips, 64);
  const bool carried = sweep.from_points.size() == static_cast<std::size_t>(strips + 1);
  // The blade's start (carried with the tissue) and end lines, tip first: 2 (n + 1) points.
  std::vector<Eigen::Vector3d> p(static_cast<std::size_t>(2 * (n + 1)));
  for (int i = 0; i <= n; ++i) {
    const double u = static_cast<double>(i) / n;
    if (carried) {
      const double f = u * strips;
      const int j = std::min(static_cast<int>(std::floor(f)), strips - 1);
      const double a = f - j;
      p[static_cast<std::size_t>(i)] = (1 - a) * sweep.from_points[static_cast<std::size_t>(j)] + a * sweep.from_points[static_cast<std::size_t>(j + 1)];
    } else {
      p[static_cast<std::size_t>(i)] = (1 - u) * sweep.from.tip_World_mm + u * sweep.from.heel_World_mm;
    }
    p[static_cast<std::size_t>(n + 1 + i)] = (1 - u) * sweep.to.tip_World_mm + u * sweep.to.heel_World_mm;
  }
  // Rest position: the barycentric combination of the rest positions of the tet holding the
  // point now. A point outside the tissue (or in the opening of a cut) keeps the displacement
  // of the nearest mapped point of its own line, else of the other line's point at the same
  // place along the blade (the blade entering from above the organ); nothing mapped: missed.
  std::vector<Eigen::Vector3d> r(p.size());
  std::vector<char> mapped(p.size(), 0);
  for (std::size_t k = 0; k < p.size(); ++k) {
    Eigen::Vector4d w;
    const int t = locate(p[k], x, w, refit && k == 0);
    if (t < 0 || w.minCoeff() < -1e-6) continue;
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    r[k].setZero();
    for (int j = 0; j < 4; ++j) r[k] += w[j] * rest.col(tet[static_cast<std::size_t>(j)]);
    mapped[k] = 1;
  }
  const auto nearest_mapped = [&](int base, int i) {
    int nearest = -1;
    for (int j = 0; j <= n; ++j)
      if (mapped[static_cast<std::size_t>(base + j)] && (nearest < 0 || std::abs(j - i) < std::abs(nearest - i))) nearest = j;
    return nearest < 0 ? -1 : base + nearest;
  };
  std::vector<Eigen::Vector3d> shift(p.size(), Eigen::Vector3d::Zero());
  for (int line = 0; line < 2; ++line) {
    const int base = line * (n + 1), other = (1 - line) * (n + 1);
    for (int i = 0; i <= n; ++i) {
      const auto k = static_cast<std::size_t>(base + i);
      if (mapped[k]) continue;
      int m = nearest_mapped(base, i);
      if (m < 0) m = nearest_mapped(other, i);
      if (m < 0) return {};
      shift[k] = r[static_cast<std::size_t>(m)] - p[static_cast<std::size_t>(m)];
    }
  }
  for (std::size_t k = 0; k < p.size(); ++k)
    if (!mapped[k]) r[k] = p[k] + shift[k];
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    const auto f0 = static_cast<std::size_t>(i), f1 = f0 + 1, t0 = static_cast<std::size_t>(n + 1 + i), t1 = t0 + 1;
    tris.push_back({r[f0], r[f1], r[t0]});
    tris.push_back({r[f1], r[t1], r[t0]});
  }
  return tris;
}

double TetCutter::surface_distance(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Vector3d& p,
                                   Eigen::Vector3d* closest) {
  double best = 1e300;
  for (const auto& chunk : chunks) {
    const Eigen::Vector3d gap = (chunk.box.min - p).cwiseMax(p - chunk.box.max).cwiseMax(0.0);
    if (gap.norm() >= best) continue;
    for (int i = chunk.begin; i < chunk.end; ++i) {
      Eigen::Vector3d c;
      const double d = point_triangle_distance(p, tris[static_cast<std::size_t>(i)], &c);
      if (d < best) {
        best = d;
        if (closest) *closest = c;
      }
    }
  }
  return best;
}

double TetCutter::surface_crossing(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Vector3d& p0,
                                   const Eigen::Vector3d& p1, double near_s) {
  Aabb edge_box;
  edge_box.extend(p0);
  edge_box.extend(p1);
  double best = -1.0;
  for (const auto& chunk : chunks) {
    if (!chunk.box.overlaps(edge_box)) continue;
    for (int i = chunk.begin; i < chunk.end; ++i) {
      double u = 0.0;
      if (segment_triangle_intersection(p0, p1, tris[static_cast<std::size_t>(i)], u) && (best < 0 || std::abs(u - near_s) < std::abs(best - near_s)))
        best = u;
    }
  }
  return best;
}

void TetCutter::append_chunk(const std::vector<Triangle>& add, std::vector<Triangle>& tris, std::vector<StrokeChunk>& chunks) {
  StrokeChunk chunk;
  chunk.begin = static_cast<int>(tris.size());
  double area2 = 0.0;
  for (const auto& t : add) {
    chunk.box.extend(t.a);
    chunk.box.extend(t.b);
    chunk.box.extend(t.c);
    const double a2 = (t.b - t.a).cross(t.c - t.a).norm();  // twice the area
    chunk.centroid += a2 * (t.a + t.b + t.c) / 3.0;
    area2 += a2;
  }
  if (area2 > 0.0) {
    chunk.centroid /= area2;
    // One frame's strip is long along the blade and short along its motion: the principal
    // direction of its points is the blade's (its normal is not reliable, see
    // material_curvature_per_mm).
    Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
    for (const auto& t : add)
      for (const Eigen::Vector3d& q : {t.a, t.b, t.c}) spread += (q - chunk.centroid) * (q - chunk.centroid).transpose();
    chunk.axis = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(spread).eigenvectors().col(2);
  }
  tris.insert(tris.end(), add.begin(), add.end());
  chunk.end = static_cast<int>(tris.size());
  chunks.push_back(chunk);
}

double TetCutter::material_curvature_per_mm() const {
  // The circle through three points of the blade's path in the material, seen along the
  // blade: the centroids of this stroke's frames' surfaces, the latest, one leg of path
  // before it and one two legs before it, projected on the plane normal to the blade's mean
  // axis there. The bend of a surface swept by a straight blade is the bend of that
  // projected path; the centroids' depth along the blade changes with how much of the blade
  // is in the tissue (+-2 mm from frame to frame on the demo's ring) and is left out.
  // Not the turn of the frames' normals: a strip 0.3 mm wide whose ends moved 0.1 mm with
  // the tissue (a grasper pulling) turns by tens of degrees, which read as radii of 1-6 mm on
  // a 21 mm ring (issue 20). A projected centroid's jitter of d mm reads as a curvature of
  // about 2 d / leg^2: legs of kLeg_mm (0.1 mm on a straight cut: a radius of 125 mm); over a
  // stroke's first 2 kLeg_mm, half its path so far (from kMinLeg_mm: a curve from the start
  // is refined from the start, a straight stroke's start a little more than it needs).
  constexpr double kLeg_mm = 5.0, kMinLeg_mm = 1.0;
  const auto& chunks = stroke_chunks_rest_;
  std::vector<std::pair<int, double>> back;  // chunk, path to the latest (mm), latest first
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  for (int j = static_cast<int>(chunks.size()) - 1; j >= 0; --j) {
    const StrokeChunk& c = chunks[static_cast<std::size_t>(j)];
    if (c.axis.squaredNorm() == 0.0) continue;  // nothing of this frame's surface in the tissue
    axis += axis.dot(c.axis) < 0.0 ? Eigen::Vector3d(-c.axis) : c.axis;
    double path_mm = 0.0;
    if (!back.empty()) {
      const Eigen::Vector3d step = c.centroid - chunks[static_cast<std::size_t>(back.back().first)].centroid, u = axis.normalized();
      path_mm = back.back().second + (step - step.dot(u) * u).norm();
    }
    back.emplace_back(j, path_mm);
    if (path_mm >= 2.0 * kLeg_mm) break;
  }
  if (back.empty()) return 0.0;
  const double leg = std::min(kLeg_mm, 0.5 * back.back().second);
  if (leg < kMinLeg_mm) return 0.0;
  const Eigen::Vector3d u = axis.normalized();
  const auto flat = [&](double at_mm) {
    const auto k = std::find_if(back.begin(), back.end(), [&](const auto& b) { return b.second >= at_mm * (1.0 - 1e-9); });
    const Eigen::Vector3d& c = chunks[static_cast<std::size_t>((k == back.end() ? back.back() : *k).first)].centroid;
    return Eigen::Vector3d(c - c.dot(u) * u);
  };
  const Eigen::Vector3d p0 = flat(0.0), p1 = flat(leg), p2 = flat(2.0 * leg);
  const Eigen::Vector3d a = p1 - p0, b = p2 - p1, c = p2 - p0;
  const double denominator = a.norm() * b.norm() * c.norm();
  return denominator > 0.0 ? 2.0 * a.cross(b).norm() / denominator : 0.0;
}

double TetCutter::material_stroke_distance(const Eigen::Vector3d& p, Eigen::Vector3d* closest) const {
  return surface_distance(stroke_tris_rest_, stroke_chunks_rest_, p, closest);
}

double TetCutter::world_stroke_crossing(int a, int b, double near_s, const Eigen::Matrix3Xd& x) const {
  return surface_crossing(stroke_tris_, stroke_chunks_, x.col(a), x.col(b), near_s);
}

bool TetCutter::material_crossing(int a, int b, double near_s, double& s) const {
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  const double u = surface_crossing(stroke_tris_rest_, stroke_chunks_rest_, rest.col(std::min(a, b)), rest.col(std::max(a, b)), near_s);
  if (u < 0.0) return false;
  s = u;
  return true;
}

double TetCutter::nearest_on_material_stroke(int a, int b, double near_s) const {
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  const Eigen::Vector3d p0 = rest.col(std::min(a, b)), p1 = rest.col(std::max(a, b));
  const auto distance = [&](double u) { return material_stroke_distance((1.0 - u) * p0 + u * p1); };
  constexpr double kLo = 0.01, kHi = 0.99;
  // The distance along the edge need not have one minimum (a curved surface): the best of
  // near_s and 17 samples, then a golden-section search in the bracket around it.
  double best_s = std::clamp(near_s, kLo, kHi), best_d = distance(best_s);
  constexpr int kSamples = 16;
  for (int i = 0; i <= kSamples; ++i) {
    const double u = kLo + (kHi - kLo) * i / kSamples;
    if (const double d = distance(u); d < best_d) {
      best_d = d;
      best_s = u;
    }
  }
  const double step = (kHi - kLo) / kSamples;
  double lo = std::max(kLo, best_s - step), hi = std::min(kHi, best_s + step);
  constexpr double kGolden = 0.6180339887498949;
  double u1 = hi - kGolden * (hi - lo), u2 = lo + kGolden * (hi - lo);
  double d1 = distance(u1), d2 = distance(u2);
  for (int i = 0; i < 20; ++i) {
    if (d1 < d2) {
      hi = u2;
      u2 = u1;
      d2 = d1;
      u1 = hi - kGolden * (hi - lo);
      d1 = distance(u1);
    } else {
      lo = u1;
      u1 = u2;
      d1 = d2;
      u2 = lo + kGolden * (hi - lo);
      d2 = distance(u2);
    }
  }
  if (d1 < best_d) best_s = u1;
  if (d2 < std::min(best_d, d1)) best_s = u2;
  return best_s;
}

void TetCutter::place_new_cut_points(int first_new_vertex, const CutStepReport& r, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  if (stroke_tris_rest_.empty()) return;
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  for (std::size_t k = 0; k < r.new_vertices.size(); ++k) {
    const int w = first_new_vertex + static_cast<int>(k);
    if (r.new_vertices[k].b < 0 || !on_stroke(w) || material_stroke_distance(rest.col(w)) <= settings_.path_tolerance_mm) continue;
    std::vector<int> copies{w};
    for (std::size_t j = k + 1; j < r.new_vertices.size(); ++j)
      if (r.new_vertices[j].b < 0 && r.new_vertices[j].a == w) copies.push_back(first_new_vertex + static_cast<int>(j));
    place_on_material_stroke(copies, x, v);
  }
}

void TetCutter::place_on_material_stroke(const std::vector<int>& copies, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  if (stroke_tris_rest_.empty() || copies.empty()) return;  // no sweep of this stroke in the material: nothing to move onto
  Eigen::Vector3d target = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  const Eigen::Vector3d from = rest.col(copies.front());
  if (!(material_stroke_distance(from, &target) > 0.5 * settings_.path_tolerance_mm + 1e-9) || !target.allFinite()) return;
  // Every copy goes to the same rest position (the lips coincide at rest, so the tissue's
  // volume is unchanged), and to the place its own side's tissue has for it now: the affine
  // map of the tet of its star that holds the new rest position best (largest smallest
  // weight; outside the star it extrapolates, and can_move_copies bounds the result).
  Eigen::Vector3d rest_new;
  std::vector<Eigen::Vector3d> x_new(copies.size()), v_new(copies.size());
  const auto place = [&](double fraction) {
    rest_new = from + fraction * (target - from);
    for (std::size_t c = 0; c < copies.size(); ++c) {
      double best = -std::numeric_limits<double>::infinity();
      for (int tt : vertex_tets_[static_cast<std::size_t>(copies[c])]) {
        const auto& tet = mesh_.tets[static_cast<std::size_t>(tt)];
        const Eigen::Vector4d w = tet_weights(rest, tet, rest_new);
        if (!w.allFinite() || w.minCoeff() <= best) continue;
        best = w.minCoeff();
        x_new[c].setZero();
        v_new[c].setZero();
        for (int k = 0; k < 4; ++k) {
          x_new[c] += w[k] * x.col(tet[static_cast<std::size_t>(k)]);
          if (v.cols() == x.cols()) v_new[c] += w[k] * v.col(tet[static_cast<std::size_t>(k)]);
        }
      }
      if (!std::isfinite(best)) return false;
    }
    return can_move_copies(copies, rest_new, x_new, x);
  };
  // All the way to the surface, else as far towards it as the tets around allow (the allowed
  // moves form an interval from zero: each bound is linear in the new position, and the star
  // is star-shaped about the vertex), found by bisection to 1/1024 of the distance.
  double allowed = 0.0;
  if (place(1.0)) {
    allowed = 1.0;
  } else {
    double refused = 1.0;
    for (int i = 0; i < 10; ++i) {
      const double f = 0.5 * (allowed + refused);
      (place(f) ? allowed : refused) = f;
    }
    if (allowed == 0.0 || !place(allowed)) return;
  }
  for (std::size_t c = 0; c < copies.size(); ++c) {
    mesh_.rest_positions_World_mm.col(copies[c]) = rest_new;
    x.col(copies[c]) = x_new[c];
    if (v.cols() == x.cols()) v.col(copies[c]) = v_new[c];
  }
}

bool TetCutter::can_move_copies(const std::vector<int>& copies, const Eigen::Vector3d& rest_new, const std::vector<Eigen::Vector3d>& x_new,
                                const Eigen::Matrix3Xd& x) const {
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  double rest_before = 0.0, rest_after = 0.0;
  for (std::size_t c = 0; c < copies.size(); ++c) {
    const int w = copies[c];
    for (int tt : vertex_tets_[static_cast<std::size_t>(w)]) {
      const auto& tet = mesh_.tets[static_cast<std::size_t>(tt)];
      // Boundary faces through the vertex must be this stroke's lips: a vertex of the organ's
      // surface moved off it would change the organ.
      for (const auto& fc : kFaces) {
        const int f0 = tet[static_cast<std::size_t>(fc[0])], f1 = tet[static_cast<std::size_t>(fc[1])], f2 = tet[static_cast<std::size_t>(fc[2])];
        if ((f0 != w && f1 != w && f2 != w) || tets_with_face(face_key(f0, f1, f2)) == 2) continue;
        if (!on_stroke(f0) || !on_stroke(f1) || !on_stroke(f2)) return false;
      }
      if (!keeps_a_quarter(tt, w, rest_new, x_new[c], x, /*inverted_may_move=*/true)) return false;
      rest_before += volume6_with(rest, tet, w, rest.col(w));
      rest_after += volume6_with(rest, tet, w, rest_new);
    }
  }
  // The copies' stars together close round the vertex at rest (the lips coincide there): the
  // move keeps the tissue's volume.
  return std::abs(rest_after - rest_before) <= 1e-9 * rest_before;
}

std::string TetCutter::describe_pending() const {
  std::ostringstream out;
  for (int t = 0; t < mesh_.num_tets(); ++t) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    std::ostringstream edges;
    for (const auto& e : kEdges) {
      const auto it = pending_.find(edge_key(tet[static_cast<std::size_t>(e[0])], tet[static_cast<std::size_t>(e[1])]));
      if (it != pending_.end()) edges << ' ' << e[0] << e[1] << '@' << it->second;
    }
    if (edges.tellp() == 0 || complete_pattern(t) != 0) continue;
    out << "tet " << t << (tip_tet_[static_cast<std::size_t>(t)] ? " [tip]" : "") << " vertices";
    for (int w : tet) out << ' ' << w << (on_stroke(w) ? "[cut]" : "") << "(side " << side_[static_cast<std::size_t>(w)] << ')';
    out << " crossings" << edges.str() << '\n';
  }
  // Interior faces with all three vertices on this stroke that are not cut.
  for (int t = 0; t < mesh_.num_tets(); ++t) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& fc : kFaces) {
      const auto key = face_key(tet[static_cast<std::size_t>(fc[0])], tet[static_cast<std::size_t>(fc[1])], tet[static_cast<std::size_t>(fc[2])]);
      if (!on_stroke(key[0]) || !on_stroke(key[1]) || !on_stroke(key[2])) continue;
      int pair[2] = {-1, -1};
      if (tets_with_face(key, pair) != 2 || pair[0] != t) continue;
      out << "face " << key[0] << ' ' << key[1] << ' ' << key[2] << (cut_faces_.count(key) ? " [cut]" : "") << " between";
      for (int k = 0; k < 2; ++k) {
        out << " tet " << pair[k] << " (";
        for (int w : mesh_.tets[static_cast<std::size_t>(pair[k])])
          out << ' ' << w << (on_stroke(w) ? "*" : "") << ':' << side_[static_cast<std::size_t>(w)];
        out << ')';
      }
      out << '\n';
    }
  }
  return out.str();
}

int TetCutter::stroke_side(int w, const Eigen::Matrix3Xd& x, double cone, bool within_reach) const {
  return surface_side(stroke_tris_, stroke_chunks_, x, w, cone, within_reach);
}

int TetCutter::surface_side(const std::vector<Triangle>& tris, const std::vector<StrokeChunk>& chunks, const Eigen::Matrix3Xd& x, int w,
                            double cone, bool within_reach) const {
  // The nearest point of the whole stroke's swept surface so far (every frame's triangles, as
  // swept; frames whose box is farther than the best distance found are skipped): the side of
  // its triangle's plane when w lies about across from it (distance to the triangle at most
  // `cone` times the distance to its plane; near the surface's border, the blade's ends or the
  // sweep's front, it may not) and within one edge of a tet around w.
  if (tris.empty()) return 0;
  const Eigen::Vector3d p = x.col(w);
  double best = 1e300;
  int nearest = -1;
  for (const auto& chunk : chunks) {
    const Eigen::Vector3d gap = (chunk.box.min - p).cwiseMax(p - chunk.box.max).cwiseMax(0.0);
    if (gap.norm() >= best) continue;
    for (int i = chunk.begin; i < chunk.end; ++i) {
      const double d = point_triangle_distance(p, tris[static_cast<std::size_t>(i)]);
      if (d < best) {
        best = d;
        nearest = i;
      }
    }
  }
  if (nearest < 0) return 0;
  const Triangle& near = tris[static_cast<std::size_t>(nearest)];
  // The plane: through the nearest point, normal to the stroke's surface averaged (by area,
  // as oriented) over the triangles within max(distance, 1 mm) of that point. One frame's
  // strip can be far from the surface's direction: when the tissue moves across the blade
  // about as fast as the blade (a swaying organ) the strip between the carried previous
  // blade and the new one turns by up to 90 degrees, or reverses; a vertex 10 mm away took
  // its side from such a strip's plane (a hole in the liver ring with XPBD).
  Eigen::Vector3d q;
  point_triangle_distance(p, near, &q);
  const double radius = std::max(best, 1.0);
  Eigen::Vector3d n_sum = Eigen::Vector3d::Zero();
  for (const auto& chunk : chunks) {
    const Eigen::Vector3d gap = (chunk.box.min - q).cwiseMax(q - chunk.box.max).cwiseMax(0.0);
    if (gap.norm() > radius) continue;
    for (int i = chunk.begin; i < chunk.end; ++i) {
      const Triangle& tri = tris[static_cast<std::size_t>(i)];
      if (point_triangle_distance(q, tri) <= radius) n_sum += 0.5 * (tri.b - tri.a).cross(tri.c - tri.a);
    }
  }
  const Eigen::Vector3d normal = n_sum.squaredNorm() > 0.0 ? Eigen::Vector3d(n_sum.normalized()) : unit_normal(near);
  const double d = normal.dot(p - q);
  double reach2 = 0.0;
  for (int tt : vertex_tets_[static_cast<std::size_t>(w)])
    for (int u : mesh_.tets[static_cast<std::size_t>(tt)]) reach2 = std::max(reach2, (x.col(u) - p).squaredNorm());
  if (std::abs(d) > settings_.vertex_tolerance_mm && best <= cone * std::abs(d) &&
      (!within_reach || (best * best <= reach2 && (cone > kEagerCone || best <= settings_.side_distance_mm))))
    return d > 0 ? 1 : -1;
  return 0;
}

CutStepReport TetCutter::finish_stroke(Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  finishing_ = true;
  SweptSurface none;
  none.from.tip_World_mm = none.to.tip_World_mm = Eigen::Vector3d::Zero();
  none.from.heel_World_mm = none.to.heel_World_mm = Eigen::Vector3d::Zero();
  CutStepReport r;
  try {
    r = step(none, x, v);
  } catch (...) {
    finishing_ = false;
    throw;
  }
  finishing_ = false;
  return r;
}

void TetCutter::watch_tet(int t) {
  if (static_cast<std::size_t>(t) >= watched_.size()) watched_.resize(mesh_.tets.size(), 0);
  if (watched_[static_cast<std::size_t>(t)]) return;
  for (int w : mesh_.tets[static_cast<std::size_t>(t)])
    if (on_stroke(w)) {
      watched_[static_cast<std::size_t>(t)] = 1;
      watch_.push_back(t);
      return;
    }
}

void TetCutter::update_surface() { mesh_.surface_tris = boundary_faces(mesh_); }

void TetCutter::begin_stroke() {
  ++stroke_;
  pending_.clear();
  pending_normal_.clear();
  stroke_tris_.clear();
  stroke_chunks_.clear();
  stroke_tris_rest_.clear();
  stroke_chunks_rest_.clear();
  for (int w : sided_) side_[static_cast<std::size_t>(w)] = 0;
  sided_.clear();
  std::fill(tip_tet_.begin(), tip_tet_.end(), 0);
  std::fill(flat_side_.begin(), flat_side_.end(), 0);
  undecided_faces_.clear();
  for (int t : watch_) watched_[static_cast<std::size_t>(t)] = 0;
  watch_.clear();
}

std::vector<Aabb> TetCutter::family_boxes(const Eigen::Matrix3Xd& x) const {
  std::vector<Aabb> boxes(family_.size());
  for (std::size_t f = 0; f < family_.size(); ++f)
    for (int t : family_[f])
      for (int v : mesh_.tets[static_cast<std::size_t>(t)]) boxes[f].extend(Eigen::Vector3d(x.col(v)));
  return boxes;
}

std::vector<int> TetCutter::tets_with_edge(int a, int b) const {
  std::vector<int> out;
  for (int t : vertex_tets_[static_cast<std::size_t>(a)]) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    if (std::find(tet.begin(), tet.end(), b) != tet.end()) out.push_back(t);
  }
  return out;
}

int TetCutter::tets_with_face(const std::array<int, 3>& f, int* tets) const {
  int n = 0;
  for (int t : vertex_tets_[static_cast<std::size_t>(f[0])]) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    if (std::find(tet.begin(), tet.end(), f[1]) != tet.end() && std::find(tet.begin(), tet.end(), f[2]) != tet.end()) {
      if (tets && n < 2) tets[n] = t;
      ++n;
    }
  }
  return n;
}

int TetCutter::complete_pattern(int t) const {
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  bool zero[4];
  for (int i = 0; i < 4; ++i) zero[i] = on_stroke(tet[static_cast<std::size_t>(i)]);
  int crossed = 0;
  for (int e = 0; e < 6; ++e) {
    const int i = kEdges[e][0], j = kEdges[e][1];
    if (zero[i] || zero[j]) continue;
    if (pending_.count(edge_key(tet[static_cast<std::size_t>(i)], tet[static_cast<std::size_t>(j)]))) crossed |= 1 << e;
  }
  if (crossed == 0) return 0;
  int free_vertices[4], k = 0;
  for (int i = 0; i < 4; ++i)
    if (!zero[i]) free_vertices[k++] = i;
  // Sides: the first free vertex is +, every assignment of the others (both sides non-empty
  // when some edge is crossed).
  for (int mask = 0; mask < (1 << (k - 1)); ++mask) {
    int side[4] = {0, 0, 0, 0};
    side[free_vertices[0]] = 1;
    for (int m = 1; m < k; ++m) side[free_vertices[m]] = (mask >> (m - 1)) & 1 ? -1 : 1;
    int pattern = 0;
    for (int e = 0; e < 6; ++e) {
      const int i = kEdges[e][0], j = kEdges[e][1];
      if (side[i] != 0 && side[j] != 0 && side[i] != side[j]) pattern |= 1 << e;
    }
    if (pattern != 0 && pattern == crossed) return crossed;
  }
  // The sides of the free vertices (known for this stroke) give the pattern; crossings
  // recorded on other edges (the tissue moved between frames) are left to the other tets.
  const int by_sides = side_pattern(t);
  if (by_sides != 0 && (by_sides & crossed) == by_sides) return by_sides;
  return 0;
}

int TetCutter::side_pattern(int t) const {
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  int side[4];
  bool plus = false, minus = false;
  for (int i = 0; i < 4; ++i) {
    const int w = tet[static_cast<std::size_t>(i)];
    side[i] = on_stroke(w) ? 0 : side_[static_cast<std::size_t>(w)];
    if (!on_stroke(w) && side[i] == 0) return 0;  // a free vertex without a side
    plus |= side[i] > 0;
    minus |= side[i] < 0;
  }
  if (!plus || !minus) return 0;
  int pattern = 0;
  for (int e = 0; e < 6; ++e)
    if (side[kEdges[e][0]] * side[kEdges[e][1]] < 0) pattern |= 1 << e;
  return pattern;
}

double TetCutter::stroke_distance(const Eigen::Vector3d& p) const { return surface_distance(stroke_tris_, stroke_chunks_, p, nullptr); }

bool TetCutter::complete_from_sides(int t, const Eigen::Matrix3Xd& x, CutStepReport& r) {
  const int pattern = side_pattern(t);
  if (pattern == 0) return false;
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  bool recorded = false;
  for (int e = 0; e < 6; ++e) recorded |= pending_.count(edge_key(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])])) > 0;
  std::vector<Eigen::Vector3d> points;
  for (int w : tet)
    if (on_stroke(w)) points.push_back(x.col(w));
  std::vector<int> missing;
  for (int e = 0; e < 6; ++e) {
    if (!(pattern & (1 << e))) continue;
    const int a = tet[static_cast<std::size_t>(kEdges[e][0])], b = tet[static_cast<std::size_t>(kEdges[e][1])];
    const auto it = pending_.find(edge_key(a, b));
    if (it == pending_.end()) {
      missing.push_back(e);
    } else {
      const int lo = std::min(a, b), hi = std::max(a, b);
      points.push_back((1 - it->second) * x.col(lo) + it->second * x.col(hi));
    }
  }
  if (missing.empty() || points.empty()) return false;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : points) centre += p;
  centre /= static_cast<double>(points.size());
  // The plane's normal: fitted through three or more points; otherwise the cut's normal at
  // the tet's vertices on the cut (or the sweep's at its recorded crossings), else the
  // stroke's surface nearest to the points (a curved cut: the last sweep's normal can be far).
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (int w : tet)
    if (on_stroke(w) && cut_normal_[static_cast<std::size_t>(w)].squaredNorm() > 0.5)
      normal += normal.dot(cut_normal_[static_cast<std::size_t>(w)]) < 0 ? Eigen::Vector3d(-cut_normal_[static_cast<std::size_t>(w)]) : cut_normal_[static_cast<std::size_t>(w)];
  for (const auto& e : kEdges) {
    const auto it = pending_normal_.find(edge_key(tet[static_cast<std::size_t>(e[0])], tet[static_cast<std::size_t>(e[1])]));
    if (it != pending_normal_.end()) normal += normal.dot(it->second) < 0 ? Eigen::Vector3d(-it->second) : it->second;
  }
  if (normal.squaredNorm() > 1e-12) {
    normal.normalize();
  } else if (!stroke_tris_.empty()) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (const auto& p : points) c += p / static_cast<double>(points.size());
    int nearest = 0;
    sweep_distance(stroke_tris_, c, &nearest);
    normal = unit_normal(stroke_tris_[static_cast<std::size_t>(nearest)]);
  } else {
    normal = last_normal_;
  }
  if (points.size() >= 3) {
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const auto& p : points) cov += (p - centre) * (p - centre).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
    if (eig.eigenvalues()[1] > 1e-12 * std::max(1e-300, eig.eigenvalues()[2])) normal = eig.eigenvectors().col(0);
  }
  // A tet with no crossing recorded (its vertices on the cut and sides only: a crossing
  // missed between two frames' strips) is completed only where the stroke really swept: each
  // new point within the tissue's motion since (the distance of the tet's vertices on the
  // cut from the stroke's surface as swept) plus path_tolerance_mm of that surface, and
  // within the same of the surface in the material (issue 20: when the grasper moves the
  // tissue, tets the blade never crossed arrive where it swept seconds earlier; their sides
  // call for a cut, the surface as swept is near, the material says it never passed there).
  // A crack front (the blade's end inside the tissue) is not extended.
  // The reach from a distance to the surface: twice the farthest of the tet's vertices on the
  // cut, plus the tolerances. The one in the material (the vertices at rest) is taken once,
  // when a check needs it.
  const auto reach_from = [&](const auto& distance_of_vertex) {
    double d = 0.0;
    for (int w : tet)
      if (on_stroke(w)) d = std::max(d, distance_of_vertex(w));
    return 2.0 * d + settings_.path_tolerance_mm + settings_.vertex_tolerance_mm;
  };
  double reach_material = -1.0;
  const auto material_reach = [&] {
    if (reach_material < 0.0)
      reach_material = reach_from([&](int w) { return material_stroke_distance(mesh_.rest_positions_World_mm.col(w)); });
    return reach_material;
  };
  const double reach = recorded ? -1.0 : reach_from([&](int w) { return stroke_distance(x.col(w)); });
  std::vector<std::pair<EdgeKey, double>> added;
  for (int e : missing) {
    const int a = std::min(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])]);
    const int b = std::max(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])]);
    const double d0 = normal.dot(x.col(a) - centre), d1 = normal.dot(x.col(b) - centre);
    // On the plane (the recorded points lie on the swept surface), no closer than 1 % of the
    // edge to an end; a plane that misses the edge (the sides say it is crossed) gives the
    // point of the edge nearest to it (the deviation is measured below).
    double s = d0 != d1 ? std::clamp(d0 / (d0 - d1), 0.01, 0.99) : 0.5;
    // Where the edge crosses the stroke's surface in the material, when it does (the tissue
    // may have moved since the blade passed; on a curved cut the plane through the tet's
    // points on the cut is a chord).
    double crossing = -1.0;
    const bool on_material = material_crossing(a, b, s, crossing);
    if (!on_material && reach >= 0.0) {
      crossing = world_stroke_crossing(a, b, s, x);  // else where it crosses the surface as swept
      if (crossing < 0.0) {                           // else on the plane, near enough to both
        const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
        if (stroke_distance((1 - s) * x.col(a) + s * x.col(b)) > reach) return false;
        if (!stroke_tris_rest_.empty() && material_stroke_distance((1 - s) * rest.col(a) + s * rest.col(b)) > material_reach()) return false;
      }
    }
    if (crossing >= 0.0) s = std::clamp(crossing, 0.01, 0.99);
    // An edge the surface in the material does not cross: its point nearest to that surface
    // (the plane through the tet's points and the surface as swept are World approximations;
    // after the tissue moved they can lie far from where the blade went in the material).
    if (!on_material && !stroke_tris_rest_.empty()) {
      s = nearest_on_material_stroke(a, b, s);
      // Mid-stroke, a point far from where the blade went in the material waits (the tet is
      // looked at again next step, and completed at the stroke's end): the sides call for a
      // crossing the surface in the material has not reached yet (issue 20: the 15 mm curve of
      // GraspCutting/RefinedTightCurve got points 7.6 and 8.0 mm off the path at s = 1.5, 3).
      // Farther than the material reach and kCompletionWait_mm: a smaller floor (0 and 0.5 mm
      // tried) left the bundled ring joined with XPBD (RingInSession): points 0.5-2 mm off the
      // path close it there; the bound on any cut vertex is 3 mm.
      constexpr double kCompletionWait_mm = 2.0;
      if (!finishing_ && material_stroke_distance((1 - s) * mesh_.rest_positions_World_mm.col(a) +
                                                  s * mesh_.rest_positions_World_mm.col(b)) > std::max(material_reach(), kCompletionWait_mm))
        return false;
    }
    added.emplace_back(edge_key(a, b), s);
  }
  for (std::size_t i = 0; i < missing.size(); ++i) {
    const int e = missing[i];
    const int a = std::min(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])]);
    const int b = std::max(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])]);
    const double s = added[i].second;
    const Eigen::Vector3d p = (1 - s) * x.col(a) + s * x.col(b);
    r.max_completion_deviation_mm = std::max(r.max_completion_deviation_mm, std::abs(normal.dot(p - centre)));
    ++r.cut_points;
    pending_[edge_key(a, b)] = s;
    pending_normal_.erase(edge_key(a, b));
  }
  return true;
}

bool TetCutter::can_move(int w, const Eigen::Vector3d& rest_new, const Eigen::Vector3d& x_new, const Eigen::Matrix3Xd& x) const {
  // Interior vertices only: moving a vertex of the organ's surface would change the tissue's
  // shape and volume.
  const std::vector<int>& star = vertex_tets_[static_cast<std::size_t>(w)];
  for (int tt : star) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(tt)];
    for (const auto& fc : kFaces) {
      const int f0 = tet[static_cast<std::size_t>(fc[0])], f1 = tet[static_cast<std::size_t>(fc[1])], f2 = tet[static_cast<std::size_t>(fc[2])];
      if ((f0 == w || f1 == w || f2 == w) && tets_with_face(face_key(f0, f1, f2)) != 2) return false;
    }
  }
  for (int tt : star)
    if (!keeps_a_quarter(tt, w, rest_new, x_new, x, /*inverted_may_move=*/false)) return false;
  return true;
}

bool keeps_a_quarter_of_volume(double volume6_before, double volume6_after) {
  return volume6_before >= 0.0 ? volume6_after >= 0.25 * volume6_before : (volume6_after >= volume6_before && volume6_after <= 0.0);
}

bool TetCutter::keeps_a_quarter(int tt, int w, const Eigen::Vector3d& rest_new, const Eigen::Vector3d& x_new, const Eigen::Matrix3Xd& x,
                                bool inverted_may_move) const {
  const auto& tet = mesh_.tets[static_cast<std::size_t>(tt)];
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  return keeps_a_quarter_of_volume(volume6_with(rest, tet, w, rest.col(w)), volume6_with(rest, tet, w, rest_new)) &&
         (inverted_may_move ? keeps_a_quarter_of_volume(volume6_with(x, tet, w, x.col(w)), volume6_with(x, tet, w, x_new))
                            : volume6_with(x, tet, w, x_new) >= 0.25 * volume6_with(x, tet, w, x.col(w)));
}

bool TetCutter::move_vertex(int w, int o, double t, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r) {
  const Eigen::Vector3d rest_new = (1 - t) * mesh_.rest_positions_World_mm.col(w) + t * mesh_.rest_positions_World_mm.col(o);
  const Eigen::Vector3d x_new = (1 - t) * x.col(w) + t * x.col(o);
  if (!can_move(w, rest_new, x_new, x)) return false;
  const std::vector<int>& star = vertex_tets_[static_cast<std::size_t>(w)];
  mesh_.rest_positions_World_mm.col(w) = rest_new;
  x.col(w) = x_new;
  if (v.cols() > w) v.col(w) = (1 - t) * v.col(w) + t * v.col(o);
  // Crossings recorded on its edges referred to the old position.
  for (int tt : star) {
    for (int u : mesh_.tets[static_cast<std::size_t>(tt)])
      if (u != w) {
        pending_.erase(edge_key(w, u));
        pending_normal_.erase(edge_key(w, u));
      }
    r.changed_tets.push_back(tt);
  }
  ++r.vertices_moved;
  return true;
}

int TetCutter::add_vertex(const VertexOrigin& o, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r) {
  const int id = mesh_.num_vertices();
  auto lerp = [&](const Eigen::Matrix3Xd& m) -> Eigen::Vector3d {
    if (o.b < 0) return m.col(o.a);
    return (1.0 - o.t) * m.col(o.a) + o.t * m.col(o.b);
  };
  const Eigen::Vector3d rest = lerp(mesh_.rest_positions_World_mm);
  mesh_.rest_positions_World_mm.conservativeResize(Eigen::NoChange, id + 1);
  mesh_.rest_positions_World_mm.col(id) = rest;
  const Eigen::Vector3d xi = lerp(x), vi = v.cols() > o.a ? lerp(v) : Eigen::Vector3d::Zero();
  x.conservativeResize(Eigen::NoChange, id + 1);
  x.col(id) = xi;
  if (v.cols() == id) {
    v.conservativeResize(Eigen::NoChange, id + 1);
    v.col(id) = vi;
  }
  vertex_tets_.emplace_back();
  on_cut_.push_back(o.b < 0 ? on_cut_[static_cast<std::size_t>(o.a)] : stroke_);
  cut_normal_.push_back(o.b < 0 ? cut_normal_[static_cast<std::size_t>(o.a)] : Eigen::Vector3d::Zero());
  side_.push_back(o.b < 0 ? side_[static_cast<std::size_t>(o.a)] : 0);
  if (side_.back() != 0) sided_.push_back(id);
  r.new_vertices.push_back(o);
  ++r.vertices_added;
  return id;
}

void TetCutter::replace_vertex(int tet, int from, int to) {
  auto& t = mesh_.tets[static_cast<std::size_t>(tet)];
  for (int& v : t)
    if (v == from) v = to;
  auto& lf = vertex_tets_[static_cast<std::size_t>(from)];
  lf.erase(std::remove(lf.begin(), lf.end(), tet), lf.end());
  vertex_tets_[static_cast<std::size_t>(to)].push_back(tet);
}

void TetCutter::split_edge(int a, int b, double t_ab, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r,
                           std::vector<int>& touched) {
  const std::vector<int> around = tets_with_edge(a, b);
  if (around.empty()) return;
  const int m = add_vertex({a, b, t_ab}, x, v, r);
  {
    // The cut's normal at the new point: the crossing's, or the ends' on the cut (an edge
    // inside the cut split at its mid-point).
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    const auto in = pending_normal_.find(edge_key(a, b));
    if (in != pending_normal_.end()) {
      n = in->second;
      pending_normal_.erase(in);
    } else if (on_stroke(a) && on_stroke(b)) {
      n = cut_normal_[static_cast<std::size_t>(a)] + cut_normal_[static_cast<std::size_t>(b)];
      n = n.squaredNorm() > 1e-12 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    }
    cut_normal_[static_cast<std::size_t>(m)] = n;
  }
  ++r.edges_split;
  for (int t : around) {
    // Child 1 keeps index t with b -> m; child 2 is t with a -> m. Both keep the orientation
    // (m lies strictly inside the edge).
    std::array<int, 4> child2 = mesh_.tets[static_cast<std::size_t>(t)];
    for (int& w : child2)
      if (w == a) w = m;
    replace_vertex(t, b, m);
    const int n = mesh_.num_tets();
    mesh_.tets.push_back(child2);
    mesh_.tet_region.push_back(mesh_.tet_region[static_cast<std::size_t>(t)]);
    origin_.push_back(origin_[static_cast<std::size_t>(t)]);
    tip_tet_.push_back(tip_tet_[static_cast<std::size_t>(t)]);
    flat_side_.push_back(0);
    family_[static_cast<std::size_t>(origin_[static_cast<std::size_t>(t)])].push_back(n);
    for (int w : child2) vertex_tets_[static_cast<std::size_t>(w)].push_back(n);
    ++r.tets_added;
    touched.push_back(t);
    touched.push_back(n);
  }
}

bool TetCutter::untouched(int t) const {
  if (!refinable(t)) return false;
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  for (const auto& e : kEdges)
    if (pending_.count(edge_key(tet[static_cast<std::size_t>(e[0])], tet[static_cast<std::size_t>(e[1])]))) return false;
  return true;
}

bool TetCutter::refinable(int t) const {
  for (int w : mesh_.tets[static_cast<std::size_t>(t)])
    if (on_cut_[static_cast<std::size_t>(w)] != 0) return false;
  return true;
}

void TetCutter::record_material_crossings(int m) {
  std::vector<int> others;
  for (int t : vertex_tets_[static_cast<std::size_t>(m)])
    for (int w : mesh_.tets[static_cast<std::size_t>(t)])
      if (w != m && std::find(others.begin(), others.end(), w) == others.end()) others.push_back(w);
  for (int w : others) {
    const EdgeKey key = edge_key(m, w);
    double s = 0.0;
    if (pending_.count(key) || !material_crossing(m, w, 0.5, s)) continue;
    pending_[key] = s;
    pending_normal_.erase(key);
  }
}

void TetCutter::refine_ahead(const std::vector<Triangle>& tris, std::vector<int>& candidates, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                             CutStepReport& r) {
  if (!(settings_.chord_sagitta_mm > 0.0) || tris.empty()) return;
  // A chord of length L across a cut of radius R lies L^2 / (8 R) off it at its middle.
  const double curvature = material_curvature_per_mm();
  if (!(curvature > 0.0)) return;  // a straight cut (so far): a plane cuts any tet exactly
  const double lmax = std::max(settings_.min_refined_edge_mm, std::sqrt(8.0 * settings_.chord_sagitta_mm / curvature));
  const double lmax2 = lmax * lmax;
  const Eigen::Matrix3Xd& rest = mesh_.rest_positions_World_mm;
  auto length2 = [&](int a, int b) { return (rest.col(a) - rest.col(b)).squaredNorm(); };
  // The sweep enters tet t: a blade end passed through it, or it crosses one of its edges.
  auto entered = [&](int t) {
    if (tip_tet_[static_cast<std::size_t>(t)]) return true;
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& e : kEdges)
      for (const auto& tri : tris) {
        double s = 0.0;
        if (segment_triangle_intersection(x.col(tet[static_cast<std::size_t>(e[0])]), x.col(tet[static_cast<std::size_t>(e[1])]), tri, s)) return true;
      }
    return false;
  };
  // The longest edge of tet t.
  auto longest = [&](int t) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    std::pair<double, EdgeKey> best{-1.0, 0};
    for (const auto& e : kEdges) {
      const int a = tet[static_cast<std::size_t>(e[0])], b = tet[static_cast<std::size_t>(e[1])];
      best = std::max(best, {length2(a, b), edge_key(a, b)});
    }
    return best;
  };
  // Longest edge first, and an edge only once it is the longest of every tet around it
  // (Rivara's longest-edge bisection: the tets' shapes stay within a bounded set of classes).
  std::priority_queue<std::pair<double, EdgeKey>> queue;
  auto offer = [&](int t) {
    if (!refinable(t) || !entered(t)) return;
    const auto l = longest(t);
    if (l.first > lmax2) queue.push(l);
  };
  for (int t : candidates) offer(t);
  std::vector<int> touched;
  std::unordered_set<EdgeKey> refused;  // cannot be bisected this frame (a tet around is cut, or a longer edge is refused)
  while (!queue.empty() && r.edges_refined < settings_.max_refinements_per_step) {
    const auto [len2, key] = queue.top();
    queue.pop();
    const auto [a, b] = edge_ends(key);
    const std::vector<int> around = tets_with_edge(a, b);
    if (around.empty()) continue;  // bisected already
    // Bisected only where it is the longest edge of every tet around it (else those tets'
    // longest edges go first; where one of them cannot be bisected, neither is this edge):
    // bisecting a shorter edge can flatten tets without end (a vertex chain converging on
    // the longer edge).
    // An edge with a crossing recorded is not bisected (the crossing would have to move to
    // a half); the tets around it are refined by their other edges.
    bool can = !refused.count(key) && !pending_.count(key), deferred = false;
    bool recorded = false;  // a tet around has crossings recorded: its new edges take theirs from the material
    for (int t : around) {
      if (!can) break;
      recorded = recorded || !untouched(t);
      if (!refinable(t)) {
        can = false;
        break;
      }
      const auto l = longest(t);
      if (l.first <= len2 * (1.0 + 1e-12)) continue;
      const auto [p, q] = edge_ends(l.second);
      const std::vector<int> around_l = tets_with_edge(p, q);
      if (refused.count(l.second) || pending_.count(l.second) ||
          !std::all_of(around_l.begin(), around_l.end(), [&](int u) { return refinable(u); })) {
        can = false;
        break;
      }
      queue.push(l);
      deferred = true;
    }
    if (!can) {
      refused.insert(key);
      continue;
    }
    if (deferred) {
      queue.push({len2, key});
      continue;
    }
    touched.clear();
    split_edge(a, b, 0.5, x, v, r, touched);
    const int m = mesh_.num_vertices() - 1;
    on_cut_[static_cast<std::size_t>(m)] = 0;  // a vertex of the mesh, not of the cut
    cut_normal_[static_cast<std::size_t>(m)] = Eigen::Vector3d::Zero();
    if (recorded) record_material_crossings(m);
    ++r.edges_refined;
    r.changed_tets.insert(r.changed_tets.end(), touched.begin(), touched.end());
    candidates.insert(candidates.end(), touched.begin(), touched.end());
    for (int t : touched) offer(t);
  }
}

bool TetCutter::ring_is_cut(int p, int q) const {
  const std::vector<int> ring = tets_with_edge(p, q);
  const int k = static_cast<int>(ring.size());
  if (k < 2) return false;
  std::vector<int> parent(static_cast<std::size_t>(k));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) i = parent[static_cast<std::size_t>(i)];
    return i;
  };
  for (int i = 0; i < k; ++i)
    for (int j = i + 1; j < k; ++j) {
      const auto& ti = mesh_.tets[static_cast<std::size_t>(ring[static_cast<std::size_t>(i)])];
      const auto& tj = mesh_.tets[static_cast<std::size_t>(ring[static_cast<std::size_t>(j)])];
      for (int w : ti) {
        if (w == p || w == q || std::find(tj.begin(), tj.end(), w) == tj.end()) continue;
        if (!cut_faces_.count(face_key(p, q, w))) parent[static_cast<std::size_t>(find(i))] = find(j);
      }
    }
  int groups = 0;
  for (int i = 0; i < k; ++i) groups += find(i) == i;
  return groups > 1;
}

int TetCutter::separate_vertex(int vertex, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r) {
  const std::vector<int> star = vertex_tets_[static_cast<std::size_t>(vertex)];
  const int k = static_cast<int>(star.size());
  if (k < 2) return 0;
  std::vector<int> parent(static_cast<std::size_t>(k));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int i) {
    while (parent[static_cast<std::size_t>(i)] != i) i = parent[static_cast<std::size_t>(i)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(i)])];
    return i;
  };
  for (int i = 0; i < k; ++i) {
    const auto& ti = mesh_.tets[static_cast<std::size_t>(star[static_cast<std::size_t>(i)])];
    for (int j = i + 1; j < k; ++j) {
      const auto& tj = mesh_.tets[static_cast<std::size_t>(star[static_cast<std::size_t>(j)])];
      int shared[3], n = 0;
      for (int a : ti)
        if (a != vertex && std::find(tj.begin(), tj.end(), a) != tj.end() && n < 3) shared[n++] = a;
      if (n != 2) continue;  // no common face through the vertex
      if (cut_faces_.count(face_key(vertex, shared[0], shared[1]))) continue;
      parent[static_cast<std::size_t>(find(i))] = find(j);
    }
  }
  std::vector<int> group(static_cast<std::size_t>(k));
  std::vector<int> roots;
  for (int i = 0; i < k; ++i) {
    const int root = find(i);
    auto it = std::find(roots.begin(), roots.end(), root);
    group[static_cast<std::size_t>(i)] = static_cast<int>(it - roots.begin());
    if (it == roots.end()) roots.push_back(root);
  }
  if (roots.size() < 2) return 0;
  for (std::size_t g = 1; g < roots.size(); ++g) {
    const int copy = add_vertex({vertex, -1, 0.0}, x, v, r);
    for (int i = 0; i < k; ++i)
      if (group[static_cast<std::size_t>(i)] == static_cast<int>(g)) {
        replace_vertex(star[static_cast<std::size_t>(i)], vertex, copy);
        r.changed_tets.push_back(star[static_cast<std::size_t>(i)]);
      }
  }
  return static_cast<int>(roots.size()) - 1;
}

void TetCutter::mark_tip_tets(const SweptSurface& sweep, const std::vector<int>& candidates, const Eigen::Matrix3Xd& x) {
  const int n = std::max(1, sweep.strips);
  const bool advected = static_cast<int>(sweep.from_points.size()) == n + 1;
  const Eigen::Vector3d tip0 = advected ? sweep.from_points.front() : sweep.from.tip_World_mm;
  const Eigen::Vector3d heel0 = advected ? sweep.from_points.back() : sweep.from.heel_World_mm;
  const std::array<std::pair<Eigen::Vector3d, Eigen::Vector3d>, 2> paths{{{tip0, sweep.to.tip_World_mm}, {heel0, sweep.to.heel_World_mm}}};
  for (int t : candidates) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& [p0, p1] : paths) {
      bool hit = false;
      for (const auto& fc : kFaces) {
        double s = 0;
        if (segment_triangle_intersection(p0, p1, {x.col(tet[static_cast<std::size_t>(fc[0])]), x.col(tet[static_cast<std::size_t>(fc[1])]),
                                                   x.col(tet[static_cast<std::size_t>(fc[2])])}, s)) {
          hit = true;
          break;
        }
      }
      if (!hit) hit = tet_weights(x, tet, p1).minCoeff() >= 0;  // the blade end inside the tet
      if (hit) tip_tet_[static_cast<std::size_t>(t)] = 1;
    }
  }
}

// Step 5 of a frame (docs/cut.md): every vertex of a cut face whose tets fall apart into groups
// is duplicated; edges inside the cut whose ends stay joined are split at their mid-points.
void TetCutter::separate_along_cut(Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v, CutStepReport& r) {
  if (cut_faces_.empty()) return;
  std::vector<int> vertices;
  for (const auto& key : cut_faces_) vertices.insert(vertices.end(), key.begin(), key.end());
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  std::vector<std::pair<int, int>> edges;
  for (const auto& key : cut_faces_)
    for (int i = 0; i < 3; ++i) edges.emplace_back(std::min(key[static_cast<std::size_t>(i)], key[static_cast<std::size_t>((i + 1) % 3)]),
                                                   std::max(key[static_cast<std::size_t>(i)], key[static_cast<std::size_t>((i + 1) % 3)]));
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  for (int w : vertices) separate_vertex(w, x, v, r);
  // Also the edges of every tet that changed (a second cut meeting an earlier one).
  for (int t : r.changed_tets) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& e : kEdges) {
      const int p = tet[static_cast<std::size_t>(e[0])], q = tet[static_cast<std::size_t>(e[1])];
      if (on_cut(p) && on_cut(q)) edges.emplace_back(std::min(p, q), std::max(p, q));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  // An edge inside the cut whose two ends stay joined (the cut reaches the edge from both
  // sides but not past its ends) would be shared by both lips (non-manifold): split it at
  // its mid-point and separate the new vertex.
  for (const auto& [p, q] : edges) {
    if (!ring_is_cut(p, q)) continue;
    const int m = mesh_.num_vertices();
    std::vector<int> touched;
    split_edge(p, q, 0.5, x, v, r, touched);
    r.changed_tets.insert(r.changed_tets.end(), touched.begin(), touched.end());
    std::vector<std::array<int, 3>> moved;
    for (auto it = cut_faces_.begin(); it != cut_faces_.end();) {
      const auto& face = *it;
      if (std::find(face.begin(), face.end(), p) != face.end() && std::find(face.begin(), face.end(), q) != face.end()) {
        const int other = face[0] != p && face[0] != q ? face[0] : (face[1] != p && face[1] != q ? face[1] : face[2]);
        moved.push_back(face_key(p, m, other));
        moved.push_back(face_key(m, q, other));
        it = cut_faces_.erase(it);
      } else {
        ++it;
      }
    }
    cut_faces_.insert(moved.begin(), moved.end());
    // The mid-point of a chord lies off a curved cut by its sagitta: separated, then it
    // and its copies moved onto the surface the blade swept in the material, as far as the
    // tets around allow.
    const int before = mesh_.num_vertices();
    separate_vertex(m, x, v, r);
    std::vector<int> copies{m};
    for (int c = before; c < mesh_.num_vertices(); ++c) copies.push_back(c);
    place_on_material_stroke(copies, x, v);
  }
  for (auto it = cut_faces_.begin(); it != cut_faces_.end();) {
    if (tets_with_face(*it) < 2) {
      ++r.faces_separated;
      it = cut_faces_.erase(it);
    } else {
      ++it;
    }
  }
}

// Step 4 (docs/cut.md): tets among check whose recorded crossings separate them completely
// have their crossed edges split (every tet around such an edge bisected: conforming),
// repeated while splits complete more; cut pieces are marked in cut_piece.
void TetCutter::split_completed(std::vector<int> check, std::vector<char>& cut_piece, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                                CutStepReport& r) {
  for (int round = 0; round < 8 && !check.empty(); ++round) {
    std::set<EdgeKey> to_split;
    for (int t : check) {
      const int pattern = complete_pattern(t);
      if (pattern == 0) continue;
      ++r.tets_cut;
      if (static_cast<std::size_t>(t) >= cut_piece.size()) cut_piece.resize(static_cast<std::size_t>(t) + 1, 0);
      cut_piece[static_cast<std::size_t>(t)] = 1;
      const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
      for (int e = 0; e < 6; ++e)
        if (pattern & (1 << e)) to_split.insert(edge_key(tet[static_cast<std::size_t>(kEdges[e][0])], tet[static_cast<std::size_t>(kEdges[e][1])]));
    }
    std::vector<int> touched;
    for (EdgeKey key : to_split) {
      const auto [a, b] = edge_ends(key);
      const auto it = pending_.find(key);
      if (it == pending_.end()) continue;
      const double t_ab = it->second;
      pending_.erase(it);
      const std::size_t first_pair = touched.size();
      split_edge(a, b, t_ab, x, v, r, touched);
      // Children inherit the parent's mark (each piece of a cut tet lies on one side).
      cut_piece.resize(mesh_.tets.size(), 0);
      for (std::size_t i = first_pair; i + 1 < touched.size(); i += 2)
        cut_piece[static_cast<std::size_t>(touched[i + 1])] = cut_piece[static_cast<std::size_t>(touched[i])];
    }
    r.changed_tets.insert(r.changed_tets.end(), touched.begin(), touched.end());
    std::sort(touched.begin(), touched.end());
    touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
    check = touched;
  }
}

// Step 4b (docs/cut.md): tets the blade has left with their crossings incomplete, and watched
// tets whose free vertices lie on both sides of the stroke's surface, are completed from the
// stroke's surface in the material and split. Candidates of this frame, and tets made since old_tets,
// are near the blade.
void TetCutter::complete_left_tets(const std::vector<int>& candidates, int old_tets, std::vector<char>& cut_piece, Eigen::Matrix3Xd& x,
                                   Eigen::Matrix3Xd& v, CutStepReport& r) {
  std::vector<char> near(mesh_.tets.size(), 0);
  for (int t : candidates) near[static_cast<std::size_t>(t)] = 1;
  for (std::size_t t = static_cast<std::size_t>(old_tets); t < near.size(); ++t) near[t] = 1;
  std::vector<int> stale;
  for (const auto& [key, param] : pending_) {
    (void)param;
    const auto [a, b] = edge_ends(key);
    for (int t : tets_with_edge(a, b))
      if (!near[static_cast<std::size_t>(t)] && !tip_tet_[static_cast<std::size_t>(t)]) stale.push_back(t);
  }
  // Tets the cut has reached (a vertex on this stroke's cut) are watched until the blade has
  // left them: one whose free vertices lie on both sides of the stroke's surface with no
  // crossing recorded on the edge between them is completed the same way. The tissue moves
  // between frames, so the strip of one frame (started from the previous blade carried with
  // the tissue: a polyline through strips + 1 carried points) and the strip of the last one
  // (straight between the points as they were) leave slivers of material between them that
  // neither swept: an edge crossing the cut there has no crossing (docs/cut.md, "The ring in
  // the running simulation").
  // At the stroke's end every tet round a vertex on this stroke's cut is looked at once
  // (O(vertices + cut), once per stroke): a tet the sweep never reached because the tissue
  // carried it across the blade's path between two frames (an organ recoiling as the cut
  // frees it moved a vertex 1.5 mm across the blade in one frame) is otherwise never
  // watched. Free vertices without a side then get one from the complete surface
  // (45 degrees, within an edge of their tets), as the faces on the cut do. The surface as
  // swept, as everywhere else: taken from the surface in the material instead (issue 20,
  // seventh session) the scene ring following the tumour no longer freed its block with the
  // FEM (RingInSessionLong), and after the curvature fix it changed nothing on the demo's
  // logs (eighth session, docs/cut.md).
  {
    for (int t : candidates) watch_tet(t);
    for (int t : r.changed_tets) watch_tet(t);
    if (finishing_) {
      for (int w = 0; w < mesh_.num_vertices(); ++w)
        if (on_stroke(w))
          for (int t : vertex_tets_[static_cast<std::size_t>(w)]) watch_tet(t);
      for (int t : watch_) {
        if (tip_tet_[static_cast<std::size_t>(t)]) continue;
        for (int w : mesh_.tets[static_cast<std::size_t>(t)]) {
          if (on_stroke(w) || side_[static_cast<std::size_t>(w)] != 0) continue;
          if (const int sd = stroke_side(w, x, kLazyCone); sd != 0) {
            side_[static_cast<std::size_t>(w)] = static_cast<signed char>(sd);
            sided_.push_back(w);
          }
        }
      }
    }
    std::vector<int> keep;
    for (int t : watch_) {
      if (near[static_cast<std::size_t>(t)] || tip_tet_[static_cast<std::size_t>(t)]) {
        keep.push_back(t);
        continue;
      }
      if (side_pattern(t) != 0 || complete_pattern(t) != 0) {
        stale.push_back(t);
        watched_[static_cast<std::size_t>(t)] = 0;
        continue;
      }
      bool unknown = false;
      for (int w : mesh_.tets[static_cast<std::size_t>(t)]) unknown |= !on_stroke(w) && side_[static_cast<std::size_t>(w)] == 0;
      if (unknown && !finishing_) {
        keep.push_back(t);
      } else {
        watched_[static_cast<std::size_t>(t)] = 0;
      }
    }
    watch_ = std::move(keep);
  }
  std::sort(stale.begin(), stale.end());
  stale.erase(std::unique(stale.begin(), stale.end()), stale.end());
  std::vector<int> completed;
  for (int t : stale) {
    if (complete_pattern(t) != 0) {
      completed.push_back(t);  // complete since (a neighbour's completion): split
    } else if (complete_from_sides(t, x, r)) {
      completed.push_back(t);
    }
  }
  r.tets_completed = static_cast<int>(completed.size());
  split_completed(completed, cut_piece, x, v, r);
}

namespace {

// The sweep's triangles with an area: those of a blade moving (almost) along its own axis
// are (nearly) collinear, their normal is round-off and would give vertices arbitrary
// sides. Kept only when the area is not negligible against the longest edge (height > 1e-9
// of it).
std::vector<Triangle> triangles_with_area(const SweptSurface& sweep) {
  std::vector<Triangle> tris;
  for (const auto& t : sweep.triangles()) {
    const double longest2 = std::max({(t.b - t.a).squaredNorm(), (t.c - t.b).squaredNorm(), (t.a - t.c).squaredNorm()});
    if ((t.b - t.a).cross(t.c - t.a).norm() > 1e-9 * longest2) tris.push_back(t);
  }
  return tris;
}

void sort_unique(std::vector<int>& ids) {
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
}

}  // namespace

std::vector<int> TetCutter::sweep_candidates(const std::vector<Triangle>& tris, const Eigen::Matrix3Xd& x) {
  std::vector<int> candidates;
  if (tris.empty()) return candidates;
  Aabb sweep_box;
  for (const auto& t : tris) {
    sweep_box.extend(t.a);
    sweep_box.extend(t.b);
    sweep_box.extend(t.c);
  }
  sweep_box = sweep_box.inflated(settings_.vertex_tolerance_mm);
  bvh_.refit(family_boxes(x));
  bvh_.query(sweep_box, [&](int fam) {
    for (int t : family_[static_cast<std::size_t>(fam)]) {
      Aabb b;
      for (int w : mesh_.tets[static_cast<std::size_t>(t)]) b.extend(Eigen::Vector3d(x.col(w)));
      if (b.overlaps(sweep_box)) candidates.push_back(t);
    }
  });
  return candidates;
}

void TetCutter::record_stroke_surface(const SweptSurface& sweep, const std::vector<Triangle>& tris, const Eigen::Matrix3Xd& x) {
  append_chunk(tris, stroke_tris_, stroke_chunks_);
  // The same surface in the material, while the tissue is where the blade met it (the
  // hierarchy holds x since the candidates' query): crossings completed later, when the
  // tissue has moved, are taken from it.
  const std::vector<Triangle> in_material = sweep_in_material(sweep, x, false);
  if (!in_material.empty()) append_chunk(in_material, stroke_tris_rest_, stroke_chunks_rest_);
}

void TetCutter::snap_vertices_on_sweep(const std::vector<Triangle>& tris, const std::vector<int>& candidates,
                                       const Eigen::Matrix3Xd& x, std::unordered_set<int>& seen_vertices, CutStepReport& r) {
  for (int t : candidates)
    for (int w : mesh_.tets[static_cast<std::size_t>(t)])
      if (seen_vertices.insert(w).second && !on_stroke(w)) {
        int nearest = 0;
        const double d = sweep_distance(tris, x.col(w), &nearest);
        if (d <= settings_.vertex_tolerance_mm) {
          on_cut_[static_cast<std::size_t>(w)] = stroke_;
          cut_normal_[static_cast<std::size_t>(w)] = unit_normal(tris[static_cast<std::size_t>(nearest)]);
          ++r.vertices_snapped;
          ++r.cut_points;
          r.max_path_deviation_mm = std::max(r.max_path_deviation_mm, d);
        }
      }
}

bool TetCutter::snap_to_crossing(int w, int o, double t_w, double edge_mm, const Triangle& tri, Eigen::Matrix3Xd& x,
                                 Eigen::Matrix3Xd& v, CutStepReport& r) {
  if (t_w > settings_.snap_fraction) return false;
  // Near an end. An interior vertex not on any cut yet is moved onto the swept surface
  // (paper 000's moving vertex: no split, no sliver, the cut stays on the path). Any other
  // vertex snaps (the cut passes through it) only when it lies within path_tolerance_mm of
  // the crossing; farther, the edge is split at the crossing (a thinner piece: path fidelity
  // over quality, docs/cut.md).
  const double off_mm = t_w * edge_mm;  // the vertex's distance along the edge from the crossing
  const bool fresh = on_cut_[static_cast<std::size_t>(w)] == 0;
  if (fresh && settings_.move_snapped_vertices && move_vertex(w, o, t_w, x, v, r)) {
    r.max_path_deviation_mm = std::max(r.max_path_deviation_mm, point_triangle_distance(x.col(w), tri));
  } else if (off_mm <= settings_.path_tolerance_mm || t_w < kMinSplitFraction) {
    r.max_path_deviation_mm = std::max(r.max_path_deviation_mm, off_mm);
  } else {
    return false;
  }
  on_cut_[static_cast<std::size_t>(w)] = stroke_;
  cut_normal_[static_cast<std::size_t>(w)] = unit_normal(tri);
  ++r.vertices_snapped;
  ++r.cut_points;
  return true;
}

std::optional<TetCutter::SecondCrossing> TetCutter::second_crossing(int p, int o, const std::vector<Triangle>& tris,
                                                                    const Eigen::Matrix3Xd& x) const {
  const double f = settings_.snap_fraction, len = (x.col(o) - x.col(p)).norm();
  const Eigen::Vector3d& n_p = cut_normal_[static_cast<std::size_t>(p)];
  for (const auto& tri : tris) {
    double s = 0.0;
    // Crossings within snap_fraction of the edge or path_tolerance_mm of the end on the cut
    // are that end's own (the sweep passing by it again, or by where the tissue carried it
    // since). Nor are crossings where the sweep's normal is within 20 degrees of the cut's
    // normal at the end on the cut, or grazing ones (the edge within 15 degrees of the
    // sweep's plane): a cut bent a little by the tissue's motion between frames, not a
    // curved cut coming back.
    if (segment_triangle_intersection(x.col(p), x.col(o), tri, s) && s > f &&
        s * len > settings_.path_tolerance_mm + settings_.vertex_tolerance_mm &&
        std::abs(unit_normal(tri).dot(x.col(o) - x.col(p))) > 0.26 * len && n_p.squaredNorm() > 0.5 && n_p.dot(unit_normal(tri)) < 0.94)
      return SecondCrossing{p, o, s, tri};
  }
  return std::nullopt;
}

void TetCutter::record_crossing(int a, int b, double s, const Triangle& tri, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                                CutStepReport& r) {
  const int w = s <= 0.5 ? a : b, o = s <= 0.5 ? b : a;
  if (snap_to_crossing(w, o, s <= 0.5 ? s : 1.0 - s, (x.col(b) - x.col(a)).norm(), tri, x, v, r)) return;
  const EdgeKey key = edge_key(a, b);
  pending_[key] = s;
  pending_normal_[key] = unit_normal(tri);
  ++r.edges_crossed;
  ++r.cut_points;
  // The recorded point, against the swept surface (round-off only).
  const Eigen::Vector3d p = x.col(a) + s * (x.col(b) - x.col(a));
  r.max_path_deviation_mm = std::max(r.max_path_deviation_mm, point_triangle_distance(p, tri));
}

std::vector<TetCutter::SecondCrossing> TetCutter::record_edge_crossings(const std::vector<Triangle>& tris,
                                                                        const std::vector<int>& candidates, Eigen::Matrix3Xd& x,
                                                                        Eigen::Matrix3Xd& v, CutStepReport& r) {
  std::vector<SecondCrossing> second_crossings;
  std::unordered_set<EdgeKey> seen_edges;
  for (int t : candidates) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& e : kEdges) {
      int a = tet[static_cast<std::size_t>(e[0])], b = tet[static_cast<std::size_t>(e[1])];
      if (a > b) std::swap(a, b);
      const EdgeKey key = edge_key(a, b);
      if (!seen_edges.insert(key).second || pending_.count(key) || (on_stroke(a) && on_stroke(b))) continue;
      if (on_stroke(a) || on_stroke(b)) {
        if (auto c = on_stroke(a) ? second_crossing(a, b, tris, x) : second_crossing(b, a, tris, x)) second_crossings.push_back(*c);
        continue;
      }
      for (const auto& tri : tris) {
        double s = 0.0;
        if (!segment_triangle_intersection(x.col(a), x.col(b), tri, s)) continue;
        record_crossing(a, b, s, tri, x, v, r);
        break;
      }
    }
  }
  return second_crossings;
}

void TetCutter::split_second_crossings(const std::vector<SecondCrossing>& crossings, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v,
                                       std::vector<int>& candidates, std::unordered_set<int>& seen_vertices, CutStepReport& r) {
  for (const auto& c : crossings) {
    if (on_stroke(c.free) || tets_with_edge(c.on_cut, c.free).empty()) continue;
    if (snap_to_crossing(c.free, c.on_cut, 1.0 - c.s, (x.col(c.free) - x.col(c.on_cut)).norm(), c.tri, x, v, r)) continue;
    const Eigen::Vector3d n = unit_normal(c.tri);
    std::vector<int> touched;
    split_edge(c.on_cut, c.free, std::clamp(c.s, kMinSplitFraction, 1.0 - kMinSplitFraction), x, v, r, touched);
    const int m = mesh_.num_vertices() - 1;
    cut_normal_[static_cast<std::size_t>(m)] = n;
    ++r.cut_points;
    r.max_path_deviation_mm = std::max(r.max_path_deviation_mm, point_triangle_distance(x.col(m), c.tri));
    r.changed_tets.insert(r.changed_tets.end(), touched.begin(), touched.end());
    for (int tt : touched) candidates.push_back(tt);
    for (int w : mesh_.tets[static_cast<std::size_t>(touched.empty() ? 0 : touched.back())]) seen_vertices.insert(w);
  }
}

void TetCutter::side_vertices_near_sweep(const std::vector<Triangle>& tris, const std::unordered_set<int>& seen_vertices,
                                         const Eigen::Matrix3Xd& x) {
  for (int w : seen_vertices) {
    if (on_stroke(w) || side_[static_cast<std::size_t>(w)] != 0) continue;
    // Mostly this frame's triangles change the answer an earlier frame gave: when they lie
    // farther than the vertex's reach they cannot be its nearest within reach, so the lookup
    // is skipped (a vertex left without a side gets one when a cut face needs it).
    double reach2 = 0.0;
    for (int tt : vertex_tets_[static_cast<std::size_t>(w)])
      for (int u : mesh_.tets[static_cast<std::size_t>(tt)]) reach2 = std::max(reach2, (x.col(u) - x.col(w)).squaredNorm());
    const double d_frame = sweep_distance(tris, x.col(w));
    if (d_frame * d_frame > reach2) continue;
    if (const int sd = stroke_side(w, x, kEagerCone); sd != 0) {
      side_[static_cast<std::size_t>(w)] = static_cast<signed char>(sd);
      sided_.push_back(w);
    }
  }
}

std::vector<std::array<int, 3>> TetCutter::separated_piece_faces(const std::vector<char>& cut_piece) {
  std::vector<std::array<int, 3>> new_cut_faces;
  for (std::size_t t = 0; t < cut_piece.size(); ++t) {
    if (!cut_piece[t]) continue;
    const auto& tet = mesh_.tets[t];
    for (const auto& fc : kFaces) {
      const std::array<int, 3> key = face_key(tet[static_cast<std::size_t>(fc[0])], tet[static_cast<std::size_t>(fc[1])],
                                              tet[static_cast<std::size_t>(fc[2])]);
      if (on_stroke(key[0]) && on_stroke(key[1]) && on_stroke(key[2]) && tets_with_face(key) == 2 && cut_faces_.insert(key).second)
        new_cut_faces.push_back(key);
    }
  }
  return new_cut_faces;
}

int TetCutter::free_side(int t) const {
  int side = 0;
  for (int w : mesh_.tets[static_cast<std::size_t>(t)]) {
    if (on_stroke(w)) continue;
    const int sw = side_[static_cast<std::size_t>(w)];
    if (sw == 0 || (side != 0 && sw != side)) return 0;
    side = sw;
  }
  return side;
}

int TetCutter::neighbours_side(int t) const {
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  int sum = 0, first = 0;
  for (const auto& fc : kFaces) {
    int pair[2] = {-1, -1};
    if (tets_with_face(face_key(tet[static_cast<std::size_t>(fc[0])], tet[static_cast<std::size_t>(fc[1])], tet[static_cast<std::size_t>(fc[2])]), pair) != 2)
      continue;
    const int other = pair[0] == t ? pair[1] : pair[0];
    // A flat neighbour counts with the side it was given (a chain of flat tets in the cut
    // takes its sides link by link).
    int sd = free_side(other);
    if (sd == 0 && other < static_cast<int>(flat_side_.size())) sd = flat_side_[static_cast<std::size_t>(other)];
    sum += sd;
    if (first == 0) first = sd;
  }
  return sum > 0 ? 1 : (sum < 0 ? -1 : first);
}

int TetCutter::tet_side(int t, const Eigen::Matrix3Xd& x) {
  int side = 0;
  bool any_free = false;
  for (int w : mesh_.tets[static_cast<std::size_t>(t)]) {
    if (on_stroke(w)) continue;
    any_free = true;
    if (side_[static_cast<std::size_t>(w)] == 0) {
      // A vertex next to the cut that no sweep gave a side yet (its neighbours were put
      // on the cut later): from the cut beside it.
      // At the stroke's end (finish_stroke) the surface is complete: the side of the plane
      // of its nearest triangle, wherever that lies (a face left undecided would stay a
      // hole in the cut).
      if (const int sd = finishing_ ? stroke_side(w, x, 1e300, false) : stroke_side(w, x, kLazyCone); sd != 0) {
        side_[static_cast<std::size_t>(w)] = static_cast<signed char>(sd);
        sided_.push_back(w);
      }
    }
    const int sw = side_[static_cast<std::size_t>(w)];
    if (sw == 0 || (side != 0 && sw != side)) return 0;
    side = sw;
  }
  return any_free ? side : flat_tet_side(t, x);
}

int TetCutter::flat_tet_side(int t, const Eigen::Matrix3Xd& x) {
  signed char& cached = flat_side_[static_cast<std::size_t>(t)];
  if (cached != 0) return static_cast<int>(cached);
  const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
  // The sides its vertices had before they were put on the cut, when they agree.
  int before = 0;
  for (int w : tet) before += side_[static_cast<std::size_t>(w)];
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  double longest = 0.0;
  for (int i = 0; i < 4; ++i) {
    c += x.col(tet[static_cast<std::size_t>(i)]) / 4.0;
    for (int j = i + 1; j < 4; ++j)
      longest = std::max(longest, (x.col(tet[static_cast<std::size_t>(i)]) - x.col(tet[static_cast<std::size_t>(j)])).norm());
  }
  // Against the whole stroke's surface (on a curved cut a tet spanning a chord lies on the
  // inner side; one frame's strip can be far from it). A sliver lying in the surface
  // (centroid within 1e-3 of its size) has no side of its own: it joins its neighbours
  // (deciding it by the sign of round-off cut it out as a piece of its own).
  if (!stroke_tris_.empty()) {
    int nearest = 0;
    const double best = sweep_distance(stroke_tris_, c, &nearest);
    const Triangle& tri = stroke_tris_[static_cast<std::size_t>(nearest)];
    const double d = unit_normal(tri).dot(c - tri.a);
    if (best <= settings_.snap_fraction * longest + settings_.vertex_tolerance_mm && std::abs(d) > 1e-3 * longest) {
      cached = static_cast<signed char>(d > 0 ? 1 : -1);
      return static_cast<int>(cached);
    }
  }
  if (before != 0) return before > 0 ? 1 : -1;
  cached = static_cast<signed char>(neighbours_side(t));
  return static_cast<int>(cached);
}

void TetCutter::decide_cut_faces(const std::vector<int>& candidates, const std::vector<int>& changed_tets,
                                 const Eigen::Matrix3Xd& x, std::vector<std::array<int, 3>>& new_cut_faces) {
  std::vector<int> face_tets = candidates;
  face_tets.insert(face_tets.end(), changed_tets.begin(), changed_tets.end());
  FaceSet seen_faces;
  // Faces on the cut whose tets' sides were not known yet are looked at again every frame
  // (the blade reaches their vertices later).
  std::vector<std::array<int, 3>> faces = std::move(undecided_faces_);
  undecided_faces_.clear();
  for (int t : face_tets) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (const auto& fc : kFaces)
      faces.push_back(face_key(tet[static_cast<std::size_t>(fc[0])], tet[static_cast<std::size_t>(fc[1])], tet[static_cast<std::size_t>(fc[2])]));
  }
  // At the stroke's end the faces still undecided are looked at again while that decides more
  // (sides given to flat tets in one pass decide their neighbours in the next): a face left
  // undecided would stay a hole in the cut.
  for (int pass = 0; pass < (finishing_ ? 32 : 1); ++pass) {
    if (pass > 0) {
      faces = std::move(undecided_faces_);
      undecided_faces_.clear();
      seen_faces.clear();
    }
    int decided = 0;
    for (const auto& key : faces) {
      if (!on_stroke(key[0]) || !on_stroke(key[1]) || !on_stroke(key[2])) continue;
      if (cut_faces_.count(key) || !seen_faces.insert(key).second) continue;
      int pair[2] = {-1, -1};
      if (tets_with_face(key, pair) != 2) continue;
      const int s0 = tet_side(pair[0], x), s1 = tet_side(pair[1], x);
      if (s0 * s1 < 0) {
        cut_faces_.insert(key);
        new_cut_faces.push_back(key);
        ++decided;
      } else if (s0 == 0 || s1 == 0) {
        undecided_faces_.push_back(key);
      } else {
        ++decided;
      }
    }
    if (decided == 0 || undecided_faces_.empty()) break;
  }
}

bool TetCutter::all_on_stroke(int t) const {
  for (int w : mesh_.tets[static_cast<std::size_t>(t)])
    if (!on_stroke(w)) return false;
  return true;
}

void TetCutter::join_walled_off_slivers(const std::vector<std::array<int, 3>>& new_cut_faces) {
  std::set<int> done;
  for (const auto& key : new_cut_faces) {
    int pair[2] = {-1, -1};
    if (tets_with_face(key, pair) != 2) continue;
    for (int seed : pair) {
      if (done.count(seed) || !all_on_stroke(seed)) continue;
      join_sliver_group(seed, done);
    }
  }
}

void TetCutter::join_sliver_group(int seed, std::set<int>& done) {
  constexpr std::size_t kMaxGroup = 64;
  std::vector<int> group{seed};
  std::set<int> in_group{seed};
  std::vector<std::pair<std::array<int, 3>, int>> walls;  // cut face, tet beyond it
  bool attached = false;
  for (std::size_t i = 0; i < group.size() && !attached && group.size() <= kMaxGroup; ++i) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(group[i])];
    for (const auto& fc : kFaces) {
      const auto face = face_key(tet[static_cast<std::size_t>(fc[0])], tet[static_cast<std::size_t>(fc[1])], tet[static_cast<std::size_t>(fc[2])]);
      int across[2] = {-1, -1};
      if (tets_with_face(face, across) != 2) continue;
      const int other = across[0] == group[i] ? across[1] : across[0];
      if (in_group.count(other)) continue;
      if (cut_faces_.count(face)) {
        walls.emplace_back(face, other);
      } else if (all_on_stroke(other)) {
        group.push_back(other);
        in_group.insert(other);
      } else {
        attached = true;
        break;
      }
    }
  }
  done.insert(group.begin(), group.end());
  if (attached || group.size() > kMaxGroup || walls.empty()) return;
  int sum = 0;
  for (const auto& wall : walls) sum += free_side(wall.second);
  const int join = sum > 0 ? 1 : (sum < 0 ? -1 : free_side(walls.front().second));
  bool opened = false;
  for (const auto& wall : walls) {
    if (join != 0 && free_side(wall.second) != join) continue;
    cut_faces_.erase(wall.first);
    opened = true;
  }
  if (!opened) cut_faces_.erase(walls.front().first);
  for (int t : group) flat_side_[static_cast<std::size_t>(t)] = static_cast<signed char>(join);
}

CutStepReport TetCutter::step(const SweptSurface& sweep, Eigen::Matrix3Xd& x, Eigen::Matrix3Xd& v) {
  const auto start = std::chrono::steady_clock::now();
  CutStepReport r;
  const int first_new_vertex = mesh_.num_vertices();
  if (x.cols() != mesh_.num_vertices()) throw std::invalid_argument("cut: positions do not match the mesh");
  if (v.cols() != 0 && v.cols() != mesh_.num_vertices()) throw std::invalid_argument("cut: velocities do not match the mesh");
  const std::vector<Triangle> tris = triangles_with_area(sweep);
  auto finish = [&]() {
    r.update_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return r;
  };
  if ((tris.empty() && !finishing_) || mesh_.tets.empty()) return finish();
  // Candidates: tets whose current box meets the swept surface's box.
  std::vector<int> candidates = sweep_candidates(tris, x);
  r.candidate_tets = static_cast<int>(candidates.size());
  if (candidates.empty() && pending_.empty() && undecided_faces_.empty()) return finish();
  const int old_tets = mesh_.num_tets();
  // Tets a blade end (tip or heel path) passes through hold the crack front.
  if (!tris.empty()) {
    mark_tip_tets(sweep, candidates, x);
    const Triangle& t0 = tris.front();
    last_normal_ = (t0.b - t0.a).cross(t0.c - t0.a).normalized();
  }
  refine_ahead(tris, candidates, x, v, r);
  // The bisected tets' children were appended (their parents' ids are kept).
  if (r.edges_refined > 0) sort_unique(candidates);
  if (!tris.empty()) record_stroke_surface(sweep, tris, x);
  // 1. Vertices on the swept surface.
  std::unordered_set<int> seen_vertices;
  snap_vertices_on_sweep(tris, candidates, x, seen_vertices, r);
  // 2. Edge crossings: snapped to an end within snap_fraction of it, recorded otherwise.
  // An edge with one end already on this stroke's cut that the sweep crosses again farther
  // along (a curved cut, a ring, on tets larger than its curvature) is split there (2b):
  // its other end lies beyond the second crossing, and a side taken from the first one
  // would be wrong.
  const std::vector<SecondCrossing> second_crossings = record_edge_crossings(tris, candidates, x, v, r);
  // 2b. Second crossings: the free end goes onto the cut when it is near (moved or snapped,
  // as above), otherwise the edge is split at the crossing (every tet around it bisected:
  // conforming, volumes exact).
  split_second_crossings(second_crossings, x, v, candidates, seen_vertices, r);
  sort_unique(candidates);
  // 3. Sides of the vertices near the sweep (kept for the stroke: a material property): from
  // the nearest point of the stroke's whole swept surface so far (stroke_side). Neither a
  // crossing of one of its edges nor this frame's strip alone is enough on a curved cut over
  // tets larger than its curvature: an edge can cross a ring twice, and a ring's first strip
  // lies across from vertices on its far side. Here, while the sweep passes, only a vertex
  // right across from the surface (within 27 degrees of the normal: the sweep's front is
  // oblique to vertices ahead of it) takes a side; a vertex a cut face needs later takes it
  // then, from the surface swept by that time, within 45 degrees (tet_side).
  side_vertices_near_sweep(tris, seen_vertices, x);
  // 4. Tets the recorded crossings separate completely: split their crossed edges (every
  // tet around such an edge is bisected: conforming). Repeated while splits complete more.
  std::vector<char> cut_piece(static_cast<std::size_t>(mesh_.num_tets()), 0);
  split_completed(candidates, cut_piece, x, v, r);
  // 4b. Tets the blade has left (no longer near the sweep) whose crossings stay incomplete
  // because the tissue moved between frames, and that no blade end passed through (those are
  // the crack tip): the missing crossings are put on the plane of the recorded ones.
  complete_left_tets(candidates, old_tets, cut_piece, x, v, r);
  // Cut faces: faces of the separated pieces with their three vertices on this stroke (the
  // cut polygons), and faces with their three vertices on this stroke between two tets on
  // opposite sides (a cut through existing vertices and faces).
  std::vector<std::array<int, 3>> new_cut_faces = separated_piece_faces(cut_piece);
  decide_cut_faces(candidates, r.changed_tets, x, new_cut_faces);
  // 4c. Slivers in the cut surface: a group of tets with every vertex on this stroke's cut
  // (no material of their own beyond the discretised surface) that the new cut faces would
  // wall off from every tet with a free vertex would come out as a fragment of its own (the
  // sides of such slivers are decided by the sign of a distance near round-off). The group
  // joins the side most of its walled-off neighbours are on: the faces to those are not cut.
  join_walled_off_slivers(new_cut_faces);
  // 5. Separate: duplicate each vertex of a cut face whose tets fall apart into groups.
  separate_along_cut(x, v, r);
  // 6. Points put on the cut off the path in the material go onto it (docs/cut.md, step 8).
  place_new_cut_points(first_new_vertex, r, x, v);
  // Tets made after the watch list was updated (the completions' splits, the separation's
  // mid-point splits of edges inside the cut) are watched like the others: the blade may
  // already have left them, and a tet never watched is never completed.
  for (int t : r.changed_tets) watch_tet(t);
  r.topology_changed = r.vertices_added > 0 || r.vertices_moved > 0;
  sort_unique(r.changed_tets);
  return finish();
}

}  // namespace arnav::host::cut
