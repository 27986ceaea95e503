#include "host/cut/bvh.hpp"

#include <algorithm>
#include <numeric>

namespace arnav::host::cut {

namespace {
constexpr int kLeafSize = 4;
}

void Bvh::build(const std::vector<Aabb>& prim_boxes) {
  prim_boxes_ = prim_boxes;
  order_.resize(prim_boxes_.size());
  std::iota(order_.begin(), order_.end(), 0);
  nodes_.clear();
  if (prim_boxes_.empty()) return;
  std::vector<Eigen::Vector3d> centroids(prim_boxes_.size());
  for (std::size_t i = 0; i < prim_boxes_.size(); ++i) centroids[i] = 0.5 * (prim_boxes_[i].min + prim_boxes_[i].max);
  nodes_.reserve(2 * prim_boxes_.size() / kLeafSize + 2);
  build_node(0, static_cast<int>(prim_boxes_.size()), centroids);
  refit_node(0);
}

int Bvh::build_node(int first, int count, std::vector<Eigen::Vector3d>& centroids) {
  const int id = static_cast<int>(nodes_.size());
  nodes_.push_back({});
  if (count <= kLeafSize) {
    nodes_[static_cast<std::size_t>(id)].first = first;
    nodes_[static_cast<std::size_t>(id)].count = count;
    return id;
  }
  Aabb cb;
  for (int i = first; i < first + count; ++i) cb.extend(centroids[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])]);
  int axis = 0;
  (cb.max - cb.min).maxCoeff(&axis);
  const int mid = first + count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + mid, order_.begin() + first + count, [&](int a, int b) {
    return centroids[static_cast<std::size_t>(a)][axis] < centroids[static_cast<std::size_t>(b)][axis];
  });
  const int left = build_node(first, mid - first, centroids);
  const int right = build_node(mid, first + count - mid, centroids);
  nodes_[static_cast<std::size_t>(id)].left = left;
  nodes_[static_cast<std::size_t>(id)].right = right;
  return id;
}

void Bvh::refit(const std::vector<Aabb>& prim_boxes) {
  if (prim_boxes.size() != prim_boxes_.size()) {
    build(prim_boxes);
    return;
  }
  prim_boxes_ = prim_boxes;
  if (!nodes_.empty()) refit_node(0);
}

void Bvh::refit_node(int n) {
  Aabb b;
  const Node node = nodes_[static_cast<std::size_t>(n)];
  if (node.left < 0) {
    for (int i = node.first; i < node.first + node.count; ++i) b.extend(prim_boxes_[static_cast<std::size_t>(order_[static_cast<std::size_t>(i)])]);
  } else {
    refit_node(node.left);
    refit_node(node.right);
    b = nodes_[static_cast<std::size_t>(node.left)].box;
    b.extend(nodes_[static_cast<std::size_t>(node.right)].box);
  }
  nodes_[static_cast<std::size_t>(n)].box = b;
}

void Bvh::query(const Aabb& box, const std::function<void(int)>& visit) const {
  if (nodes_.empty()) return;
  std::vector<int> stack{0};
  while (!stack.empty()) {
    const Node& node = nodes_[static_cast<std::size_t>(stack.back())];
    stack.pop_back();
    if (!node.box.overlaps(box)) continue;
    if (node.left < 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        const int p = order_[static_cast<std::size_t>(i)];
        if (prim_boxes_[static_cast<std::size_t>(p)].overlaps(box)) visit(p);
      }
    } else {
      stack.push_back(node.left);
      stack.push_back(node.right);
    }
  }
}

std::vector<Aabb> triangle_boxes(const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x) {
  std::vector<Aabb> boxes(tris.size());
  for (std::size_t i = 0; i < tris.size(); ++i)
    for (int v : tris[i]) boxes[i].extend(Eigen::Vector3d(x.col(v)));
  return boxes;
}

Contact blade_contact(const Bvh& bvh, const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x,
                      const BladeSegment& blade) {
  return blade_contact([&bvh](const Aabb& box, const std::function<void(int)>& visit) { bvh.query(box, visit); }, tris, x, blade);
}

Contact blade_contact(const TriangleQuery& query, const std::vector<std::array<int, 3>>& tris, const Eigen::Matrix3Xd& x,
                      const BladeSegment& blade) {
  Contact c;
  Aabb box;
  box.extend(blade.tip_World_mm);
  box.extend(blade.heel_World_mm);
  std::vector<std::pair<double, int>> hits;  // parameter from the tip, triangle
  query(box, [&](int i) {
    const auto& t = tris[static_cast<std::size_t>(i)];
    if (t[0] < 0) return;
    const Triangle tri{x.col(t[0]), x.col(t[1]), x.col(t[2])};
    double s = 0;
    if (segment_triangle_intersection(blade.tip_World_mm, blade.heel_World_mm, tri, s)) hits.emplace_back(s, i);
  });
  if (hits.empty()) return c;
  std::sort(hits.begin(), hits.end());
  const auto& entry = hits.back();  // closest to the heel
  c.touching = true;
  c.triangle = entry.second;
  c.point_World_mm = blade.tip_World_mm + entry.first * (blade.heel_World_mm - blade.tip_World_mm);
  c.tip_inside = hits.size() % 2 == 1;
  c.depth_mm = c.tip_inside ? (c.point_World_mm - blade.tip_World_mm).norm() : 0.0;
  return c;
}

}  // namespace arnav::host::cut
