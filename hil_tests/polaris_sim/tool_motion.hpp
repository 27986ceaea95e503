#pragma once
// Scripted motion of a simulated tool: X_NdiTool(t) as a closed-form function of the
// device time t_s = frame_number / frame_rate, so the ground truth of any frame can be
// recomputed exactly. Units: mm, s, rad.
#include <array>
#include <memory>
#include <string>

#include <Eigen/Geometry>

#include "appliance/synthetic_camera/phantom_recording.hpp"

namespace arnav::hil {

// The tool that deforms the bench's phantom (hil_tests/phantom, arnav-phantom-record): its
// recorded path X_ModelTool(t), placed in the tracker frame by X_NdiModel (where the
// phantom's model frame sits for the tracker: X_NdiCam * X_CamBoard * X_BoardModel of the
// synthetic camera's static board), so the host sees the tool the camera's world moves with.
struct PhantomToolPath {
  std::shared_ptr<const camera_sim::PhantomRecording> recording;
  int tool = 0;                                    // index into recording->tool_names
  Eigen::Isometry3d X_NdiModel = Eigen::Isometry3d::Identity();
  double t0_s = 0.0;                               // device time of recording time start_s (first_frame / rate: the boot)
  double start_s = 0.0;
};

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
  // When set, the tool follows the phantom recording instead (the fields above unused).
  std::shared_ptr<const PhantomToolPath> phantom;

  Eigen::Isometry3d X_NdiTool(double t_s) const;
};

// A distinct, deterministic default motion for the i-th tool of a scenario without an
// explicit motion block (tools stay about 1.5 m in front of the camera, inside the volume).
ToolMotion default_motion(int tool_index);

}  // namespace arnav::hil
