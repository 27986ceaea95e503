#include "calibration/lib/point_registration.hpp"

#include <chrono>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <Eigen/Geometry>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {

PointRegistrationResult register_paired_points(const std::vector<Eigen::Vector3d>& p_A,
                                               const std::vector<Eigen::Vector3d>& p_B) {
  const auto start = std::chrono::steady_clock::now();
  if (p_A.size() != p_B.size()) {
    throw CalibError("registration: " + std::to_string(p_A.size()) + " fixed but " +
                     std::to_string(p_B.size()) + " moving points; they must be paired");
  }
  const auto n = static_cast<Eigen::Index>(p_A.size());
  if (n < 3) {
    throw DegenerateInput("registration: " + std::to_string(n) +
                          " point pairs; at least 3 non-collinear pairs are needed (4+ to "
                          "estimate FLE meaningfully)");
  }
  Eigen::Matrix3Xd A(3, n);
  Eigen::Matrix3Xd B(3, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    A.col(i) = p_A[static_cast<std::size_t>(i)];
    B.col(i) = p_B[static_cast<std::size_t>(i)];
  }
  if (!A.allFinite() || !B.allFinite()) throw CalibError("registration: non-finite point");

  PointRegistrationResult res;
  res.centroid_A = A.rowwise().mean();
  const Eigen::Matrix3Xd Ac = A.colwise() - res.centroid_A;
  const Eigen::Matrix3Xd Bc = B.colwise() - B.rowwise().mean();
  // Collinear fiducials leave the rotation about their line free.
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(Ac * Ac.transpose() / static_cast<double>(n));
  const Eigen::Vector3d ev = eig.eigenvalues();  // ascending
  if (ev(1) < 1e-6 * std::max(ev(2), 1e-300)) {
    throw DegenerateInput("registration: the fiducials are (nearly) collinear; the rotation "
                          "about their line is undetermined. Add a fiducial off that line.");
  }
  res.principal_axes_A = eig.eigenvectors();
  // RMS distance from principal axis k: sqrt of the sum of the other two variances.
  for (int k = 0; k < 3; ++k) {
    res.rms_distance_from_axis_mm(k) = std::sqrt(ev.sum() - ev(k));
  }

  // Reflection guard: Eigen::umeyama already forces det(R) = +1; detect when it had to.
  const Eigen::Matrix3d H = Ac * Bc.transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  res.reflection_guarded = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0;

  const Eigen::Matrix4d T = Eigen::umeyama(B, A, /*with_scaling=*/false);
  res.X_AB.matrix() = T;
  if (std::abs(res.X_AB.linear().determinant() - 1.0) > 1e-9) {
    throw CalibError("registration: internal error, result is not a rotation");
  }
  double sum = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double e = (res.X_AB * B.col(i) - A.col(i)).norm();
    res.residual_mm.push_back(e);
    sum += e * e;
  }
  res.fre_rms_mm = std::sqrt(sum / static_cast<double>(n));
  res.fle_rms_mm = n > 2 ? res.fre_rms_mm * std::sqrt(static_cast<double>(n) / static_cast<double>(n - 2))
                         : 0.0;
  res.summary.method = "paired-point rigid registration (Umeyama/Arun, reflection guard)";
  res.summary.termination = res.reflection_guarded ? "closed form; reflection guarded" : "closed form";
  res.summary.initial_cost = res.fre_rms_mm;
  res.summary.final_cost = res.fre_rms_mm;
  res.summary.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return res;
}

double predicted_tre_mm(const PointRegistrationResult& reg, const Eigen::Vector3d& r, double fle, int n) {
  if (n < 3) throw CalibError("TRE prediction needs at least 3 fiducials");
  const Eigen::Vector3d d = r - reg.centroid_A;
  double sum = 0.0;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d axis = reg.principal_axes_A.col(k);
    const double dk2 = (d - d.dot(axis) * axis).squaredNorm();  // distance from axis k
    const double fk2 = reg.rms_distance_from_axis_mm(k) * reg.rms_distance_from_axis_mm(k);
    sum += dk2 / fk2;
  }
  return std::sqrt(fle * fle / n * (1.0 + sum / 3.0));
}

double predicted_tre_mm(const PointRegistrationResult& reg, const Eigen::Vector3d& r) {
  return predicted_tre_mm(reg, r, reg.fle_rms_mm, static_cast<int>(reg.residual_mm.size()));
}

}  // namespace arnav::calib
