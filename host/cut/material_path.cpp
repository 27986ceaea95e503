#include "host/cut/material_path.hpp"

#include <algorithm>
#include <cmath>

namespace arnav::host::cut {

void MaterialPathMeter::record_sweep(TetCutter& cutter, const Eigen::Matrix3Xd& x, const SweptSurface& sweep) {
  const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
  // The pull-back is affine per tet; over a blade segment that spans tets of different
  // strain (the tissue the blade pushed before cutting, a grasp nearby) the segment's image
  // is curved: the lines are resampled every ~1 mm (at most 64 segments) so the chords stay on it.
  const int strips = sweep.strips;
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
  // Pull back: rest = the barycentric combination of the rest positions of the tet holding
  // the point now; a point outside the tissue (or in the opening of a cut) keeps the
  // displacement of the nearest mapped point of its line (the blade's part outside the
  // organ cuts nothing).
  std::vector<Eigen::Vector3d> r(p.size());
  std::vector<char> mapped(p.size(), 0);
  bool refit = true;
  for (std::size_t k = 0; k < p.size(); ++k) {
    Eigen::Vector4d w;
    const int t = cutter.locate(p[k], x, w, refit);
    refit = false;
    if (t < 0 || w.minCoeff() < -1e-6) continue;  // outside the tissue (or in a cut's opening)
    const auto& tet = cutter.mesh().tets[static_cast<std::size_t>(t)];
    r[k].setZero();
    for (int j = 0; j < 4; ++j) r[k] += w[j] * rest.col(tet[static_cast<std::size_t>(j)]);
    mapped[k] = 1;
  }
  // A point outside takes the displacement of the nearest mapped point of its own line, or,
  // when its whole line lies outside (the blade entering from above the organ: its start
  // line still outside, its end line inside), of the other line's point at the same place
  // along the blade. Nothing mapped on either line: the sweep missed the tissue.
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
      if (m < 0) return;
      shift[k] = r[static_cast<std::size_t>(m)] - p[static_cast<std::size_t>(m)];
    }
  }
  for (std::size_t k = 0; k < p.size(); ++k)
    if (!mapped[k]) r[k] = p[k] + shift[k];
  Sweep sw;
  for (int i = 0; i < n; ++i) {
    const auto f0 = static_cast<std::size_t>(i), f1 = f0 + 1, t0 = static_cast<std::size_t>(n + 1 + i), t1 = t0 + 1;
    sw.tris.push_back({r[f0], r[f1], r[t0]});
    sw.tris.push_back({r[f1], r[t1], r[t0]});
  }
  for (const auto& t : sw.tris) {
    sw.box.extend(t.a);
    sw.box.extend(t.b);
    sw.box.extend(t.c);
  }
  sweeps_.push_back(std::move(sw));
  if (sweeps_.size() > static_cast<std::size_t>(max_sweeps_)) sweeps_.pop_front();
}

int MaterialPathMeter::measure_new_cut_vertices(const TetCutter& cutter, double& worst_mm, std::vector<double>* distances_mm) {
  const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
  measured_.resize(static_cast<std::size_t>(rest.cols()), 0);
  int fresh = 0;
  worst_mm = -1.0;
  for (Eigen::Index v = 0; v < rest.cols(); ++v) {
    if (measured_[static_cast<std::size_t>(v)] || !cutter.on_cut(static_cast<int>(v))) continue;
    measured_[static_cast<std::size_t>(v)] = 1;
    ++fresh;
    double best = 1e300;
    const Eigen::Vector3d p = rest.col(v);
    for (auto it = sweeps_.rbegin(); it != sweeps_.rend(); ++it) {
      if (it->box.exteriorDistance(p) >= best) continue;  // newest first: the bound tightens fast
      for (const auto& t : it->tris) best = std::min(best, point_triangle_distance(p, t));
    }
    if (best < 1e299) {
      worst_mm = std::max(worst_mm, best);
      if (distances_mm) distances_mm->push_back(best);
    }
  }
  return fresh;
}

}  // namespace arnav::host::cut
