#pragma once
// Pivot calibration of a tracked pointer: the tool is rotated about its tip resting in a
// divot. Every pose X_NdiTool_i satisfies R_i * p_ToolTip + t_i = p_NdiPivot.
// In: poses X_NdiTool (mm). Out: p_ToolTip_mm (tip in the Tool frame), p_NdiPivot_mm
// (divot in the tracker frame), residuals in mm.
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "calibration/lib/solver_summary.hpp"

namespace arnav::calib {

enum class PivotMethod { Algebraic, SphereFit, Ransac };
std::string to_string(PivotMethod method);
PivotMethod parse_pivot_method(const std::string& name);  // "algebraic" | "sphere" | "ransac"

struct PivotOptions {
  PivotMethod method = PivotMethod::Algebraic;
  int min_poses = 8;
  // Largest angle between any pose's rotation and the mean rotation must exceed this.
  double min_rotation_spread_deg = 15.0;
  // Smallest singular value of the stacked [R_i | -I] relative to the largest: below
  // this the system is rank deficient (rank < 6).
  double rank_tolerance = 1e-3;
  // RANSAC: inlier if the pose's residual is below this (mm); iterations; fixed seed so
  // a calibration is reproducible.
  double ransac_inlier_mm = 1.0;
  int ransac_iterations = 500;
  unsigned ransac_seed = 1;
};

struct PivotResult {
  Eigen::Vector3d p_ToolTip_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_NdiPivot_mm = Eigen::Vector3d::Zero();
  std::vector<double> residual_mm;   // per pose |R_i p_tip + t_i - p_pivot|
  std::vector<bool> inlier;          // RANSAC inliers (all true otherwise)
  double rms_mm = 0.0;               // over inliers
  double max_mm = 0.0;
  double rotation_spread_deg = 0.0;
  int rank = 0;                      // numerical rank of the stacked system
  double condition_number = 0.0;
  SolverSummary summary;
};

// Throws DegenerateInput (too few poses, rank < 6, rotation spread below the threshold:
// the message says which and asks to tilt the tool more) or CalibError.
PivotResult calibrate_pivot(const std::vector<Eigen::Isometry3d>& X_NdiTool,
                            const PivotOptions& options = {});

// Largest angle (deg) between any rotation and their chordal mean.
double rotation_spread_deg(const std::vector<Eigen::Isometry3d>& poses);
// Chordal L2 mean of the rotations (projection of the averaged matrices onto SO(3)).
Eigen::Matrix3d mean_rotation(const std::vector<Eigen::Matrix3d>& rotations);

}  // namespace arnav::calib
