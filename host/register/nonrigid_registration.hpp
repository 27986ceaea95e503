#pragma once
// Non-rigid initial registration (after paper 002): the tissue model's mechanical energy
// plus a point-to-plane data term from the intraoperative points to the model surface
// (plus an optional landmark term), minimised by quasi-static steps of the scene's tissue
// model. The data term acts through the model's attachments (paper 001's spring forces):
// each kept correspondence is a zero-rest-length spring from the material point on the
// volume's surface triangle to the point's projection on the tangent plane (so the surface
// may slide), recomputed after every relaxation, trimmed and robustly weighted (Huber), so
// partial coverage and outliers are tolerated. Stiff-to-flexible: the data weight rises
// level by level; the schedule stops once the residual reaches the expected noise
// (discrepancy principle) or stops improving.
// Everything here is in the Model frame (the scene frame World) in mm; the caller
// transforms the data with the rigid result first.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "host/scene/scene.hpp"

namespace arnav::host {

struct NonrigidOptions {
  std::string model_kind;                 // empty: the scene's model kind (its solver settings kept)
  // Data weight per level: spring stiffness per mm^2 of covered surface, in units of
  // E_default / organ extent (E of the scene's default material). Stiff to flexible.
  std::vector<double> data_weight_schedule = {4.0, 16.0, 64.0, 256.0, 1024.0, 4096.0};
  int max_updates_per_level = 4;          // correspondence updates per level
  int steps_per_update = 1;               // model steps (velocity zeroed after each) per update
  double step_s = 0.0;                    // model step; 0: 1 s for corotational_fem, the scene's time step otherwise
  double keep_fraction = 0.9;             // trimming: closest fraction of the points
  double max_distance_mm = 15.0;          // and no pair further apart than this (after the rigid stage)
  double huber_sigmas = 1.345;
  double min_sigma_mm = 0.3;
  double noise_mm = 1.0;                  // expected point noise (RMS distance); the schedule stops here
  // Discrepancy principle with the model's own error: the volume's surface is an
  // approximation of the organ surface the points were measured on (a coarse volume of a
  // finer surface), so the residual cannot fall below that approximation error without
  // fitting noise; the schedule stops at sqrt(noise^2 + e^2), e the RMS distance of the
  // scene's organ (display) surface vertices to the volume's surface at rest.
  bool include_model_error = false;  // off by default: no TRE gain on the benchmark (docs/register.md)
  double min_improvement = 0.02;          // a level must lower the RMS by this fraction to go on
  // Hold the scene's fixed vertices (ligaments) at their Model-frame rest positions. Off by
  // default: after a rigid fit those positions carry the rigid error, and holding them
  // there biased every benchmark case (docs/register.md); the data springs hold the
  // rigid modes of the free model.
  bool scene_boundary = false;
  // Anchored boundary (register_patient only): after the free fit, the rigid part is
  // corrected by the rigid motion of the scene's fixed vertices in the free fit (they are
  // where the organ is attached, so in truth they did not move relative to the body), and
  // the fit is run again from rest with the fixed vertices held there. The rest of the
  // organ is then constrained by its attachment, which the free fit lacks for the parts
  // the data do not see. Needs fixed vertices in the scene; ignored with scene_boundary.
  bool anchored_boundary = false;
  // Gravity change (with the boundary held: scene_boundary, or the anchored second fit):
  // the preoperative shape carries the old gravity; a change of the patient's position
  // changes the load on the whole organ, also where the data do not reach. A uniform body
  // force change b (3 numbers) is fitted to the data first: the model's responses to a unit
  // gravity along x, y and z (relaxed with the boundary held) are combined by least
  // squares on the point-to-plane residuals at rest (Huber-weighted, trimmed, |b| at most
  // gravity_max_fraction of the scene's |g|), and the fit then runs under b.
  bool estimate_gravity_change = false;
  double gravity_max_fraction = 1.0;
  int gravity_relax_steps = 8;
  // Self-contact term (paper 002's self-collision): a surface vertex that comes within
  // contact_margin_mm of another part of the surface (self_contact.hpp) is pushed back to
  // the margin, and that part the other way, by springs contact_stiffness_factor times the
  // stiffest data spring of the update, so the data cannot pull one lobe through another.
  bool self_contact = true;
  double contact_margin_mm = 1.0;
  double contact_stiffness_factor = 10.0;
  double contact_exclusion_mm = 0.0;      // 0: three mean surface edges (SelfContactDetector)
  double landmark_weight = 0.0;           // 0: landmarks not used; else stiffness in mN/mm per landmark, per level
  double time_budget_s = 0.0;             // 0: none; else stop starting new levels past it
};

struct NonrigidLevel {
  double data_weight = 0.0;
  double stiffness_per_point_mN_per_mm = 0.0;  // mean over kept points
  int updates = 0;
  int model_steps = 0;
  double elastic_energy = 0.0;          // mN*mm, from the model's last step summary
  double data_energy = 0.0;             // mN*mm, sum of 0.5 k d^2 over kept pairs
  double rms_mm = 0.0;                  // point-to-surface distance over kept points
  double max_mm = 0.0;
  int points_used = 0;
  int points_trimmed = 0;
  int contacts = 0;                     // self-contact springs in the level's last update
  double max_displacement_mm = 0.0;     // largest vertex displacement from rest
  double wall_time_s = 0.0;
  double model_time_s = 0.0;            // of which in the tissue model (steps, attachments, state resets)
  std::string termination;
};

struct NonrigidResult {
  Eigen::Matrix3Xd x_Model_mm;          // volume positions (Model frame); rest when not accepted
  bool accepted = false;                // false: the rigid result is kept
  std::string message;                  // why not accepted, or what limited it
  double rigid_rms_mm = 0.0;            // same measure at rest, for "never worse than rigid"
  double final_rms_mm = 0.0;
  double model_surface_error_mm = 0.0;  // e above (0 when not used)
  double discrepancy_mm = 0.0;          // where the schedule stops
  int inverted_elements = 0;
  Eigen::Vector3d gravity_change_mm_s2 = Eigen::Vector3d::Zero();  // estimated body force change (0: not estimated)
  double gravity_time_s = 0.0;
  double contact_time_s = 0.0;          // of wall_time_s, in the self-contact search
  int crossed_vertices = 0;             // surface vertices inside another part of the organ (lobes passed through)
  std::vector<NonrigidLevel> levels;
  double wall_time_s = 0.0;
  std::string model;                    // the model that ran
};

struct LandmarkPair {
  Eigen::Vector3d p_Model_mm;           // on or in the model at rest
  Eigen::Vector3d target_Model_mm;      // measured, mapped into Model by the rigid result
};

// data_Model_mm: the intraoperative points mapped into Model by the rigid result.
// Throws std::invalid_argument for a bad model kind (names it).
NonrigidResult register_nonrigid(const Scene& scene, const Eigen::Matrix3Xd& data_Model_mm, const std::vector<LandmarkPair>& landmarks,
                                 const NonrigidOptions& options);

// Distance of each point to the surface of the volume at positions x (mm), trimmed set
// as the registration uses it: returns RMS over the kept fraction; fills per-point
// distances when asked.
double surface_rms_mm(const TetMesh& mesh, const Eigen::Matrix3Xd& x_mm, const Eigen::Matrix3Xd& points_mm, double keep_fraction,
                      double max_distance_mm, std::vector<double>* distances = nullptr);

}  // namespace arnav::host
