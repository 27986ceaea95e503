#pragma once
// Runs a loaded scene headless: steps the tissue model frame by frame, writes positions
// (VTK or OBJ sequences) and a per-frame summary CSV. Frame World, units mm, s.
#include <optional>
#include <ostream>
#include <string>

#include "host/cut/scalpel_path.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {

struct SimRunOptions {
  int frames = 60;
  std::string out_dir;          // empty: no files, summary to the stream only
  std::string format = "vtk";   // "vtk" (volume + surfaces) or "obj" (surfaces only)
  int write_every = 1;          // write positions every N frames (frame 0 and the last always)
  // Scalpel path (arnav-sim --scalpel): the scene must declare `cutting:` (docs/cut.md).
  // The volume files then hold the cut mesh, the organ surface is the boundary of the cut
  // volume (cut faces included), frames.csv gains the cut columns and cut_events.csv lists
  // margin/vessel events.
  std::optional<cut::ScalpelPath> scalpel;
};

struct SimRunResult {
  int frames_run = 0;
  bool healthy = true;
  std::string warning;               // first unhealthy step's reason
  double median_step_ms = 0.0;
  double max_displacement_mm = 0.0;  // over the volume vertices, last frame
  Eigen::Vector3d tumour_displacement_mm = Eigen::Vector3d::Zero();  // first tumour, last frame
  // Inverted elements (a counted warning, docs/sim.md): frames that ended with some, the
  // most at once, and the longest run of consecutive such frames (simulated s).
  int frames_with_inverted = 0;
  int peak_inverted = 0;
  double worst_inverted_run_s = 0.0;
  double peak_strain = 0.0;  // largest principal Green strain of any tet, every 10th and the last frame
  // Step control (docs/sim.md): frames whose step was redone or ran at a finer factor of the
  // substeps (their warning names "step control").
  int step_control_frames = 0;
  // With a scalpel path:
  int tets = 0, vertices = 0;        // of the cut mesh, last frame
  int pieces = 1;                    // face-connected pieces, last frame
  int cut_events = 0;
  double max_topology_update_ms = 0.0;
};

// `csv` receives the per-frame summary (header + one row per frame).
SimRunResult run_scene(const Scene& scene, const SimRunOptions& options, std::ostream& csv);

}  // namespace arnav::host
