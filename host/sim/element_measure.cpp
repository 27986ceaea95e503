#include "host/sim/element_measure.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>

namespace arnav::host {

Eigen::Matrix3d deformation_gradient(const Eigen::Matrix3Xd& x_World_mm, const std::array<int, 4>& tet,
                                     const Eigen::Matrix3d& Dm_inv) {
  return edge_matrix(x_World_mm, tet) * Dm_inv;
}

double von_mises(const Eigen::Matrix3d& stress) {
  const Eigen::Matrix3d s = 0.5 * (stress + stress.transpose());
  const Eigen::Matrix3d dev = s - (s.trace() / 3.0) * Eigen::Matrix3d::Identity();
  return std::sqrt(1.5 * dev.squaredNorm());
}

double max_green_strain(const Eigen::Matrix3d& F) {
  const Eigen::Matrix3d E = 0.5 * (F.transpose() * F - Eigen::Matrix3d::Identity());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(E, Eigen::EigenvaluesOnly);
  return eig.eigenvalues().maxCoeff();
}

Eigen::Matrix3d polar_rotation(const Eigen::Matrix3d& F) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d V = svd.matrixV();
  // An inverted F has a reflection in U*V^T; flip the axis of the smallest singular value
  // so that R stays a rotation (the inversion then shows as a negative stretch).
  if ((U * V.transpose()).determinant() < 0.0) U.col(2) *= -1.0;
  return U * V.transpose();
}

Eigen::Matrix3d corotated_linear_stress_kPa(const Eigen::Matrix3d& F, const Lame& lame) {
  const Eigen::Matrix3d R = polar_rotation(F);
  const Eigen::Matrix3d S = R.transpose() * F;
  const Eigen::Matrix3d eps = 0.5 * (S + S.transpose()) - Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d local = 2.0 * lame.mu_kPa * eps + lame.lambda_kPa * eps.trace() * Eigen::Matrix3d::Identity();
  return R * local * R.transpose();
}

ElementMeasure element_measure_from(const Eigen::Matrix3d& F, const Eigen::Matrix3d& stress_kPa) {
  ElementMeasure m;
  m.von_mises_stress_kPa = von_mises(stress_kPa);
  m.max_principal_strain = max_green_strain(F);
  m.volume_ratio = F.determinant();
  return m;
}

}  // namespace arnav::host
