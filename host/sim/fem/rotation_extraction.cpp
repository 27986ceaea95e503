#include "host/sim/fem/rotation_extraction.hpp"

#include <Eigen/SVD>
#include <cmath>

namespace arnav::host {

Eigen::Quaterniond extract_rotation(const Eigen::Matrix3d& F, const Eigen::Quaterniond& q_warm,
                                    const RotationExtraction& options, int* iterations) {
  Eigen::Quaterniond q = q_warm.normalized();
  int it = 0;
  for (; it < options.max_iterations; ++it) {
    const Eigen::Matrix3d R = q.toRotationMatrix();
    // Gradient of tr(R^T F) with respect to a small rotation of R, scaled by a curvature
    // estimate: a Newton-like step on the rotation angle.
    const Eigen::Vector3d torque = R.col(0).cross(F.col(0)) + R.col(1).cross(F.col(1)) + R.col(2).cross(F.col(2));
    const double scale = std::abs(R.col(0).dot(F.col(0)) + R.col(1).dot(F.col(1)) + R.col(2).dot(F.col(2))) + 1e-9;
    const Eigen::Vector3d omega = torque / scale;
    const double angle = omega.norm();
    if (!(angle > options.tolerance_rad)) break;  // also stops on NaN input
    q = Eigen::Quaterniond(Eigen::AngleAxisd(angle, omega / angle)) * q;
    q.normalize();
  }
  if (iterations) *iterations = it;
  return q;
}

Eigen::Quaterniond rotation_by_svd(const Eigen::Matrix3d& F) {
  if (!F.allFinite()) return Eigen::Quaterniond::Identity();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d& V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0.0) U.col(2) = -U.col(2);  // smallest singular value
  return Eigen::Quaterniond(U * V.transpose());
}

}  // namespace arnav::host
