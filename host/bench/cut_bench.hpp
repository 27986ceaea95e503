#pragma once
// arnav-bench cut: the tracked scalpel cutting the bundled liver, for every tissue model
// (docs/cut.md, docs/benchmarks.md). Per run: topology-update and whole-frame time (median,
// p99), model rebuild time, new elements, smallest dihedral angle, volume change, path
// fidelity, pieces and events.
#include <Eigen/Core>

#include <string>
#include <vector>

namespace arnav::host {

struct CutBenchOptions {
  std::string data_dir;                                        // folder with liver/*.scene.yaml and the scalpel paths
  bool quick = false;                                          // CI smoke run: coarse mesh, XPBD, 150 frames
  std::vector<std::string> meshes = {"coarse"};                // coarse (4,768 tets) and/or paper (26,054 tets)
  std::vector<std::string> scenarios = {"right_lobe", "ring"};  // ring: data/liver/scalpel_ring.csv; ring_scene: made from the scene (cut/ring_path.hpp); ring_follow: that path following the tumour
  std::vector<std::string> setting_prefixes;                   // model labels to run (prefix match; empty: all)
  int max_frames = 0;                                          // cap per run (0: the whole path)
  std::vector<bool> background = {false};                      // rebuild the model inline and/or in the background
  std::string reference_mesh;                                  // coarse/paper: compare each run with the same path cut on it (cut_reference.hpp); empty: none
  // CutSessionSettings::local_updates per run: {true} (default), {false} (every model rebuilt
  // after a cut) or {false, true}: then each local run is compared, frame by frame, with the
  // rebuilt run of the same model (state difference: the accuracy cost of the local update).
  std::vector<bool> local_updates = {true};
  // The co-rotational FEM (linear material) with refactor_in_background (the recommended
  // real-time setting, docs/sim-fem.md) instead of model_variants()' inline refactorisation;
  // its label gains "+background_refactor".
  bool fem_background_refactor = false;
  // >= -1: the co-rotational FEM's cut-region correction after a cut
  // (CorotationalFem::set_cut_region_rings; -1 off); its label gains "+cut_rings N".
  int fem_cut_region_rings = -2;
  double min_dihedral_deg = -1;                                // >= 0: overrides the scene's cutting.min_dihedral_deg (0: treatment off)
  double chord_sagitta_mm = -1;                                     // >= 0: overrides the scene's cutting.chord_sagitta_mm (0: no refinement)
};

// One frame of a run (cut_frames.csv): where the frame's time went.
struct CutFrameTiming {
  int frame = 0;
  double frame_ms = 0, frame_cpu_ms = 0;  // wall time of apply_blade + step, CPU time of the stepping thread
  double topology_ms = 0;                 // the cutter's topology update
  double model_update_ms = 0;             // model updated in place or rebuilt (0 without topology change)
  double reembed_ms = 0;                  // tumours and vessels re-embedded and split
  double step_ms = 0;                     // the model's step (StepSummary::wall_time_ms)
  int changed_tets = 0;                   // tets the cut changed this frame
  bool topology_changed = false;
  // the model step's solver iterations and final residual (StepSummary: PCG iterations for
  // the co-rotational FEM, Newton iterations for the stable Neo-Hookean one)
  int iterations = 0;
  double final_residual = 0;
};

struct CutBenchRow {
  std::string mesh, scenario, label;
  std::vector<CutFrameTiming> frame_timings;  // per frame (cut_frames.csv)
  bool background = false;  // model rebuilt on a worker thread
  bool local_updates_enabled = true;  // CutSessionSettings::local_updates
  // Local runs with a rebuilt run of the same model (CutBenchOptions::local_updates both):
  // largest vertex position difference from it over the frames until the two meshes first
  // differ in vertex count (the cut follows the tissue: once the states differ, the cuts
  // can too, and the runs are no longer comparable), and at the last of them; -1: not compared.
  double state_diff_max_mm = -1, state_diff_final_mm = -1;
  int state_compared_frames = 0;
  int tets_before = 0, tets_after = 0, vertices_after = 0, frames = 0, topology_changes = 0, new_tets = 0;
  double topology_median_ms = 0, topology_p99_ms = 0, topology_max_ms = 0;
  double frame_median_ms = 0, frame_p99_ms = 0;
  double frame_thread_cpu_median_ms = 0, frame_thread_cpu_p99_ms = 0;  // CPU time of the stepping thread per frame (workers not counted)
  double rebuild_median_ms = 0, rebuild_p99_ms = 0;  // over frames with a topology change
  double min_dihedral_input_deg = 0, min_dihedral_deg = 0;  // every tet (raw)
  double chord_sagitta_mm = 0;                                   // refinement ahead of the blade (0: off)
  // Quality bound (docs/cut.md "Element quality"): the bound, the smallest dihedral angle of
  // the elastic (active) tets, and the tets below it (embedded: no elastic term) with their
  // share of the volume, the vertices they drive and the rigid pieces.
  double min_dihedral_bound_deg = 0, min_dihedral_active_deg = 0;
  int embedded_tets = 0, driven_vertices = 0, rigid_groups = 0;
  double embedded_volume_fraction = 0;
  double volume_change_rel = 0;                      // rest volume after / before - 1
  double path_fidelity_mm = 0;                       // the cutter's own: largest distance of a cut point from this frame's sweep (bounded by path_tolerance_mm)
  // The cut-path error in the material (host/cut/material_path.hpp): every vertex put on the
  // cut against the surfaces the blade swept, at its rest position; percentiles over vertices.
  double path_error_p50_mm = 0, path_error_p95_mm = 0, path_error_max_mm = 0;
  int cut_vertices_measured = 0;
  double completion_deviation_mm = 0;                // completed tets: largest distance of a point from their recorded points' plane
  int completed_tets = 0;                            // tets completed from vertex sides (tissue moved)
  int pieces = 1, free_pieces = 0, events = 0;
  int tumours_freed = 0;        // tumours lying entirely in one free piece (cut out)
  int tumours_separated = 0;    // tumours lying entirely in one piece that is not the largest (cut out of the organ, maybe still held by a fixed vertex)
  // ring_scene (made from the scene): over the hold after the bottom cut, the freed
  // tumour's centroid displacement (it falls as a free body) and the largest displacement of
  // a vertex of the organ's largest piece (it stays hanging); -1: not measured.
  double freed_drop_mm = -1, organ_drift_mm = -1;
  double ring_radius_mm = 0;                     // ring derived from the scene: radius and access axis
  Eigen::Vector3d ring_axis = Eigen::Vector3d::Zero();
  int local_updates = 0, rebuilds = 0;  // model updated in place / rebuilt after a cut
  double local_median_ms = 0, local_p99_ms = 0;  // model update time of the local updates
  bool healthy = true, mesh_valid = true;
  std::string warning;
  // Against the reference mesh (CutBenchOptions::reference_mesh; cut_reference.hpp), at the last frame run.
  std::string reference_mesh;
  int reference_tets = 0;
  bool reference_healthy = true;
  double reference_wall_s = 0;
  double tumour_centroid_error_mm = -1;            // -1: not measured (no tumour, no reference)
  double cut_surface_mean_mm = -1, cut_surface_max_mm = -1;  // symmetric distance of the cut faces; -1: a run has none
};

std::vector<CutBenchRow> run_cut_bench(const CutBenchOptions& options);
void write_cut_csv(const std::string& path, const std::vector<CutBenchRow>& rows);
// Per-frame breakdown of every run (CutFrameTiming): one line per frame.
void write_cut_frames_csv(const std::string& path, const std::vector<CutBenchRow>& rows);

}  // namespace arnav::host
