#pragma once
// Synthetic ground truth for the calibration tests: random rotations, noisy poses.
#include <random>

#include <Eigen/Geometry>

namespace arnav::calib::test {

inline Eigen::Vector3d gaussian3(std::mt19937& rng, double sigma) {
  std::normal_distribution<double> g(0.0, sigma);
  return {g(rng), g(rng), g(rng)};
}

// Rotation by a random axis and an angle uniform in [0, max_rad].
inline Eigen::Matrix3d random_rotation(std::mt19937& rng, double max_rad) {
  std::uniform_real_distribution<double> u(0.0, max_rad);
  return Eigen::AngleAxisd(u(rng), gaussian3(rng, 1.0).normalized()).toRotationMatrix();
}

inline double rotation_angle_deg(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  return Eigen::AngleAxisd(A.transpose() * B).angle() * 180.0 / M_PI;
}

}  // namespace arnav::calib::test
