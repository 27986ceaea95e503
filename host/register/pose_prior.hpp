#pragma once
// A Gaussian prior on the registration's rigid pose, and the posterior the surface data
// give with it (docs/register.md, "Pose prior").
//
// Every start of the registration carries its uncertainty: the landmark fit (covariance
// from the landmark error and the landmarks' layout), a given pose (--initial-pose FILE) or
// the identity for data already aligned (--initial-pose identity), each with an
// uncertainty in degrees and millimetres. The surface fits (ICP, the load fit) add the
// prior to their normal equations, so a direction the partial surface does not constrain
// (sliding along a flat patch, turning about its normal) stays at the start instead of
// wandering.
//
// Parametrisation: T = X_IntraopModel^-1 maps the data into Model. The deviation from the
// prior mean T0 is Delta = T * T0^-1 (Model -> Model), written as
//   xi = (w, t): w the rotation vector of Delta (rad), t = Delta(c) - c (mm),
// c = centre_Model_mm (the organ's centre: the translation uncertainty is the centre's).
// The prior is xi ~ N(0, covariance). Units: rad, mm.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>
#include <vector>

#include "host/register/point_files.hpp"

namespace arnav::host {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

struct PosePrior {
  Eigen::Isometry3d X_IntraopModel = Eigen::Isometry3d::Identity();  // the mean
  Eigen::Vector3d centre_Model_mm = Eigen::Vector3d::Zero();
  Matrix6d covariance = Matrix6d::Identity();  // of xi = (rotation vector rad, centre translation mm)
  std::string source;                          // "landmarks", "initial pose", "identity"
  Matrix6d information() const;                // covariance^-1 (pseudo-inverse when singular)
};

// An isotropic prior: rotation_deg (1 sigma, about every axis) and translation_mm (1 sigma,
// along every axis, at the centre). Throws std::invalid_argument for non-positive values.
PosePrior isotropic_pose_prior(const Eigen::Isometry3d& X_IntraopModel, const Eigen::Vector3d& centre_Model_mm, double rotation_deg,
                               double translation_mm, const std::string& source);

// The landmark fit's prior: X_IntraopModel from the paired-point fit, covariance
// s^2 (sum J_i^T J_i)^-1 with J_i = [-[p_i - c]x, I] at the model landmarks p_i and
// s = landmark_error_mm / sqrt 3 (RMS 3-D error per coordinate); the error is taken as
// at least the fit's FRE-based estimate of it. Throws std::invalid_argument for fewer than
// 3 landmarks or a non-positive error.
PosePrior landmark_pose_prior(const std::vector<Landmark>& landmarks, const Eigen::Isometry3d& X_IntraopModel, double fre_rms_mm,
                              const Eigen::Vector3d& centre_Model_mm, double landmark_error_mm);

// The deviation xi of T (data -> Model) from the prior mean.
Vector6d pose_deviation(const PosePrior& prior, const Eigen::Isometry3d& T_ModelData);

// d xi / d(omega, tau) of a step T <- S T, S rotating by omega about `linearisation_centre`
// and translating by tau (first order; exact at xi = 0).
Matrix6d pose_deviation_jacobian(const PosePrior& prior, const Eigen::Isometry3d& T_ModelData, const Eigen::Vector3d& linearisation_centre);

// Adds the prior's term to Gauss-Newton normal equations A delta = rhs over a step
// (omega, tau) about linearisation_centre (A: the top-left 6x6 block, rhs: the first 6),
// weighted by scale2 (the data term's noise variance: the data term is sum r^2, the prior
// xi^T P xi times scale2).
void add_pose_prior(const PosePrior& prior, const Eigen::Isometry3d& T_ModelData, const Eigen::Vector3d& linearisation_centre, double scale2,
                    Eigen::Ref<Eigen::MatrixXd> A6, Eigen::Ref<Eigen::VectorXd> rhs6);

// Posterior of the pose: the data's information (H_data / noise^2, H_data the data term's
// Gauss-Newton matrix over the step about linearisation_centre) plus the prior's.
struct PosePosterior {
  Eigen::Vector3d rotation_sigma_deg = Eigen::Vector3d::Zero();     // per Model axis
  Eigen::Vector3d translation_sigma_mm = Eigen::Vector3d::Zero();   // per Model axis, at the centre
  Eigen::Vector3d prior_rotation_sigma_deg = Eigen::Vector3d::Zero();
  Eigen::Vector3d prior_translation_sigma_mm = Eigen::Vector3d::Zero();
  Vector6d deviation = Vector6d::Zero();  // xi of the result from the prior mean (rad, mm)
  double deviation_sigmas = 0.0;          // Mahalanobis distance of the result from the prior mean
  // Directions (unit 6-vectors in (rad * 100 mm, mm) units) the data constrain less than
  // the prior does (or, without a prior, hardly at all): they stay at the start.
  std::vector<Vector6d> unconstrained;
  std::vector<std::string> unconstrained_text;  // e.g. "translation along (0.12, 0.99, 0.05)"
  bool valid = false;
};
PosePosterior pose_posterior(const PosePrior* prior, const Eigen::Isometry3d& T_ModelData, const Eigen::Vector3d& linearisation_centre,
                             const Matrix6d& H_data, double noise2);

// Noise of a point cloud estimated from the data alone: each point's distance to the plane
// through its k nearest neighbours (robust: 1.4826 x the median, corrected for the plane's
// fitted degrees of freedom). 0 when fewer than 20 points. Mostly noise plus the surface's
// curvature over the neighbourhood (an upper estimate on a curved organ).
double estimate_point_noise_mm(const Eigen::Matrix3Xd& points_mm, int k = 16);

}  // namespace arnav::host
