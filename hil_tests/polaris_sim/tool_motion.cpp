#include "hil_tests/polaris_sim/tool_motion.hpp"

#include <cmath>
#include <numbers>

namespace arnav::hil {

Eigen::Isometry3d ToolMotion::X_NdiTool(double t_s) const {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  if (phantom) {
    const double t = phantom->start_s + t_s - phantom->t0_s;
    return phantom->X_NdiModel * phantom->recording->tool_pose_at(t, phantom->tool);
  }
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  Eigen::Vector3d p = center_mm;
  for (int i = 0; i < 3; ++i) p[i] += amplitude_mm[i] * std::sin(kTwoPi * frequency_hz[i] * t_s + phase_rad[i]);
  const double angle = rotation_amplitude_rad * std::sin(kTwoPi * rotation_frequency_hz * t_s);
  const Eigen::Quaterniond q = (q_base * Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation_axis.normalized()))).normalized();
  X.linear() = q.toRotationMatrix();
  X.translation() = p;
  return X;
}

ToolMotion default_motion(int tool_index) {
  const double k = static_cast<double>(tool_index);
  ToolMotion m;
  m.center_mm = Eigen::Vector3d(-150.0 + 60.0 * k, 40.0 * std::cos(k), -1400.0 - 25.0 * k);
  m.amplitude_mm = Eigen::Vector3d(60.0, 40.0, 25.0);
  m.frequency_hz = Eigen::Vector3d(0.21 + 0.02 * k, 0.33, 0.13 + 0.01 * k);
  m.phase_rad = Eigen::Vector3d(0.3 * k, 0.0, 1.1 * k);
  m.q_base = Eigen::Quaterniond(Eigen::AngleAxisd(0.4 * k + 0.2, Eigen::Vector3d(1.0, -0.5, 0.3).normalized()));
  m.rotation_axis = Eigen::Vector3d(0.2, 1.0, 0.1 * k).normalized();
  m.rotation_amplitude_rad = 0.6;
  m.rotation_frequency_hz = 0.17 + 0.03 * k;
  return m;
}

}  // namespace arnav::hil
