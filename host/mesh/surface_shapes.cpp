#include "host/mesh/surface_shapes.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <numbers>
#include <stdexcept>

namespace arnav::host {

TriMesh make_ellipsoid_surface(const Eigen::Vector3d& center, const Eigen::Vector3d& radii, int subdivisions) {
  if (subdivisions < 0 || subdivisions > 6) throw std::invalid_argument("ellipsoid subdivisions must be 0..6");
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, g, 0}, {1, g, 0}, {-1, -g, 0}, {1, -g, 0}, {0, -1, g}, {0, 1, g},
                                    {0, -1, -g}, {0, 1, -g}, {g, 0, -1}, {g, 0, 1}, {-g, 0, -1}, {-g, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                       {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                                       {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> next;
    for (const auto& t : f) {
      const int ab = midpoint(t[0], t[1]), bc = midpoint(t[1], t[2]), ca = midpoint(t[2], t[0]);
      next.push_back({t[0], ab, ca});
      next.push_back({t[1], bc, ab});
      next.push_back({t[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    f = std::move(next);
  }
  TriMesh out;
  out.positions_World_mm.resize(3, static_cast<int>(v.size()));
  for (std::size_t i = 0; i < v.size(); ++i) out.positions_World_mm.col(static_cast<int>(i)) = center + radii.cwiseProduct(v[i]);
  out.tris = std::move(f);
  return out;
}

double winding_number(const TriMesh& s, const Eigen::Vector3d& p) {
  // Sum of signed solid angles (Van Oosterom and Strackee) over 4 pi.
  double total = 0;
  for (const auto& t : s.tris) {
    const Eigen::Vector3d a = s.positions_World_mm.col(t[0]) - p, b = s.positions_World_mm.col(t[1]) - p,
                          c = s.positions_World_mm.col(t[2]) - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    total += 2.0 * std::atan2(num, den);
  }
  return total / (4.0 * std::numbers::pi);
}

Eigen::Vector3d closed_surface_centroid(const Eigen::Matrix3Xd& p_mm, const std::vector<std::array<int, 3>>& tris) {
  double volume = 0.0;
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
  for (const auto& t : tris) {
    const Eigen::Vector3d a = p_mm.col(t[0]), b = p_mm.col(t[1]), c = p_mm.col(t[2]);
    const double v = a.dot(b.cross(c)) / 6.0;
    volume += v;
    moment += v * (a + b + c) / 4.0;
  }
  return std::abs(volume) > 0 ? Eigen::Vector3d(moment / volume) : Eigen::Vector3d(p_mm.rowwise().mean());
}

}  // namespace arnav::host
