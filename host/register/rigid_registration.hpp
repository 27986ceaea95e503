#pragma once
// Rigid registration of the patient model (frame Model = the scene frame World) to the
// intraoperative data (frame Intraop): X_IntraopModel maps model points into Intraop.
//  - landmarks: paired points (Umeyama via the calibration library), FRE, predicted TRE;
//  - surface: point-to-plane ICP from the data points to the model surface, with a robust
//    (Huber) kernel and trimming, so a partial surface with outliers registers.
// Units: mm, rad.
#include <Eigen/Geometry>

#include <array>
#include <string>
#include <vector>

#include "calibration/lib/point_registration.hpp"
#include "host/register/point_files.hpp"
#include "host/register/pose_prior.hpp"

namespace arnav::host {

struct LandmarkFit {
  Eigen::Isometry3d X_IntraopModel = Eigen::Isometry3d::Identity();
  calib::PointRegistrationResult fit;   // residuals, FRE, FLE estimate, fiducial axes (A = Intraop)
  int count = 0;
  // Fitzpatrick's predicted RMS TRE (mm) at a Model-frame point for a known FLE (RMS, mm).
  double predicted_tre_mm(const Eigen::Vector3d& p_Model_mm, double fle_rms_mm) const;
};

// Throws std::invalid_argument naming the problem (fewer than 3, collinear).
LandmarkFit register_landmarks(const std::vector<Landmark>& landmarks);

struct IcpOptions {
  int max_iterations = 100;
  double keep_fraction = 0.9;          // trimming: closest fraction of the data kept
  double max_distance_mm = 30.0;       // beyond this a point is an outlier (after the first iterations)
  double huber_sigmas = 1.345;         // Huber threshold in robust sigmas of the residual
  double min_sigma_mm = 0.3;           // floor of the robust residual scale
  double max_normal_angle_deg = 60.0;  // with data normals: reject pairs whose normals disagree more
  double step_tolerance_mm = 1e-4;     // stop when the update moves no point more than this
  // With a pose prior: a redescending kernel (Tukey's biweight, zero weight beyond
  // tukey_sigmas robust sigmas) instead of Huber: a local deformation in the patch (a
  // tool's dent) then has no pull on the pose, which the prior keeps well-posed.
  double tukey_sigmas = 4.685;
  // With a pose prior and the point noise known (given or estimated from the points; 0:
  // unknown), the result replaces the start only when the rigid model explains the data:
  // its trimmed residual at most model_error_ratio x the noise. A larger residual is model
  // error (the organ is deformed), which biases a rigid fit on a partial patch (it turns
  // the organ to fit a dent): the start is kept and the non-rigid stage decides.
  double noise_mm = 0.0;
  double model_error_ratio = 1.5;
};

struct IcpIteration {
  double rms_mm = 0.0;      // point-to-plane RMS over the kept pairs
  int used = 0;
  double step_mm = 0.0;
};

struct IcpSummary {
  int iterations = 0;
  double initial_rms_mm = 0.0;  // point-to-plane RMS over the kept pairs, first iteration
  double final_rms_mm = 0.0;    // distance to the surface, RMS over the kept points, at the result
  double final_max_mm = 0.0;
  int points_used = 0;
  int points_trimmed = 0;
  std::string termination;
  double wall_time_s = 0.0;
  std::vector<IcpIteration> history;
};

struct IcpResult {
  Eigen::Isometry3d X_IntraopModel = Eigen::Isometry3d::Identity();
  IcpSummary summary;
  // The pose's posterior (the data's information at the result, plus the prior's when one
  // was given), the data's robust scale it was weighed with, and the MAP objective
  // (robust data term / scale^2 + prior) at the start and at the result.
  PosePosterior posterior;
  double robust_scale_mm = 0.0;
  double objective_start = 0.0, objective_result = 0.0;
  Eigen::Isometry3d X_IntraopModel_fit = Eigen::Isometry3d::Identity();  // ICP's own result, kept or not
  bool start_kept = false;  // the result was not supported against the prior: the start is returned
  std::string start_kept_reason;
};

// Model surface (positions in Model, triangles outward), data points in Intraop (and
// optional unit normals, 0 columns when none), initial pose. Empty data returns the
// initial pose with termination "no data". With a pose prior (pose_prior.hpp) every
// Gauss-Newton step is the MAP step: the prior's term, weighted by the data's robust
// scale squared, joins the normal equations, so directions the data do not constrain stay
// at the prior's mean; the result replaces the start only when it lowers the MAP
// objective (robust data term plus prior; without a prior the data term alone).
IcpResult icp_point_to_plane(const Eigen::Matrix3Xd& model_positions_mm, const std::vector<std::array<int, 3>>& model_tris,
                             const Eigen::Matrix3Xd& data_Intraop_mm, const Eigen::Matrix3Xd& data_normals_Intraop,
                             const Eigen::Isometry3d& X_IntraopModel_initial, const IcpOptions& options = {}, const PosePrior* prior = nullptr);

// Rotation angle (deg) and translation (mm) of a transform, for reports.
double rotation_angle_deg(const Eigen::Isometry3d& X);

}  // namespace arnav::host
