#pragma once
// arnav-bench register: in-silico registration benchmark after the Sparse Data Challenge.
// Deformed states of the bundled liver come from a different model than the one that
// registers (fine-mesh co-rotational FEM, heterogeneous stiffness, gravity change, lobe
// pull and a pressing tool, solved to equilibrium with exact solves); the registration
// runs on the coarse scene. Partial anterior surfaces (coverage 20-60 %), noise, 5 %
// outliers, 45 interior + 15 surface targets, a 20-30 deg / 100 mm rigid offset and 3
// landmarks with 3 mm error. Per case TRE mean/median/p90/max for: the optimal rigid fit
// to the targets (the floor), landmark rigid, surface rigid, non-rigid; with run times.
// Frames: Model (scene) and Intraop. Units: mm, s.
#include <string>
#include <vector>

namespace arnav::host {

struct RegisterBenchOptions {
  std::string data_dir;
  bool quick = false;                                   // one state, one coverage, one noise level
  std::vector<double> coverages = {0.2, 0.3, 0.4, 0.6};
  std::vector<double> noises_mm = {0.0, 1.0, 2.0};      // per-axis Gaussian sigma
  int states = 3;                                       // deformed states
  std::string scene_dir = "liver";                      // under data_dir (patients: "patients")
  std::string registration_scene = "liver_coarse.scene.yaml";
  std::string truth_scene = "liver.scene.yaml";
  // Non-rigid methods to run: "energy" (rows "nonrigid", paper 002's energy minimisation)
  // and "loads" (rows "nonrigid_loads", load basis with the pose, load_basis.hpp).
  std::vector<std::string> methods = {"energy", "loads"};
  int basis_patches = 0;                                // 0: the library default
  int support_clusters = -1;                            // -1: the library default
  bool no_gravity_modes = false;
  bool loads_fixed_pose = false;                        // loads: keep the ICP pose (weights only)
  double prior_strain = -1.0;                           // loads: MAP prior strain (0: discrepancy principle; < 0: the library default)
  double landmark_error_mm = -1.0;                      // loads: landmark term's error (0: off; < 0: the library default)
  bool prebuilt_basis = false;                          // loads: build the basis once per run (before surgery), not per case
  bool pose_prior = false;                              // the landmark fit's covariance as the pose prior (issue 22)
  bool estimate_noise = false;                          // the noise estimated from the points, not told
  std::string model_kind;                               // registering model (empty: the scene's)
  std::vector<double> schedule;                         // data-weight schedule (empty: default)
  bool scene_boundary = false;
  bool anchored_boundary = false;
  bool gravity_change = false;
  bool no_self_contact = false;
  bool model_error = false;
  int updates_per_level = 0;                            // 0: the library default
  int steps_per_update = 0;
  unsigned seed = 1;
  std::string export_dir;                               // non-empty: write the first case's input files here
  bool track_scene_model_settings = false;              // track: the scene's model settings instead of the real-time ones
};

struct TreStats {
  double mean = 0, median = 0, p90 = 0, max = 0;
};

struct RegisterBenchRow {
  int state = 0;
  double coverage = 0, achieved_coverage = 0, noise_mm = 0;
  int points = 0, outliers = 0;
  double max_deformation_mm = 0;        // largest target displacement of the state (rigid part removed: optimal fit)
  std::string method;                   // optimal_rigid, landmark_rigid, surface_rigid, nonrigid, nonrigid_loads
  TreStats tre, tre_interior;
  // Diagnostic: mean TRE left after the best rigid correction of the prediction (the shape
  // error); the rest of tre.mean is pose error.
  double shape_error_mean_mm = 0;
  double surface_rms_mm = 0;
  double wall_s = 0;
  std::string note;
};

std::vector<RegisterBenchRow> run_register_bench(const RegisterBenchOptions& options);

// Tracking (arnav-bench track): a 10 s deforming sequence at 60 Hz (the truth state 1
// deformation - gravity tilt and tool press - breathed in and out with a 4 s period, as a
// quasi-static interpolation of the two equilibria), 60 surface features with IDs on the
// visible side (0.5 mm noise) driving the registration scene's real-time model from the
// true initial pose. Per frame: target TRE tracked and untracked (static model), frame time.
struct TrackBenchRow {
  int frame = 0;
  double t_s = 0, tre_tracked_mm = 0, tre_static_mm = 0, tre_max_tracked_mm = 0, frame_ms = 0, model_ms = 0;
  int tracked = 0;
  bool healthy = true;
};
std::vector<TrackBenchRow> run_track_bench(const RegisterBenchOptions& options, int frames, std::string& model_name);
void write_register_csv(const std::string& path, const std::vector<RegisterBenchRow>& rows);
void write_register_plots(const std::string& dir, const std::vector<RegisterBenchRow>& rows);
void write_track_plot(const std::string& png, const std::vector<TrackBenchRow>& rows);

}  // namespace arnav::host
