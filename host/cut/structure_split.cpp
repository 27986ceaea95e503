#include "host/cut/structure_split.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cstdint>
#include <limits>
#include <map>
#include <unordered_map>
#include <unordered_set>

namespace arnav::host::cut {

namespace {

constexpr const auto& kFaces = kTetFaces;
// Two lip hits belong to the same cut face when they lie this close along the segment (the
// lips coincide in the rest configuration, up to the round-off of separate edge splits).
constexpr double kLipTolerance_mm = 1e-3;

std::array<int, 3> sorted3(int a, int b, int c) {
  std::array<int, 3> k{a, b, c};
  std::sort(k.begin(), k.end());
  return k;
}

struct Face3Hash {
  std::size_t operator()(const std::array<int, 3>& f) const {
    return std::hash<std::uint64_t>()((static_cast<std::uint64_t>(f[0]) * 73856093ULL) ^ (static_cast<std::uint64_t>(f[1]) * 19349663ULL) ^
                                      (static_cast<std::uint64_t>(f[2]) * 83492791ULL));
  }
};

// New points of a structure under construction.
struct Builder {
  const TetMesh& mesh;
  std::vector<Eigen::Vector3d> rest;
  std::vector<int> tet;
  std::vector<Eigen::Vector4d> weights;
  std::vector<int> source;
  std::vector<Eigen::Vector3d> into_side;  // per point: direction from its lip into its side (zero for input points)

  Builder(const TetMesh& m, const Eigen::Matrix3Xd& rest_in, const Embedding& e) : mesh(m) {
    for (int i = 0; i < rest_in.cols(); ++i) {
      rest.push_back(rest_in.col(i));
      tet.push_back(e.tet[static_cast<std::size_t>(i)]);
      weights.push_back(e.weights.col(i));
      source.push_back(i);
      into_side.push_back(Eigen::Vector3d::Zero());
    }
  }
  int add(const Eigen::Vector3d& p, int t, int src, const Eigen::Vector3d& into) {
    rest.push_back(p);
    tet.push_back(t);
    weights.push_back(rest_weights(mesh, t, p));
    source.push_back(src);
    into_side.push_back(into);
    return static_cast<int>(rest.size()) - 1;
  }
  SplitStructure finish() {
    SplitStructure out;
    const int n = static_cast<int>(rest.size());
    out.rest_World_mm.resize(3, n);
    out.embedding.tet = tet;
    out.embedding.weights.resize(4, n);
    for (int i = 0; i < n; ++i) {
      out.rest_World_mm.col(i) = rest[static_cast<std::size_t>(i)];
      out.embedding.weights.col(i) = weights[static_cast<std::size_t>(i)];
    }
    out.source = source;
    return out;
  }
};

// Copies of an input edge's crossing: the one on the smaller vertex's side, the other's.
struct EdgeCopies {
  int lo = -1, hi = -1;
};

// Crossing copies of edge a-b, made once per edge (shared by the triangles around it).
std::optional<EdgeCopies> edge_copies(int a, int b, const Eigen::Matrix3Xd& rest, const CutLips& lips, Builder& build,
                                      std::unordered_map<std::uint64_t, std::optional<EdgeCopies>>& done, int& crossed) {
  const std::uint64_t key = edge_key(a, b);
  if (const auto it = done.find(key); it != done.end()) return it->second;
  const int lo = std::min(a, b), hi = std::max(a, b);
  std::optional<EdgeCopies> copies;
  if (const auto c = lips.crossing(rest.col(lo), rest.col(hi))) {
    const Eigen::Vector3d p = rest.col(lo) + c->s * (rest.col(hi) - rest.col(lo));
    copies = EdgeCopies{build.add(p, c->tet0, lo, -c->normal0), build.add(p, c->tet1, hi, c->normal0)};
    ++crossed;
  }
  done.emplace(key, copies);
  return copies;
}

// The copy of edge a-b's crossing on vertex v's side (v is a or b).
int copy_on_side(const EdgeCopies& c, int a, int b, int v) { return v == std::min(a, b) ? c.lo : c.hi; }


// Triangulation of the polygon p[0..m-1] (closed by p[m-1] -> p[0]) of least total area
// (dynamic programming over the polygon's diagonals, O(m^3)): on a long, thin, curved
// polygon (a slit's side) it joins the two long sides by short rungs that follow the curve,
// where a fan from one point makes long slivers across it. Triangles as index triples
// i < k < j in polygon order; empty when m < 3.
std::vector<std::array<int, 3>> least_area_triangulation(const std::vector<Eigen::Vector3d>& p) {
  const int m = static_cast<int>(p.size());
  std::vector<std::array<int, 3>> out;
  if (m < 3) return out;
  const auto at = [m](int i, int j) { return static_cast<std::size_t>(i) * static_cast<std::size_t>(m) + static_cast<std::size_t>(j); };
  std::vector<double> cost(static_cast<std::size_t>(m) * static_cast<std::size_t>(m), 0.0);
  std::vector<int> best(static_cast<std::size_t>(m) * static_cast<std::size_t>(m), -1);
  for (int len = 2; len < m; ++len)
    for (int i = 0; i + len < m; ++i) {
      const int j = i + len;
      double c_best = std::numeric_limits<double>::infinity();
      for (int k = i + 1; k < j; ++k) {
        const double area = 0.5 * (p[static_cast<std::size_t>(k)] - p[static_cast<std::size_t>(i)]).cross(p[static_cast<std::size_t>(j)] - p[static_cast<std::size_t>(i)]).norm();
        const double c = cost[at(i, k)] + cost[at(k, j)] + area;
        if (c < c_best) {
          c_best = c;
          best[at(i, j)] = k;
        }
      }
      cost[at(i, j)] = c_best;
    }
  std::vector<std::pair<int, int>> todo{{0, m - 1}};
  while (!todo.empty()) {
    const auto [i, j] = todo.back();
    todo.pop_back();
    if (j - i < 2) continue;
    const int k = best[at(i, j)];
    out.push_back({i, k, j});
    todo.emplace_back(i, k);
    todo.emplace_back(k, j);
  }
  return out;
}

// A slit: the loop a cut ending inside the surface opens. It runs from one crack end (an
// input vertex where the cut ends inside a triangle) along the crossing copies of the slit
// to the other crack end and back along their twins (the other copies of the same
// crossings, in reverse order); where the slit's end is ragged (the crack front crosses
// the surface between tets the cut has not separated yet) it also passes input vertices
// between the copies, once each way. Each way is closed by its own surface spanning its
// points and the chord between the crack ends (the crack front inside the structure),
// triangulated with least area; the way back's is the mirror image of the way out's, so the
// two meet along the chord, coincide in the rest shape (the volume is unchanged) and part as
// the cut opens. False (nothing added) when the loop is not such a mirror, a point repeats
// on one way, or the chord is already an edge.
bool close_slit(const std::vector<int>& loop, int input_points, const std::vector<Eigen::Vector3d>& rest,
                const std::unordered_set<std::uint64_t>& directed, std::vector<std::array<int, 3>>& out) {
  constexpr std::size_t kMaxSide = 600;  // O(m^3) work: longer slits keep the fan
  const std::size_t n = loop.size();
  if (n < 4 || n % 2 != 0 || n / 2 + 1 > kMaxSide) return false;
  // Copies are made in pairs (edge_copies: the lower vertex's side, then the other's).
  const auto twin = [input_points](int v) { return v < input_points ? v : input_points + ((v - input_points) ^ 1); };
  const std::size_t half = n / 2;
  for (std::size_t i0 = 0; i0 < half; ++i0) {
    const std::size_t i1 = i0 + half;
    if (loop[i0] >= input_points || loop[i1] >= input_points || loop[i0] == loop[i1]) continue;
    bool mirror = true;
    for (std::size_t k = 1; k < half && mirror; ++k) mirror = loop[(i0 + k) % n] == twin(loop[(i0 + n - k) % n]);
    if (!mirror) continue;
    std::vector<int> a(loop.begin() + static_cast<std::ptrdiff_t>(i0), loop.begin() + static_cast<std::ptrdiff_t>(i1) + 1);
    std::vector<int> b;  // c1, the way back, c0: b[j] is the twin of a[m-1-j]
    for (std::size_t k = i1; k <= i0 + n; ++k) b.push_back(loop[k % n]);
    const std::size_t m = a.size();
    std::vector<int> sorted = a;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) return false;
    const int c0 = a.front(), c1 = a.back();
    const auto key = [](int i, int j) { return directed_edge_key(i, j); };
    if (directed.count(key(c0, c1)) || directed.count(key(c1, c0))) return false;
    std::vector<Eigen::Vector3d> pa;
    for (int v : a) pa.push_back(rest[static_cast<std::size_t>(v)]);
    for (const auto& [i, k, j] : least_area_triangulation(pa)) {
      // Reverse orientation of the loop, as the loop's own surface runs against it.
      out.push_back({a[static_cast<std::size_t>(j)], a[static_cast<std::size_t>(k)], a[static_cast<std::size_t>(i)]});
      out.push_back({b[m - 1 - static_cast<std::size_t>(i)], b[m - 1 - static_cast<std::size_t>(k)], b[m - 1 - static_cast<std::size_t>(j)]});
    }
    return true;
  }
  return false;
}

// A ragged slit (the crack front crosses the surface between tets the cut has not
// separated, or the cut branches): the loop, which runs along both sides of the slit and
// passes the crack ends, is sewn shut by its own least-area triangulation (each pair of
// copies of a crossing and its neighbours form triangles of zero area in the rest shape,
// which open with the cut). False (nothing added) when a point repeats on the loop, it is
// too long, or a diagonal is already an edge of the surface.
bool sew_slit(const std::vector<int>& loop, const std::vector<Eigen::Vector3d>& rest, const std::unordered_set<std::uint64_t>& directed,
              std::vector<std::array<int, 3>>& out) {
  constexpr std::size_t kMaxLoop = 600;  // O(n^3) work
  const std::size_t n = loop.size();
  if (n < 3 || n > kMaxLoop) return false;
  std::vector<int> sorted = loop;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) return false;
  std::vector<Eigen::Vector3d> p;
  for (int v : loop) p.push_back(rest[static_cast<std::size_t>(v)]);
  const auto tris = least_area_triangulation(p);
  const auto key = [](int i, int j) { return directed_edge_key(i, j); };
  for (const auto& [i, k, j] : tris)
    for (const auto& [u, w] : {std::pair{i, k}, std::pair{k, j}, std::pair{i, j}}) {
      if (w - u == 1 || (u == 0 && w == static_cast<int>(n) - 1)) continue;  // a loop edge
      const int a = loop[static_cast<std::size_t>(u)], b = loop[static_cast<std::size_t>(w)];
      if (directed.count(key(a, b)) || directed.count(key(b, a))) return false;
    }
  for (const auto& [i, k, j] : tris) out.push_back({loop[static_cast<std::size_t>(j)], loop[static_cast<std::size_t>(k)], loop[static_cast<std::size_t>(i)]});
  return true;
}

}  // namespace

Eigen::Vector4d rest_weights(const TetMesh& mesh, int tet, const Eigen::Vector3d& p) {
  const auto& rest = mesh.rest_positions_World_mm;
  const auto& t = mesh.tets[static_cast<std::size_t>(tet)];
  Eigen::Matrix3d D;
  for (int k = 0; k < 3; ++k) D.col(k) = rest.col(t[static_cast<std::size_t>(k + 1)]) - rest.col(t[0]);
  const Eigen::Vector3d l = D.partialPivLu().solve(p - rest.col(t[0]));
  return {1.0 - l.sum(), l[0], l[1], l[2]};
}

StructureEdges::StructureEdges(const Eigen::Matrix3Xd& rest_World_mm, std::vector<std::array<int, 2>> edges)
    : rest_(rest_World_mm), edges_(std::move(edges)) {
  std::vector<Aabb> boxes;
  boxes.reserve(edges_.size());
  for (const auto& [a, b] : edges_) {
    Aabb box;
    box.extend(Eigen::Vector3d(rest_.col(a)));
    box.extend(Eigen::Vector3d(rest_.col(b)));
    boxes.push_back(box);
  }
  bvh_.build(boxes);
}

bool StructureEdges::crossed_by(const Triangle& face) const {
  if (edges_.empty()) return false;
  constexpr double kGrow = 1e-3;
  const Eigen::Vector3d c = (face.a + face.b + face.c) / 3.0;
  const Triangle grown{c + (1 + kGrow) * (face.a - c), c + (1 + kGrow) * (face.b - c), c + (1 + kGrow) * (face.c - c)};
  Aabb box;
  box.extend(grown.a);
  box.extend(grown.b);
  box.extend(grown.c);
  bool crossed = false;
  bvh_.query(box.inflated(kLipTolerance_mm), [&](int i) {
    double s = 0;
    const auto& [a, b] = edges_[static_cast<std::size_t>(i)];
    crossed = crossed || segment_triangle_intersection(rest_.col(a), rest_.col(b), grown, s);
  });
  return crossed;
}

std::vector<std::array<int, 2>> surface_edges(const std::vector<std::array<int, 3>>& tris) {
  std::unordered_set<std::uint64_t> seen;
  std::vector<std::array<int, 2>> out;
  for (const auto& t : tris)
    for (int k = 0; k < 3; ++k) {
      const int a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)];
      if (seen.insert(edge_key(a, b)).second) out.push_back({std::min(a, b), std::max(a, b)});
    }
  return out;
}

CutLips::CutLips(const TetMesh& mesh, const std::vector<int>& region_tets) : mesh_(mesh), region_tets_(region_tets) {
  // Faces used by one region tet. A face inside the mesh whose other tet is outside the
  // region also shows up once, but its twin lip is missing, so it never pairs (below).
  std::unordered_map<std::array<int, 3>, std::pair<int, int>, Face3Hash> count;  // face -> (uses, tet * 4 + face)
  for (int t : region_tets_) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    for (int f = 0; f < 4; ++f) {
      auto& c = count[sorted3(tet[static_cast<std::size_t>(kFaces[f][0])], tet[static_cast<std::size_t>(kFaces[f][1])],
                              tet[static_cast<std::size_t>(kFaces[f][2])])];
      ++c.first;
      c.second = t * 4 + f;
    }
  }
  const auto& rest = mesh_.rest_positions_World_mm;
  std::vector<Aabb> boxes;
  for (const auto& [key, c] : count) {
    if (c.first != 1) continue;
    const int t = c.second / 4, f = c.second % 4;
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    Face face;
    face.tri = {rest.col(tet[static_cast<std::size_t>(kFaces[f][0])]), rest.col(tet[static_cast<std::size_t>(kFaces[f][1])]),
                rest.col(tet[static_cast<std::size_t>(kFaces[f][2])])};
    face.tet = t;
    Eigen::Vector3d n = (face.tri.b - face.tri.a).cross(face.tri.c - face.tri.a);
    const int opposite = tet[static_cast<std::size_t>(6 - kFaces[f][0] - kFaces[f][1] - kFaces[f][2])];
    if (n.dot(rest.col(opposite) - face.tri.a) > 0) n = -n;  // outward whatever the tet's orientation
    if (!(n.norm() > 0)) continue;
    face.normal = n.normalized();
    Aabb b;
    b.extend(face.tri.a);
    b.extend(face.tri.b);
    b.extend(face.tri.c);
    boxes.push_back(b);
    faces_.push_back(face);
  }
  // Keep the lips: faces with a twin (the same face seen from the other side: same centroid,
  // opposite normal). Faces at the region's border (interior faces whose other tet is not
  // in the region) and the organ's own surface have none.
  bvh_.build(boxes);
  std::vector<Face> lips;
  std::vector<Aabb> lip_boxes;
  for (std::size_t i = 0; i < faces_.size(); ++i) {
    const Face& f = faces_[i];
    const Eigen::Vector3d c = (f.tri.a + f.tri.b + f.tri.c) / 3.0;
    bool twin = false;
    bvh_.query(boxes[i].inflated(kLipTolerance_mm), [&](int j) {
      const Face& g = faces_[static_cast<std::size_t>(j)];
      if (!twin && static_cast<std::size_t>(j) != i && (c - (g.tri.a + g.tri.b + g.tri.c) / 3.0).norm() <= kLipTolerance_mm && f.normal.dot(g.normal) < -0.99)
        twin = true;
    });
    if (!twin) continue;
    lips.push_back(f);
    lip_boxes.push_back(boxes[i]);
  }
  faces_ = std::move(lips);
  bvh_ = Bvh();
  bvh_.build(lip_boxes);
}

std::optional<SegmentCut> CutLips::crossing(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1) const {
  if (faces_.empty()) return std::nullopt;
  Aabb box;
  box.extend(p0);
  box.extend(p1);
  struct Hit {
    double s;
    int face;
    bool towards_p1;  // the face's outward normal points to p1: its tet is on p0's side
  };
  std::vector<Hit> hits;
  const Eigen::Vector3d d = p1 - p0;
  bvh_.query(box.inflated(kLipTolerance_mm), [&](int i) {
    double s = 0;
    const Face& f = faces_[static_cast<std::size_t>(i)];
    if (segment_triangle_intersection(p0, p1, f.tri, s)) hits.push_back({s, i, f.normal.dot(d) > 0});
  });
  if (hits.size() < 2) return std::nullopt;
  std::sort(hits.begin(), hits.end(), [](const Hit& a, const Hit& b) { return a.s < b.s; });
  const double len = d.norm(), tol = len > 0 ? kLipTolerance_mm / len : 0.0;
  for (std::size_t i = 0; i < hits.size(); ++i) {
    if (!hits[i].towards_p1) continue;
    for (std::size_t j = 0; j < hits.size(); ++j) {
      if (hits[j].towards_p1 || std::abs(hits[j].s - hits[i].s) > tol) continue;
      // Twins only: the same face seen from both sides (not the two faces of a sliver).
      const Face& fi = faces_[static_cast<std::size_t>(hits[i].face)];
      const Face& fj = faces_[static_cast<std::size_t>(hits[j].face)];
      if ((fi.tri.a + fi.tri.b + fi.tri.c - fj.tri.a - fj.tri.b - fj.tri.c).norm() / 3.0 > kLipTolerance_mm || fi.normal.dot(fj.normal) > -0.99) continue;
      SegmentCut c;
      c.s = std::clamp(0.5 * (hits[i].s + hits[j].s), 0.0, 1.0);
      c.tet0 = faces_[static_cast<std::size_t>(hits[i].face)].tet;
      c.tet1 = faces_[static_cast<std::size_t>(hits[j].face)].tet;
      c.normal0 = faces_[static_cast<std::size_t>(hits[i].face)].normal;
      return c;
    }
  }
  return std::nullopt;
}

int CutLips::lip_along(const Eigen::Vector3d& p, const Eigen::Vector3d& d, double reach, Eigen::Vector3d& on_lip) const {
  const Eigen::Vector3d p0 = p - reach * d, p1 = p + reach * d;
  Aabb box;
  box.extend(p0);
  box.extend(p1);
  int best_tet = -1;
  double best = 1e300;
  bvh_.query(box, [&](int i) {
    const Face& f = faces_[static_cast<std::size_t>(i)];
    double s = 0;
    if (f.normal.dot(d) >= 0 || !segment_triangle_intersection(p0, p1, f.tri, s)) return;
    if (std::abs(s - 0.5) < best) {
      best = std::abs(s - 0.5);
      best_tet = f.tet;
      on_lip = p0 + s * (p1 - p0);
    }
  });
  return best_tet;
}

int CutLips::locate(const Eigen::Vector3d& p, Eigen::Vector4d& weights) const {
  int best_tet = -1;
  double best = -1e300;
  for (int t : region_tets_) {
    const auto& tet = mesh_.tets[static_cast<std::size_t>(t)];
    Aabb b;
    for (int w : tet) b.extend(Eigen::Vector3d(mesh_.rest_positions_World_mm.col(w)));
    if (best > -1e299 && !b.inflated(1e-9).overlaps(Aabb{p, p})) continue;
    const Eigen::Vector4d w = rest_weights(mesh_, t, p);
    if (w.allFinite() && w.minCoeff() > best) {
      best = w.minCoeff();
      best_tet = t;
      weights = w;
    }
  }
  return best_tet;
}

SplitStructure split_surface(const TetMesh& mesh, const CutLips& lips, const Eigen::Matrix3Xd& rest, const Embedding& embedding,
                             const std::vector<std::array<int, 3>>& tris) {
  Builder build(mesh, rest, embedding);
  std::unordered_map<std::uint64_t, std::optional<EdgeCopies>> done;
  int crossed = 0;
  std::vector<std::array<int, 3>> out;
  out.reserve(tris.size() + 16);
  for (const auto& t : tris) {
    std::optional<EdgeCopies> e[3];  // edge k: t[k] - t[k+1]
    int mask = 0;
    for (int k = 0; k < 3; ++k) {
      e[k] = edge_copies(t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)], rest, lips, build, done, crossed);
      if (e[k]) mask |= 1 << k;
    }
    const auto on = [&](int k, int v) {  // copy of edge k's crossing on vertex v's side
      return copy_on_side(*e[k], t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)], v);
    };
    const int n_crossed = __builtin_popcount(static_cast<unsigned>(mask));
    if (n_crossed == 0) {
      out.push_back(t);
    } else if (n_crossed == 1) {
      // The cut ends inside the triangle: two triangles meeting at the vertex opposite the crossed edge.
      const int k = mask == 1 ? 0 : mask == 2 ? 1 : 2;
      const int a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)], c = t[static_cast<std::size_t>((k + 2) % 3)];
      out.push_back({a, on(k, a), c});
      out.push_back({on(k, b), b, c});
    } else if (n_crossed == 2) {
      // Lone vertex: shared by the two crossed edges. Rotate so that it is a, edges a-b (k0) and c-a (k2).
      const int uncrossed = mask == 3 ? 2 : mask == 5 ? 1 : 0;  // edge index not crossed
      const int ka = (uncrossed + 2) % 3;                          // lone vertex index: the one not on the uncrossed edge
      const int a = t[static_cast<std::size_t>(ka)], b = t[static_cast<std::size_t>((ka + 1) % 3)], c = t[static_cast<std::size_t>((ka + 2) % 3)];
      const int k_ab = ka, k_ca = (ka + 2) % 3;
      out.push_back({a, on(k_ab, a), on(k_ca, a)});
      out.push_back({on(k_ab, b), b, c});
      out.push_back({on(k_ab, b), c, on(k_ca, c)});
    } else {
      // Two cuts cross inside the triangle: its three corners, the middle left to the cap.
      for (int k = 0; k < 3; ++k) {
        const int a = t[static_cast<std::size_t>(k)];
        out.push_back({a, on(k, a), on((k + 2) % 3, a)});
      }
    }
  }
  // Close the loops the split opened: a slit (the cut ends inside the surface) side by side,
  // any other loop by a fan around a centre on the cut.
  const std::size_t first_cap = out.size();
  int caps = 0, slits = 0, ragged = 0;
  if (crossed > 0) {
    const auto key = [](int i, int j) { return directed_edge_key(i, j); };
    std::unordered_set<std::uint64_t> directed;
    directed.reserve(3 * out.size());
    for (const auto& t : out)
      for (int k = 0; k < 3; ++k) directed.insert(key(t[static_cast<std::size_t>(k)], t[static_cast<std::size_t>((k + 1) % 3)]));
    std::multimap<int, int> next;  // boundary edge i -> j (no opposite edge j -> i)
    for (const auto& t : out)
      for (int k = 0; k < 3; ++k) {
        const int i = t[static_cast<std::size_t>(k)], j = t[static_cast<std::size_t>((k + 1) % 3)];
        if (!directed.count(key(j, i))) next.emplace(i, j);
      }
    while (!next.empty()) {
      std::vector<int> loop{next.begin()->first};
      for (;;) {
        const auto it = next.find(loop.back());
        if (it == next.end()) break;
        const int j = it->second;
        next.erase(it);
        if (j == loop.front()) break;
        loop.push_back(j);
      }
      if (loop.size() < 3) continue;
      // A slit (the cut ends inside the surface): the loop passes an input vertex (a crack
      // end) or both copies of a crossing (a triangle the ragged crack front crosses thrice).
      bool slit = false;
      {
        std::unordered_set<int> on_loop(loop.begin(), loop.end());
        const int n_in = static_cast<int>(rest.cols());
        for (int v : loop) slit |= v < n_in || on_loop.count(n_in + ((v - n_in) ^ 1)) > 0;
      }
      if (slit && close_slit(loop, static_cast<int>(rest.cols()), build.rest, directed, out)) {
        ++caps;
        ++slits;
        continue;
      }
      if (slit && sew_slit(loop, build.rest, directed, out)) {
        ++caps;
        ++slits;
        ++ragged;
        continue;
      }
      Eigen::Vector3d centre = Eigen::Vector3d::Zero(), into = Eigen::Vector3d::Zero();
      Aabb box;
      for (int v : loop) {
        centre += build.rest[static_cast<std::size_t>(v)];
        into += build.into_side[static_cast<std::size_t>(v)];
        box.extend(build.rest[static_cast<std::size_t>(v)]);
      }
      centre /= static_cast<double>(loop.size());
      // The centre goes onto the cut (the lip across from the loop's centroid, on the loop's
      // side: a curved cut's loop is not planar) and is embedded in that lip's tet. A loop
      // of both sides (the cut ends inside the surface) or no lip found: the centroid, in
      // the tet containing it.
      int tet = -1;
      if (into.norm() > 1e-12) {
        Eigen::Vector3d on_lip;
        tet = lips.lip_along(centre, into.normalized(), (box.max - box.min).norm(), on_lip);
        if (tet >= 0) centre = on_lip;
      }
      Eigen::Vector4d w;
      if (tet < 0) tet = lips.locate(centre, w);
      if (tet < 0) tet = build.tet[static_cast<std::size_t>(loop.front())];
      const int c = build.add(centre, tet, -1, Eigen::Vector3d::Zero());
      for (std::size_t i = 0; i < loop.size(); ++i) out.push_back({loop[(i + 1) % loop.size()], loop[i], c});
      ++caps;
    }
  }
  SplitStructure s = build.finish();
  s.tris = std::move(out);
  s.crossed_edges = crossed;
  s.caps = caps;
  s.slits = slits;
  s.ragged_slits = ragged;
  s.first_cap_tri = static_cast<int>(first_cap);
  return s;
}

SplitStructure split_segments(const TetMesh& mesh, const CutLips& lips, const Eigen::Matrix3Xd& rest, const Embedding& embedding,
                              const std::vector<std::array<int, 2>>& segments) {
  Builder build(mesh, rest, embedding);
  std::unordered_map<std::uint64_t, std::optional<EdgeCopies>> done;
  int crossed = 0;
  std::vector<std::array<int, 2>> out;
  for (const auto& [a, b] : segments) {
    const auto c = edge_copies(a, b, rest, lips, build, done, crossed);
    if (!c) {
      out.push_back({a, b});
      continue;
    }
    out.push_back({a, copy_on_side(*c, a, b, a)});
    out.push_back({copy_on_side(*c, a, b, b), b});
  }
  SplitStructure s = build.finish();
  s.segments = std::move(out);
  s.crossed_edges = crossed;
  return s;
}

}  // namespace arnav::host::cut
