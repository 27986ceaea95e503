#pragma once
// Scripted motion of a simulated tool: X_NdiTool(t) as a closed-form function of the
// device time t_s = frame_number / frame_rate, so the ground truth of any frame can be
// recomputed exactly. Units: mm, s, rad.
#include <array>

#include <Eigen/Geometry>

namespace arnav::hil {

struct ToolMotion {
  // Position: center + amplitude * sin(2 pi f t + phase), per axis (a Lissajous figure).
  Eigen::Vector3d center_mm{0.0, 0.0, -1500.0};
  Eigen::Vector3d amplitude_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d frequency_hz = Eigen::Vector3d::Zero();
  Eigen::Vector3d phase_rad = Eigen::Vector3d::Zero();
  // Orientation: R_base * rotation of angle(t) = amplitude * sin(2 pi f t) about axis.
  Eigen::Quaterniond q_base = Eigen::Quaterniond::Identity();
  Eigen::Vector3d rotation_axis = Eigen::Vector3d::UnitZ();
  double rotation_amplitude_rad = 0.0;
  double rotation_frequency_hz = 0.0;

  Eigen::Isometry3d X_NdiTool(double t_s) const;
};

// A distinct, deterministic default motion for the i-th tool of a scenario without an
// explicit motion block (tools stay about 1.5 m in front of the camera, inside the volume).
ToolMotion default_motion(int tool_index);

}  // namespace arnav::hil
