#pragma once
// Paired-point rigid registration (Arun 1987 / Umeyama 1991 via Eigen::umeyama) with the
// reflection guard, the fiducial registration error (FRE) and Fitzpatrick's (1998)
// prediction of the target registration error (TRE) at a point.
// In: fiducials p_AF_i (fixed frame A, e.g. Ref) and p_BF_i (moving frame B, e.g.
// Model), mm. Out: X_AB with p_A = X_AB * p_B.
#include <vector>

#include <Eigen/Geometry>

#include "calibration/lib/solver_summary.hpp"

namespace arnav::calib {

struct PointRegistrationResult {
  Eigen::Isometry3d X_AB = Eigen::Isometry3d::Identity();
  std::vector<double> residual_mm;  // |X_AB p_B_i - p_A_i|
  double fre_rms_mm = 0.0;          // RMS of the residuals
  double fle_rms_mm = 0.0;          // FLE estimated from FRE: FLE^2 = FRE^2 N / (N - 2)
  // True when the unconstrained least-squares orthogonal fit is a reflection
  // (det(U V^T) = -1) and the guard flipped the weakest axis to keep a rotation. Almost
  // always a sign of mismatched point pairs: the tool reports it.
  bool reflection_guarded = false;
  // Fiducial configuration: centroid and principal axes in A (columns), RMS distance of
  // the fiducials from each principal axis (f_k in Fitzpatrick's formula).
  Eigen::Vector3d centroid_A = Eigen::Vector3d::Zero();
  Eigen::Matrix3d principal_axes_A = Eigen::Matrix3d::Identity();
  Eigen::Vector3d rms_distance_from_axis_mm = Eigen::Vector3d::Zero();
  SolverSummary summary;
};

// Throws DegenerateInput for fewer than 3 pairs or (nearly) collinear fiducials, and
// CalibError for mismatched sizes or non-finite points.
PointRegistrationResult register_paired_points(const std::vector<Eigen::Vector3d>& p_A_mm,
                                               const std::vector<Eigen::Vector3d>& p_B_mm);

// Fitzpatrick, West, Maurer 1998: TRE^2(r) = FLE^2/N (1 + 1/3 sum_k d_k^2 / f_k^2),
// d_k the distance of target r (frame A) from principal axis k of the fiducials.
// Returns the predicted RMS TRE in mm; needs N >= 3 (uses the result's FLE estimate).
double predicted_tre_mm(const PointRegistrationResult& registration, const Eigen::Vector3d& p_A_target_mm);
// The same with a known FLE (RMS, mm) and the fiducial count.
double predicted_tre_mm(const PointRegistrationResult& registration, const Eigen::Vector3d& p_A_target_mm,
                        double fle_rms_mm, int fiducial_count);

}  // namespace arnav::calib
