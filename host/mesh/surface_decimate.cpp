#include "host/mesh/surface_decimate.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <queue>
#include <stdexcept>

namespace arnav::host {
namespace {

using Quadric = Eigen::Matrix4d;

struct Candidate {
  double cost;
  int a, b;
  int version_a, version_b;
  Eigen::Vector3d target;
  bool operator>(const Candidate& o) const { return cost > o.cost; }
};

double quadric_cost(const Quadric& q, const Eigen::Vector3d& p) {
  const Eigen::Vector4d h(p.x(), p.y(), p.z(), 1.0);
  return std::max(0.0, h.dot(q * h));
}

}  // namespace

DecimationReport decimate_surface(TriMesh& s, int target) {
  if (target < 8) throw std::invalid_argument("decimate_surface: target must be at least 8 vertices");
  DecimationReport report;
  Eigen::Matrix3Xd& x = s.positions_World_mm;
  const int nv = static_cast<int>(x.cols());
  report.input_vertices = nv;
  std::vector<std::array<int, 3>> faces = s.tris;
  std::vector<char> face_alive(faces.size(), 1), vertex_alive(nv, 1);
  std::vector<int> version(nv, 0);
  std::vector<std::vector<int>> vfaces(nv);
  std::vector<Quadric> Q(nv, Quadric::Zero());
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const Eigen::Vector3d a = x.col(faces[f][0]), b = x.col(faces[f][1]), c = x.col(faces[f][2]);
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double area2 = n.norm();
    if (area2 <= 0) continue;
    n /= area2;
    const Eigen::Vector4d plane(n.x(), n.y(), n.z(), -n.dot(a));
    const Quadric K = plane * plane.transpose() * (area2 / 2.0);  // area-weighted
    for (int v : faces[f]) {
      Q[v] += K;
      vfaces[v].push_back(static_cast<int>(f));
    }
  }
  auto neighbours = [&](int v) {
    std::vector<int> out;
    for (int f : vfaces[v])
      if (face_alive[f])
        for (int w : faces[f])
          if (w != v) out.push_back(w);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  };
  auto candidate = [&](int a, int b) {
    const Quadric q = Q[a] + Q[b];
    Eigen::Matrix3d A = q.topLeftCorner<3, 3>();
    const Eigen::Vector3d rhs = -q.topRightCorner<3, 1>();
    Candidate c{0, a, b, version[a], version[b], 0.5 * (x.col(a) + x.col(b))};
    const Eigen::FullPivLU<Eigen::Matrix3d> lu(A);
    const Eigen::Vector3d mid = c.target;
    if (lu.rank() == 3) {
      const Eigen::Vector3d p = lu.solve(rhs);
      // Keep the optimum near the edge: far optima come from nearly flat quadrics.
      if ((p - mid).norm() <= (x.col(a) - x.col(b)).norm()) c.target = p;
    }
    c.cost = quadric_cost(q, c.target);
    for (const Eigen::Vector3d& p : {Eigen::Vector3d(x.col(a)), Eigen::Vector3d(x.col(b)), mid}) {
      const double e = quadric_cost(q, p);
      if (e < c.cost) c.cost = e, c.target = p;
    }
    return c;
  };
  std::priority_queue<Candidate, std::vector<Candidate>, std::greater<Candidate>> heap;
  for (int v = 0; v < nv; ++v)
    for (int w : neighbours(v))
      if (v < w) heap.push(candidate(v, w));

  int alive = nv;
  while (alive > target && !heap.empty()) {
    const Candidate c = heap.top();
    heap.pop();
    if (!vertex_alive[c.a] || !vertex_alive[c.b] || version[c.a] != c.version_a || version[c.b] != c.version_b) continue;
    // Link condition: on a closed manifold the edge's two triangles give exactly two
    // common neighbours; more would pinch the surface.
    const std::vector<int> na = neighbours(c.a), nb = neighbours(c.b);
    std::vector<int> common;
    std::set_intersection(na.begin(), na.end(), nb.begin(), nb.end(), std::back_inserter(common));
    if (common.size() != 2 || na.size() <= 3 || nb.size() <= 3) continue;
    // No triangle may flip or collapse to a sliver.
    bool ok = true;
    for (int v : {c.a, c.b}) {
      for (int f : vfaces[v]) {
        if (!face_alive[f]) continue;
        const auto& t = faces[f];
        if (std::find(t.begin(), t.end(), c.a) != t.end() && std::find(t.begin(), t.end(), c.b) != t.end()) continue;
        Eigen::Vector3d p[3], q[3];
        for (int k = 0; k < 3; ++k) {
          p[k] = x.col(t[k]);
          q[k] = (t[k] == c.a || t[k] == c.b) ? c.target : p[k];
        }
        const Eigen::Vector3d n0 = (p[1] - p[0]).cross(p[2] - p[0]), n1 = (q[1] - q[0]).cross(q[2] - q[0]);
        const double longest = std::max({(q[1] - q[0]).squaredNorm(), (q[2] - q[1]).squaredNorm(), (q[0] - q[2]).squaredNorm()});
        if (n0.dot(n1) <= 0.2 * n0.norm() * n1.norm() || n1.norm() < 0.05 * longest) ok = false;
      }
    }
    if (!ok) continue;
    // Collapse b into a.
    for (int f : vfaces[c.b]) {
      if (!face_alive[f]) continue;
      auto& t = faces[f];
      if (std::find(t.begin(), t.end(), c.a) != t.end()) {
        face_alive[f] = 0;
        continue;
      }
      for (int& v : t)
        if (v == c.b) v = c.a;
      vfaces[c.a].push_back(f);
    }
    x.col(c.a) = c.target;
    Q[c.a] += Q[c.b];
    vertex_alive[c.b] = 0;
    ++version[c.a];
    --alive;
    report.max_error_mm2 = std::max(report.max_error_mm2, c.cost);
    for (int w : neighbours(c.a)) {
      ++version[w];  // its other edges' costs are unchanged, but re-push them with new stamps
    }
    for (int w : neighbours(c.a)) {
      heap.push(candidate(c.a, w));
      for (int u : neighbours(w))
        if (u != c.a) heap.push(candidate(std::min(u, w), std::max(u, w)));
    }
  }
  // Compact.
  std::vector<int> map(nv, -1);
  int next = 0;
  for (int v = 0; v < nv; ++v)
    if (vertex_alive[v]) map[v] = next++;
  Eigen::Matrix3Xd y(3, next);
  for (int v = 0; v < nv; ++v)
    if (map[v] >= 0) y.col(map[v]) = x.col(v);
  std::vector<std::array<int, 3>> tris;
  for (std::size_t f = 0; f < faces.size(); ++f)
    if (face_alive[f]) tris.push_back({map[faces[f][0]], map[faces[f][1]], map[faces[f][2]]});
  s.positions_World_mm = std::move(y);
  s.tris = std::move(tris);
  report.output_vertices = next;
  return report;
}

}  // namespace arnav::host
