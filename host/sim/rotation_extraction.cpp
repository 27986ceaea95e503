#include "host/sim/rotation_extraction.hpp"

#include <cmath>

namespace arnav::host {

Eigen::Matrix3d refine_rotation(const Eigen::Matrix3d& F, Eigen::Quaterniond& q, int max_iterations, double tol_rad) {
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
