#include "host/register/self_contact.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>
#include <utility>

#include "host/register/surface_index.hpp"

namespace arnav::host {
namespace {

// Closest point of triangle t (positions x) to p: returns the plane distance
// n . (p - q) (face normal n, outward), with the distance |p - q|, the barycentric
// weights, the point and the normal.
struct Side {
  double plane = 0.0, distance = 0.0;
  Eigen::Vector3d w, point, normal;
  double lateral() const { return std::sqrt(std::max(0.0, distance * distance - plane * plane)); }
};
Side side_of(const Eigen::Matrix3Xd& x, const std::array<int, 3>& t, const Eigen::Vector3d& p) {
  const Eigen::Vector3d a = x.col(t[0]), b = x.col(t[1]), c = x.col(t[2]);
  Side s;
  s.w = closest_on_triangle(p, a, b, c);
  s.point = s.w[0] * a + s.w[1] * b + s.w[2] * c;
  Eigen::Vector3d n = (b - a).cross(c - a);
  const double len = n.norm();
  s.normal = len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
  s.plane = s.normal.dot(p - s.point);
  s.distance = (p - s.point).norm();
  return s;
}

// At rest, a vertex faces a triangle of another part when it lies in front of it, within
// 60 degrees of its normal (coplanar neighbours and the far faces of a thin part do not).
bool faces_at_rest(const Side& s) { return s.plane > 0.5 * s.distance; }

}  // namespace

SelfContactDetector::SelfContactDetector(const Eigen::Matrix3Xd& rest, const std::vector<std::array<int, 3>>& tris, double exclusion_mm)
    : rest_(rest), tris_(tris) {
  const int n = static_cast<int>(rest.cols());
  std::vector<std::vector<std::pair<int, double>>> adj(static_cast<std::size_t>(n));
  double edge_sum = 0.0;
  for (const auto& t : tris) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[static_cast<std::size_t>(k)], b = t[static_cast<std::size_t>((k + 1) % 3)];
      if (a < 0 || b < 0 || a >= n || b >= n) throw std::invalid_argument("self contact: a triangle indexes a missing vertex");
      const double l = (rest.col(a) - rest.col(b)).norm();
      adj[static_cast<std::size_t>(a)].push_back({b, l});
      adj[static_cast<std::size_t>(b)].push_back({a, l});
      edge_sum += l;
    }
  }
  exclusion_mm_ = exclusion_mm > 0 ? exclusion_mm : (tris.empty() ? 0.0 : 3.0 * edge_sum / (3.0 * static_cast<double>(tris.size())));
  near_.resize(static_cast<std::size_t>(n));
  std::vector<double> dist(static_cast<std::size_t>(n), std::numeric_limits<double>::infinity());
  for (int v = 0; v < n; ++v) {
    if (adj[static_cast<std::size_t>(v)].empty()) continue;
    vertices_.push_back(v);
    // Dijkstra on the edge graph, bounded by the exclusion radius.
    std::vector<int> touched;
    using Item = std::pair<double, int>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    dist[static_cast<std::size_t>(v)] = 0.0;
    touched.push_back(v);
    queue.push({0.0, v});
    while (!queue.empty()) {
      const auto [d, u] = queue.top();
      queue.pop();
      if (d > dist[static_cast<std::size_t>(u)]) continue;
      for (const auto& [w, l] : adj[static_cast<std::size_t>(u)]) {
        const double nd = d + l;
        if (nd > exclusion_mm_ || nd >= dist[static_cast<std::size_t>(w)]) continue;
        if (std::isinf(dist[static_cast<std::size_t>(w)])) touched.push_back(w);
        dist[static_cast<std::size_t>(w)] = nd;
        queue.push({nd, w});
      }
    }
    // the triangles around v's ring always count as v's own part
    for (const auto& [w, l] : adj[static_cast<std::size_t>(v)])
      if (std::isinf(dist[static_cast<std::size_t>(w)])) {
        dist[static_cast<std::size_t>(w)] = l;
        touched.push_back(w);
      }
    std::sort(touched.begin(), touched.end());
    near_[static_cast<std::size_t>(v)] = touched;
    for (int u : touched) dist[static_cast<std::size_t>(u)] = std::numeric_limits<double>::infinity();
  }
  // Rest clearance of each vertex (capped: beyond the cap the vertex is checked once the
  // organ has moved that far).
  clearance_.assign(static_cast<std::size_t>(n), 0.0);
  if (tris.empty()) return;
  const double cap = 8.0 * exclusion_mm_;
  const SurfaceIndex index(rest, tris);
  const int nv = static_cast<int>(vertices_.size());
#pragma omp parallel for schedule(dynamic, 64)
  for (int i = 0; i < nv; ++i) {
    const int v = vertices_[static_cast<std::size_t>(i)];
    const std::vector<int>& near = near_[static_cast<std::size_t>(v)];
    const Eigen::Vector3d pv = rest.col(v);
    auto skip = [&](int ti) {
      const auto& t = tris_[static_cast<std::size_t>(ti)];
      for (int u : t)
        if (std::binary_search(near.begin(), near.end(), u)) return true;
      return !faces_at_rest(side_of(rest_, t, pv));
    };
    const SurfaceHit h = index.closest(pv, cap, skip);
    clearance_[static_cast<std::size_t>(v)] = h.tri >= 0 ? h.distance_mm : cap;
  }
}

std::vector<SelfContact> SelfContactDetector::find(const Eigen::Matrix3Xd& x, double margin_mm, double max_depth_mm) const {
  if (x.cols() != rest_.cols()) throw std::invalid_argument("self contact: positions have " + std::to_string(x.cols()) + " columns, the surface " + std::to_string(rest_.cols()));
  std::vector<SelfContact> out;
  if (tris_.empty()) return out;
  const SurfaceIndex index(x, tris_);
  const double reach = std::max(margin_mm, max_depth_mm);
  const double lateral_limit = std::max(2.0 * margin_mm, 0.25 * exclusion_mm_);
  double moved = 0.0;  // largest displacement from rest of a surface vertex
  for (int v : vertices_) moved = std::max(moved, (x.col(v) - rest_.col(v)).norm());
  const int nv = static_cast<int>(vertices_.size());
  std::vector<SelfContact> found(static_cast<std::size_t>(nv));
#pragma omp parallel for schedule(dynamic, 64)
  for (int i = 0; i < nv; ++i) {
    const int v = vertices_[static_cast<std::size_t>(i)];
    // it and any triangle moved at most `moved`: no contact while the rest gap exceeds 2 moved + reach
    const double clear = clearance_[static_cast<std::size_t>(v)];
    if (clear > 2.0 * moved + reach) continue;
    const std::vector<int>& near = near_[static_cast<std::size_t>(v)];
    const Eigen::Vector3d pv_rest = rest_.col(v);
    auto skip = [&](int ti) {
      const auto& t = tris_[static_cast<std::size_t>(ti)];
      for (int u : t)
        if (std::binary_search(near.begin(), near.end(), u)) return true;
      return !faces_at_rest(side_of(rest_, t, pv_rest));
    };
    const SurfaceHit h = index.closest(x.col(v), reach, skip);
    if (h.tri < 0) continue;
    const auto& t = tris_[static_cast<std::size_t>(h.tri)];
    const Side now = side_of(x, t, x.col(v));
    SelfContact c;
    c.signed_distance_mm = now.plane;
    c.barycentric = now.w;
    c.point = now.point;
    c.normal = now.normal;
    c.wanted_mm = std::min(margin_mm, side_of(rest_, t, pv_rest).plane);
    // in contact: nearer than wanted (or behind) and over the triangle, not beside it
    if (c.signed_distance_mm >= c.wanted_mm || c.signed_distance_mm < -max_depth_mm || now.lateral() > lateral_limit) continue;
    c.vertex = v;
    c.tri = h.tri;
    found[static_cast<std::size_t>(i)] = c;
  }
  for (const auto& c : found)
    if (c.vertex >= 0) out.push_back(c);
  return out;
}

int SelfContactDetector::count_crossed(const Eigen::Matrix3Xd& x, double max_depth_mm) const {
  int n = 0;
  for (const auto& c : find(x, 0.0, max_depth_mm))
    if (c.signed_distance_mm < 0) ++n;
  return n;
}

}  // namespace arnav::host
