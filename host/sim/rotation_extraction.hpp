#pragma once
// Rotational part of a deformation gradient without an SVD: the proper rotation R that
// maximises tr(R^T F) (the polar rotation, reflection-safe for inverted F), found by the
// iteration of Mueller et al. 2016 ("A Robust Method to Extract the Rotational Part of
// Deformations"), warm-started from the previous result. A few iterations when warm.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

namespace arnav::host {

// (host/sim/fem has its own variant for the FEM.) Refines q in place (unit quaternion) and returns its rotation matrix. Stops when the
// correction angle is below tol_rad or after max_iterations.
// Defined inline: it runs once per tet per XPBD sweep, and inlining lets the compiler
// keep F and q in registers.
inline Eigen::Matrix3d refine_rotation(const Eigen::Matrix3d& F, Eigen::Quaterniond& q, int max_iterations = 20,
                                       double tol_rad = 1e-12) {
  Eigen::Matrix3d R = q.toRotationMatrix();
  for (int it = 0; it < max_iterations; ++it) {
    // Torque-like correction: sum r_i x f_i over the columns, scaled by the alignment.
    const Eigen::Vector3d omega = (R.col(0).cross(F.col(0)) + R.col(1).cross(F.col(1)) + R.col(2).cross(F.col(2))) /
                                  (std::abs(R.col(0).dot(F.col(0)) + R.col(1).dot(F.col(1)) + R.col(2).dot(F.col(2))) + 1e-9);
    const double angle = omega.norm();
    if (!(angle > tol_rad)) break;  // also stops on NaN input
    // Small corrections (the warm-started case) use the first-order quaternion of the
    // rotation vector: same axis, angle 2 atan(angle/2), no trigonometry.
    const Eigen::Quaterniond dq = angle < 0.1 ? Eigen::Quaterniond(1.0, 0.5 * omega.x(), 0.5 * omega.y(), 0.5 * omega.z())
                                              : Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle));
    q = dq * q;
    q.normalize();
    R = q.toRotationMatrix();
  }
  return R;
}


}  // namespace arnav::host
