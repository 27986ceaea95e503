#pragma once
// The bench's reference deformation (issue 12, "bench world that moves like tissue"): a
// reference simulation of the liver phantom, on a different mesh, model and material than
// the host's session uses, driven by a simulated grasper that grabs a surface patch and
// pulls it along a scripted path. Its output is a phantom recording
// (appliance/synthetic_camera/phantom_recording.hpp) that the synthetic camera films and
// the simulated Polaris tracks. Frame Model = the scene's World; mm, s.
#include <Eigen/Geometry>

#include <functional>
#include <string>

#include "appliance/synthetic_camera/phantom_recording.hpp"

namespace arnav::hil {

struct PhantomScript {
  double fps = 15.0;                 // recorded frames per second
  double duration_s = 10.0;          // recording length
  // The grasp: surface vertices of the organ within grasp_radius_mm of the surface point
  // nearest to grasp_near_mm (Model), each held by a spring to its rest position + pull(t).
  Eigen::Vector3d grasp_near_mm = Eigen::Vector3d(70, 160, 60);
  double grasp_radius_mm = 12.0;
  double grasp_stiffness_mN_per_mm = 200.0;
  // pull(t) = pull_mm * s(t): s rises smoothly (cosine) from 0 at hold_start_s to 1 at
  // ramp_s later, stays for hold_s, falls back to 0 over ramp_s, then repeats after rest_s.
  Eigen::Vector3d pull_mm = Eigen::Vector3d(0, 0, -20);
  double start_s = 0.5, ramp_s = 2.5, hold_s = 2.0, rest_s = 1.0;
  int substeps = 1;                  // model steps per recorded frame
  // Frames before the pull whose next frame is at rest too are neither solved nor written
  // (frame 0 and the last rest frame are): the organ is exactly at rest there (no gravity,
  // springs at their rest targets), and the camera's interpolation between the two frames
  // kept is the rest shape. Makes a long wait before the pull cheap (scripts/demo).
  bool skip_rest_frames = false;
  bool gravity = false;              // frame 0 = the rest shape (what the host registered)
  double interior_offset_mm = 15.0;  // extra targets: tumour centroid +- this along x, y, z (inside the volume)

  double pull_fraction(double t_s) const;
};

struct PhantomRecordStats {
  int frames = 0;
  double max_tumour_displacement_mm = 0.0;
  double max_surface_displacement_mm = 0.0;
  double median_step_ms = 0.0;
  int grasped_vertices = 0;
  std::string model;
  int volume_vertices = 0, volume_tets = 0, surface_vertices = 0;
  Eigen::Vector3d surface_min_mm = Eigen::Vector3d::Zero(), surface_max_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d tumour_rest_mm = Eigen::Vector3d::Zero(), grasp_centre_mm = Eigen::Vector3d::Zero();
  bool healthy = true;
  std::string warning;
};

// Loads the scene (host/scene), builds its model (host/sim), runs the script and returns
// the recording. Throws std::runtime_error (scene errors name file:line) or
// std::invalid_argument for a bad script. progress(frame, frames) is called per frame.
camera_sim::PhantomRecording record_phantom(const std::string& scene_path, const PhantomScript& script,
                                            PhantomRecordStats& stats,
                                            const std::function<void(int, int)>& progress = {});

// Tumour centroid (target 0) of `model` against `reference`, frame by frame (same script,
// same times): how far a model that does deform under the same grasp is from the reference
// (mesh/model/material mismatch), next to a rigid model (the rest centroid). mm, 3D.
struct CentroidComparison {
  double model_mean_mm = 0, model_p95_mm = 0, model_max_mm = 0;
  double rigid_mean_mm = 0, rigid_p95_mm = 0, rigid_max_mm = 0;
};
// Throws std::invalid_argument when the frame times differ.
CentroidComparison compare_tumour_centroids(const camera_sim::PhantomRecording& reference, const camera_sim::PhantomRecording& model);

}  // namespace arnav::hil
