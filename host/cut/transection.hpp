#pragma once
// A full transection of an organ by the blade, driven through CutSession (issue 23): a
// vertical blade edge longer than the organ is high sweeps through the whole organ along the
// plane x = (organ centroid x), from beyond one side (y) to beyond the other, with the model
// stepping every frame. Used by cut_transection_test (coarse patient livers) and
// `arnav-bench transection` (full resolution). Frame World, units mm, s.
#include <array>
#include <string>
#include <vector>

#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host::cut {

struct TransectionSettings {
  double settle_s = 0.25;      // model runs, blade outside, before the stroke
  double stroke_s = 0.5;       // the blade crosses the organ (about 300-400 mm/s on a liver)
  double after_s = 0.5;        // model runs after the cut
  // A second stroke back along the same plane (from beyond the far side to beyond the near
  // one) after the first: a surgeon's second pass through what the first left joined (a
  // swinging organ can carry material past the blade's end).
  bool return_stroke = false;
  // The blade starts and ends this far outside the organ (also above and below it). 5 mm
  // left the bundled liver at rest joined by a bridge (540 tets cut, one piece; 10 mm and
  // more separate it exactly: a cutter limit, docs/cut.md).
  double margin_mm = 30.0;
  int threads = 1;             // model threads
  double min_dihedral_deg = 5.0;  // the session's quality bound (docs/cut.md)
};

struct TransectionResult {
  int frames = 0;
  int unhealthy_steps = 0;          // false stops when the model is sound
  std::string first_unhealthy;      // "frame N: warning"
  bool finite = true;
  bool mesh_valid = false;
  std::string mesh_summary;
  int tets_cut = 0;
  int pieces_after_first_stroke = 0;  // face-connected pieces when the first stroke ended
  int pieces = 0;
  int pieces_across_plane = 0;      // pieces holding material more than 1 mm on both sides
  double uncut_volume_mm3 = 0.0, total_volume_mm3 = 0.0;
  std::array<double, 2> side_volume_mm3{};           // x < plane, x > plane (pieces by side)
  std::array<double, 2> expected_side_volume_mm3{};  // uncut mesh clipped by the plane at stroke start
  int peak_inverted = 0, frames_with_inverted = 0;
  int refused = 0;                  // steps refused for a known limit (explicit stability bound)
  std::vector<double> step_ms, frame_ms;  // model step; blade + step (whole frame)
  std::string summary() const;
};

// Runs the transection of sc's organ with one model variant (the explicit mass-spring
// integrator gets the substeps its stability bound asks for, +25 %, as in the patient suite).
TransectionResult run_transection(const Scene& sc, const ModelVariant& variant, const TransectionSettings& settings);

// Rest volume of the material on the side `side` (-1: n.x < d, +1: n.x > d) of a plane in
// the configuration x (per tet: rest volume times the fraction of the deformed tet on that
// side; an affine map keeps volume ratios).
double clipped_rest_volume_mm3(const TetMesh& mesh, const Eigen::Matrix3Xd& x_World_mm, const Eigen::Vector3d& n, double d, int side);

}  // namespace arnav::host::cut
