#pragma once
// Non-rigid registration by estimating the unseen loads jointly with the pose (after the
// Sparse Data Challenge's best entries, BCF-FEM / LIBR of Heiselman & Miga): a basis of
// displacement responses of the tissue, linear elastic about the rest shape (the scene's
// tet mesh, materials and supported = fixed vertices), to GENERIC loads:
//   - a unit force along x, y and z spread over each of `patches` surface patches that
//     tile the WHOLE organ surface (farthest-point clustering of the volume's surface
//     vertices; not the part the data cover, not where any tool acted);
//   - a change of the body force (gravity) along x, y and z;
//   - translations along x, y and z of `support_clusters` - 1 parts of the supported region
//     relative to the first (the ligaments move a little with the diaphragm);
// each response is one solve with the factorised stiffness (CHOLMOD). The registration
// then solves, by Gauss-Newton over recomputed, trimmed, Huber-weighted point-to-plane
// correspondences, for a rigid correction of the pose (6 numbers) and the basis weights
// alpha, Tikhonov-regularised by the strain energy 1/2 alpha^T G alpha of the deformation
// (G = U^T K U), the regularisation weight falling level by level (stiff to flexible) down
// to the weight of a Gaussian prior on the deformation (prior_strain: noise^2 / (sum(E V)
// strain^2), the default) or, without a prior, until the misfit reaches the expected noise
// (Morozov's discrepancy principle) or stops improving (model error), so nothing is tuned
// per case. Landmark pairs, when given, pull their model points with the weight of their
// error. Frames: Model (the scene frame
// World); the data are given in Model after the rigid stage, and the result adds a rigid
// correction D of them.
// Units: mm, mN, kPa (= mN/mm^2).
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <optional>
#include <string>
#include <vector>

#include "host/register/load_basis_types.hpp"
#include "host/register/nonrigid_registration.hpp"
#include "host/register/pose_prior.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {

// Throws std::invalid_argument when the basis cannot be built (no tets, a degenerate tet,
// materials missing for a region, fewer than 4 surface vertices outside the support).
LoadBasis build_load_basis(const Scene& scene, const LoadBasisOptions& options);

struct LoadFitOptions {
  double keep_fraction = 0.9;     // trimming (as the energy method)
  double max_distance_mm = 15.0;
  double huber_sigmas = 1.345;
  double min_sigma_mm = 0.3;
  double noise_mm = 1.0;          // expected RMS point-to-plane noise: the discrepancy target
  // Regularisation weights, stiff to flexible (units: trace of the data term's normal
  // matrix over trace(G), so they do not depend on the point count or the basis scale).
  std::vector<double> lambda_schedule = {1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5, 1e-6};
  int iterations_per_level = 4;   // Gauss-Newton iterations (correspondences recomputed) per level at most
  int max_iterations = 28;        // over all levels
  // Morozov's discrepancy principle: the schedule stops at the first level whose residual
  // is at most discrepancy_factor * noise_mm (a factor > 1: the linear model and the
  // volume's discretisation have errors of their own).
  double discrepancy_factor = 1.1;
  // Prior on the deformation (MAP, the default), > 0: instead of the discrepancy principle, the
  // regularisation is that of a Gaussian prior whose expected strain energy is that of a
  // uniform strain of prior_strain RMS over the organ, E0 = 1/2 sum(E V) prior_strain^2,
  // against the data's noise: minimise sum r^2 / noise^2 + (strain energy) / E0, i.e.
  // lambda = noise^2 / (sum(E V) prior_strain^2) on alpha^T G alpha. The stiff-to-flexible
  // levels run down to that weight (continuation for the correspondences) and stop there.
  // 0: the discrepancy principle (discrepancy_factor, plateau_improvement). The default,
  // 1 % RMS strain, is a round value inside the broad optimum (0.7-1 %) of both patients'
  // livers on arnav-bench register (docs/benchmarks.md, "Registration, fourth round").
  double prior_strain = 0.01;
  double plateau_improvement = 0.05;  // a level (10x less regularisation) lowering the residual by less is a plateau
  double converged_step_mm = 0.05;  // a level ends when no point / vertex moves more than this in a step
  double min_improvement = 0.02;  // a level must lower the residual by this fraction; the fit is accepted only
                                  // if it lowers the rigid residual by it (never worse than rigid)
  bool estimate_pose = true;      // false: only the loads (the pose of the rigid stage kept)
  // Landmark term: each landmark pair (touched with the pointer) pulls the model point at
  // its rest position (the closest point of the volume's surface, displaced with it)
  // towards its measured position, weighted as a measurement of landmark_error_mm RMS
  // (3-D) against the data's robust scale: weight (sigma_data / (landmark_error /
  // sqrt 3))^2 per coordinate, Huber beyond 2 landmark errors. <= 0: landmarks not used.
  double landmark_error_mm = 3.0;
  double time_budget_s = 0.0;     // 0: none
  // Pose prior on the correction D (pose_prior.hpp: its mean is the D that puts the data
  // at the prior's pose, i.e. X = X_rigid^-1 * X_prior when the data were mapped into
  // Model by X_rigid): joins the normal equations weighted by the data's scale squared,
  // so directions the data do not constrain stay at the prior. Absent: D is free.
  std::optional<PosePrior> pose_prior;
  // Held supports (> 0): the support modes' translations (mm) get a Gaussian prior of this
  // sigma: the ligaments stay put unless the data demand otherwise. 0: only the strain
  // energy regularises them.
  double support_sigma_mm = 0.0;
};

struct LoadFitIteration {
  double rms_mm = 0.0;            // trimmed point-to-surface RMS before the step
  double predicted_rms_mm = 0.0;  // weighted point-to-plane RMS the step predicts
  double lambda = 0.0;            // chosen regularisation weight (relative to trace ratio)
  double step_pose_mm = 0.0;      // largest data point motion by the pose step
  double step_shape_mm = 0.0;     // largest vertex motion by the weights' step
  int points_used = 0;
  double strain_energy = 0.0;     // mN mm, 1/2 alpha^T G alpha after the step
};

struct LoadFitResult {
  Eigen::Matrix3Xd x_Model_mm;    // volume positions in Model (rest when not accepted)
  Eigen::Isometry3d D = Eigen::Isometry3d::Identity();  // correction: the data's Model positions are D * data
  Eigen::VectorXd alpha;          // basis weights
  bool accepted = false;
  std::string message;
  double rigid_rms_mm = 0.0;      // trimmed point-to-surface RMS at rest, input pose
  double final_rms_mm = 0.0;
  double max_displacement_mm = 0.0;
  double strain_energy = 0.0;
  // Landmarks used by the fit: RMS 3-D distance of the measured landmarks to their model
  // points at the input pose and rest, and after the fit (0 when none).
  int landmarks_used = 0;
  double landmark_rigid_rms_mm = 0.0, landmark_final_rms_mm = 0.0;
  double gravity_fraction = 0.0;  // share of the strain energy in the gravity modes (diagnostic)
  int crossed_vertices = 0;       // surface vertices left inside another part of the organ
  std::vector<LoadFitIteration> iterations;
  std::vector<double> level_lambda, level_rms_mm;  // per level run: its lambda and converged residual
  double lambda = 0.0;            // the level kept (relative units)
  double prior_lambda = 0.0;      // with prior_strain: the MAP weight in relative units (0: discrepancy principle)
  double wall_time_s = 0.0;       // fit only (the basis is timed by build_time_s)
  // The MAP objective (data term over noise^2, Huber, all points capped at max_distance;
  // plus the strain prior energy / E0 with prior_strain; plus the pose prior's and the held
  // supports' terms) at the rigid start and at the fit: the fit is accepted only when it
  // is lower (and the residual rule above holds).
  double objective_rigid = 0.0, objective_fit = 0.0;
  // The pose's posterior at the result (data information at the last step plus the prior).
  PosePosterior posterior;
};

// data_Model_mm: the intraoperative points mapped into Model by the rigid result;
// landmarks: p_Model_mm at rest, target_Model_mm measured and mapped into Model by the
// rigid result (the correction D applies to them as to the points). Throws
// std::invalid_argument for a basis of another mesh.
LoadFitResult fit_load_basis(const Scene& scene, const LoadBasis& basis, const Eigen::Matrix3Xd& data_Model_mm,
                             const std::vector<LandmarkPair>& landmarks, const LoadFitOptions& options);
inline LoadFitResult fit_load_basis(const Scene& scene, const LoadBasis& basis, const Eigen::Matrix3Xd& data_Model_mm,
                                    const LoadFitOptions& options) {
  return fit_load_basis(scene, basis, data_Model_mm, {}, options);
}

}  // namespace arnav::host
