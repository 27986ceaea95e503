#pragma once
// The cut-path error in the material (docs/overlay.md, "Cutting"; docs/cut.md): where the cut
// was put in the tissue against where the blade went in the tissue, whatever the tissue did
// afterwards. Every cutting sweep (the surface the blade swept, its start carried with the
// tissue as the cutter used it: CutSession::last_sweep) is pulled back into the rest
// configuration at that instant; every vertex put on the cut (split points, vertices snapped
// or moved onto it) is compared, at its rest position, with those surfaces. Measured from
// the mesh and the blade, independently of the cutter's own bookkeeping
// (CutStepReport::max_path_deviation_mm, bounded by path_tolerance_mm by construction).
// Used by the session (host/app/model_runner) and arnav-bench cut.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <deque>
#include <vector>

#include "host/cut/blade.hpp"
#include "host/cut/tet_cutter.hpp"

namespace arnav::host::cut {

class MaterialPathMeter {
 public:
  // Keeps the last max_sweeps sweeps (a vertex put on the cut later is measured against them).
  explicit MaterialPathMeter(int max_sweeps) : max_sweeps_(max_sweeps) {}
  // After a cutting sweep, with the tissue at x_World_mm (the state the cutter cut).
  void record_sweep(TetCutter& cutter, const Eigen::Matrix3Xd& x_World_mm, const SweptSurface& sweep);
  // The vertices newly on the cut since the last call: how many, the largest distance
  // (worst_mm, -1 when none could be measured), each distance appended to distances_mm.
  int measure_new_cut_vertices(const TetCutter& cutter, double& worst_mm, std::vector<double>* distances_mm = nullptr);

 private:
  struct Sweep {
    Eigen::AlignedBox3d box;
    std::vector<Triangle> tris;
  };
  int max_sweeps_;
  std::deque<Sweep> sweeps_;     // in the material (rest) frame, newest last
  std::vector<char> measured_;   // per vertex: already measured on the cut
};

}  // namespace arnav::host::cut
