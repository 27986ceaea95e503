#include "host/sim/fem/rotation_extraction.hpp"

#include <Eigen/LU>
#include <Eigen/SVD>
#include <cmath>

namespace arnav::host {

Eigen::Quaterniond extract_rotation(const Eigen::Matrix3d& F, const Eigen::Quaterniond& q_warm,
                                    const RotationExtraction& options, int* iterations) {
  Eigen::Quaterniond q = q_warm.normalized();
  int it = 0;
  for (; it < options.max_iterations; ++it) {
    const Eigen::Matrix3d R = q.toRotationMatrix();
    // Maximise tr(R^T F) over rotations R <- exp([omega]) R. To second order the gain is
    // omega.tau - omega^T H omega / 2 with tau = sum_i r_i x f_i and H = tr(B) I - B,
    // B = sym(F R^T). Newton's step omega = H^-1 tau converges quadratically; where H is
    // not positive definite (far from the solution, inverted elements) Mueller's step
    // tau / tr(B) is taken instead (H with B replaced by 0).
    const Eigen::Vector3d torque = R.col(0).cross(F.col(0)) + R.col(1).cross(F.col(1)) + R.col(2).cross(F.col(2));
    const Eigen::Matrix3d FRt = F * R.transpose();
    const double trB = FRt.trace();
    // Converged (the Newton step is at most ~|tau| / tr(B) near the solution, where H ~ 2/3 tr(B)).
    if (!(torque.norm() > 0.5 * options.tolerance_rad * std::abs(trB))) break;  // also stops on NaN
    const Eigen::Matrix3d H = trB * Eigen::Matrix3d::Identity() - 0.5 * (FRt + FRt.transpose());
    // Positive definite by leading principal minors; then the closed-form 3x3 inverse.
    const double m1 = H(0, 0), m2 = H(0, 0) * H(1, 1) - H(0, 1) * H(0, 1), det = H.determinant();
    const double floor = 1e-6 * std::abs(trB);
    Eigen::Vector3d omega;
    if (m1 > floor && m2 > floor * floor && det > floor * floor * floor) {
      omega = H.inverse() * torque;
    } else {
      omega = torque / (std::abs(trB) + 1e-9);
    }
    const double angle = omega.norm();
    if (!(angle > options.tolerance_rad)) break;
    // Rotate by omega using the unnormalised quaternion (1, omega/2): no trigonometry,
    // the same axis and, to first order, angle; the fixed point (omega = 0) is unchanged,
    // and a large step is shortened (2 atan(|omega|/2) < pi).
    const Eigen::Quaterniond dq(1.0, 0.5 * omega.x(), 0.5 * omega.y(), 0.5 * omega.z());
    q = dq * q;
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
