#include "host/cut/ring_path.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <iomanip>
#include <numeric>
#include <sstream>
#include <stdexcept>

namespace arnav::host::cut {

std::string RingPath::csv() const {
  std::ostringstream out;
  out << "# arnav-sim --scalpel path (docs/cut.md, \"Ring path from the scene\"): ring of radius " << radius_mm << " mm round the tumour centred at ("
      << centre_World_mm.transpose() << ") mm,\n# axis (" << axis.transpose() << ") towards the access surface, bottom cut " << bottom_mm
      << " mm beyond the centre; World frame, mm, s.\n";
  out << "t_s,tip_x,tip_y,tip_z,heel_x,heel_y,heel_z,cutting\n" << std::setprecision(10);
  for (const auto& s : path.samples)
    out << s.t_s << ',' << s.blade.tip_World_mm.x() << ',' << s.blade.tip_World_mm.y() << ',' << s.blade.tip_World_mm.z() << ',' << s.blade.heel_World_mm.x() << ','
        << s.blade.heel_World_mm.y() << ',' << s.blade.heel_World_mm.z() << ',' << (s.cutting ? 1 : 0) << '\n';
  return out.str();
}

RingPath make_ring_path(const TetMesh& mesh, const Eigen::Matrix3Xd& x, const std::vector<int>& fixed_vertices, const Eigen::Matrix3Xd& tumour,
                        const RingPathSettings& o) {
  if (tumour.cols() == 0) throw std::invalid_argument("ring path: the tumour has no points");
  if (x.cols() != mesh.num_vertices()) throw std::invalid_argument("ring path: positions do not match the mesh");
  if (!(o.margin_mm >= 0 && o.ring_speed_mm_s > 0 && o.bottom_speed_mm_s > 0 && o.plunge_speed_mm_s > 0 && o.directions >= 6))
    throw std::invalid_argument("ring path: margin >= 0, speeds > 0 and at least 6 directions");
  RingPath best;
  best.centre_World_mm = tumour.rowwise().mean();
  const Eigen::Vector3d c = best.centre_World_mm;
  double best_surface = 1e300;
  bool found = false;
  int closest_fixed_count = -1;
  for (int k = 0; k < o.directions; ++k) {
    // Evenly spread unit vectors (Fibonacci sphere).
    const double z = 1.0 - 2.0 * (k + 0.5) / o.directions, rho = std::sqrt(std::max(0.0, 1.0 - z * z));
    const double phi = k * M_PI * (3.0 - std::sqrt(5.0));
    const Eigen::Vector3d d(rho * std::cos(phi), rho * std::sin(phi), z);
    double across = 0.0, low = 1e300, high = -1e300;
    for (int i = 0; i < tumour.cols(); ++i) {
      const Eigen::Vector3d p = tumour.col(i) - c;
      const double a = p.dot(d);
      across = std::max(across, (p - a * d).norm());
      low = std::min(low, a);
      high = std::max(high, a);
    }
    const double radius = across + o.margin_mm, bottom = -low + o.margin_mm;
    double surface = high;
    for (int v = 0; v < x.cols(); ++v) {
      const Eigen::Vector3d p = x.col(v) - c;
      const double a = p.dot(d);
      if (a > surface && (p - a * d).norm() <= radius + o.bottom_extension_mm) surface = a;
    }
    int fixed_inside = 0;
    for (int v : fixed_vertices) {
      const Eigen::Vector3d p = x.col(v) - c;
      const double a = p.dot(d);
      if (a >= -bottom - 1.0 && (p - a * d).norm() <= radius + 1.0) ++fixed_inside;
    }
    if (fixed_inside > 0) {
      if (closest_fixed_count < 0 || fixed_inside < closest_fixed_count) closest_fixed_count = fixed_inside;
      continue;
    }
    if (surface < best_surface) {
      best_surface = surface;
      found = true;
      best.axis = d;
      best.radius_mm = radius;
      best.bottom_mm = bottom;
      best.surface_mm = surface;
    }
  }
  if (!found)
    throw std::invalid_argument("ring path: every access direction puts fixed vertices inside the block (at least " + std::to_string(closest_fixed_count) +
                                "): the tumour lies against the attachment, no ring frees it");
  const Eigen::Vector3d d = best.axis;
  const Eigen::Vector3d e1 = d.unitOrthogonal(), e2 = d.cross(e1);
  // The crack front (where a blade's end stops inside the tissue) lags up to a tet behind
  // the blade's end: the ring's wall reaches below the bottom cut, and the bottom cut beyond
  // the ring, by at least the longest edge of the tets round the ring's foot, so that the
  // two cuts meet in the mesh (not only in space).
  double lag = 0.0;
  for (const auto& tet : mesh.tets) {
    bool near = false;
    for (int v : tet) {
      const Eigen::Vector3d p = x.col(v) - c;
      const double a = p.dot(d);
      near |= std::abs(a + best.bottom_mm) <= best.radius_mm && std::abs((p - a * d).norm() - best.radius_mm) <= best.radius_mm;
    }
    if (!near) continue;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) lag = std::max(lag, (x.col(tet[static_cast<std::size_t>(i)]) - x.col(tet[static_cast<std::size_t>(j)])).norm());
  }
  best.overshoot_mm = std::max(o.bottom_overshoot_mm, lag);
  best.extension_mm = std::max(o.bottom_extension_mm, lag);
  const double r = best.radius_mm, outside = best.surface_mm + o.outside_mm;
  auto point = [&](double axial, double radial, double angle) {
    return Eigen::Vector3d(c + axial * d + radial * (std::cos(angle) * e1 + std::sin(angle) * e2));
  };
  auto& samples = best.path.samples;
  double t = 0.0;
  auto add = [&](double dt, const Eigen::Vector3d& tip, const Eigen::Vector3d& heel, bool cutting) {
    t += dt;
    samples.push_back({t, {tip, heel}, cutting});
  };
  // Ring: the blade along the axis, tip past the bottom cut, heel outside the organ.
  const double tip_axial = -best.bottom_mm - best.overshoot_mm, length = outside - tip_axial;
  samples.push_back({0.0, {point(outside, r, 0.0), point(outside + length, r, 0.0)}, false});
  add(o.wait_s, point(outside, r, 0.0), point(outside + length, r, 0.0), true);
  add(length / o.plunge_speed_mm_s, point(tip_axial, r, 0.0), point(outside, r, 0.0), true);
  const double ring_angle = 2.0 * M_PI + o.overlap_deg * M_PI / 180.0, step = 2.5 * M_PI / 180.0;
  const int ring_steps = static_cast<int>(std::ceil(ring_angle / step));
  for (int i = 1; i <= ring_steps; ++i) {
    const double a = ring_angle * i / ring_steps;
    add(r * ring_angle / ring_steps / o.ring_speed_mm_s, point(tip_axial, r, a), point(outside, r, a), true);
  }
  add(length / o.plunge_speed_mm_s, point(outside, r, ring_angle), point(outside + length, r, ring_angle), false);  // lifted out along itself
  best.ring_end_s = t;
  // Bottom cut: a straight blade across the axis in the plane bottom_mm beyond the tumour,
  // spanning the ring and extension_mm beyond it on both sides, swept across the ring from
  // outside the organ on the side where the organ's edge is nearest (the shortest slit
  // through healthy tissue) to extension_mm past the ring's far side.
  const double half = r + best.extension_mm, plane = -best.bottom_mm;
  double best_edge = 1e300, best_angle = 0.0;
  for (int k = 0; k < 16; ++k) {
    const double a = 2.0 * M_PI * k / 16;
    const Eigen::Vector3d along = std::cos(a) * e1 + std::sin(a) * e2, across = d.cross(along);
    double edge = r;
    for (int v = 0; v < x.cols(); ++v) {
      const Eigen::Vector3d p = x.col(v) - c;
      if (std::abs(p.dot(d) - plane) > 10.0 || std::abs(p.dot(across)) > half + 10.0) continue;
      edge = std::max(edge, p.dot(along));
    }
    if (edge < best_edge) {
      best_edge = edge;
      best_angle = a;
    }
  }
  const Eigen::Vector3d along = std::cos(best_angle) * e1 + std::sin(best_angle) * e2, across = d.cross(along);
  auto bottom_blade = [&](double s) {
    const Eigen::Vector3d m = c + plane * d + s * along;
    return std::make_pair(Eigen::Vector3d(m - half * across), Eigen::Vector3d(m + half * across));
  };
  const double s_start = best_edge + o.outside_mm, s_end = -half;
  const auto [tip0, heel0] = bottom_blade(s_start);
  const auto [tip1, heel1] = bottom_blade(s_end);
  add(1e-3, tip0, heel0, false);  // moved outside the organ in one frame
  add(o.wait_s, tip0, heel0, true);
  add((s_start - s_end) / o.bottom_speed_mm_s, tip1, heel1, false);
  best.cut_end_s = t;
  // Out of the organ in one frame (cutting off: no contact on the way), then the block falls.
  const Eigen::Vector3d away = c + (outside + length) * d;
  add(1e-3, away, away + length * d, false);
  add(o.hold_s, away, away + length * d, false);
  return best;
}

BladeSegment follow_tracked(const BladeSegment& planned, const Eigen::Matrix3Xd& then, const Eigen::Matrix3Xd& now) {
  if (then.cols() != now.cols() || then.cols() < 3) {
    throw std::invalid_argument("follow_tracked: the tracked point sets must be the same points (" + std::to_string(then.cols()) + " then, " +
                                std::to_string(now.cols()) + " now), at least 3");
  }
  const Eigen::Matrix4d T = Eigen::umeyama(then, now, false);
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  const Eigen::Vector3d p = T.topRightCorner<3, 1>();
  return {R * planned.tip_World_mm + p, R * planned.heel_World_mm + p};
}

bool piece_is_free(const TetMesh& mesh, int seed_tet, const std::vector<int>& fixed_vertices) {
  if (seed_tet < 0 || seed_tet >= mesh.num_tets()) throw std::invalid_argument("piece_is_free: tet " + std::to_string(seed_tet) + " is not in the mesh");
  std::vector<int> parent(static_cast<std::size_t>(mesh.num_vertices()));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int v) {
    while (parent[static_cast<std::size_t>(v)] != v) v = parent[static_cast<std::size_t>(v)] = parent[static_cast<std::size_t>(parent[static_cast<std::size_t>(v)])];
    return v;
  };
  for (const auto& tet : mesh.tets)
    for (int k = 1; k < 4; ++k) parent[static_cast<std::size_t>(find(tet[static_cast<std::size_t>(k)]))] = find(tet[0]);
  const int root = find(mesh.tets[static_cast<std::size_t>(seed_tet)][0]);
  for (int v : fixed_vertices)
    if (v >= 0 && v < mesh.num_vertices() && find(v) == root) return false;
  return true;
}

}  // namespace arnav::host::cut
