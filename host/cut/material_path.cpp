#include "host/cut/material_path.hpp"

#include <algorithm>
#include <cmath>

namespace arnav::host::cut {

void MaterialPathMeter::record_sweep(TetCutter& cutter, const Eigen::Matrix3Xd& x, const SweptSurface& sweep) {
  // The surface the blade swept, pulled back into the rest configuration through the tissue
  // as it was at this sample (TetCutter::sweep_in_material); nothing mapped: the sweep missed.
  Sweep sw;
  sw.tris = cutter.sweep_in_material(sweep, x, true);
  if (sw.tris.empty()) return;
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
