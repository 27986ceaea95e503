#pragma once
// Scripted motion of a simulated tool: X_NdiTool(t) as a closed-form function of the
// device time t_s = frame_number / frame_rate, so the ground truth of any frame can be
// recomputed exactly. Units: mm, s, rad.
#include <array>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

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

// A scripted path of a tool in the organ's model frame (motion: {path: FILE.csv, ...}):
// rows "t_s, x_mm, y_mm, z_mm[, qw, qx, qy, qz]" (tip position and, optionally, the tool's
// orientation in Model; identity when absent), times strictly increasing, piecewise linear
// (orientation slerped), held at the first/last row outside the rows' time span. Placed in
// the tracker frame by X_NdiModel; row time 0 is device time t0_s - start_s.
struct ScriptedToolPath {
  std::vector<double> t_s;
  std::vector<Eigen::Vector3d> p_Model_mm;
  std::vector<Eigen::Quaterniond> q_ModelTool;
  Eigen::Isometry3d X_NdiModel = Eigen::Isometry3d::Identity();
  double t0_s = 0.0;
  double start_s = 0.0;

  Eigen::Isometry3d X_ModelTool(double t_path_s) const;
};

class ToolPathError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Parses the CSV text of a scripted path; errors name source:line and what to fix. Blank
// lines and lines starting with '#' are skipped; a first line starting with "t_s" is a header.
ScriptedToolPath parse_tool_path_csv(const std::string& text, const std::string& source);

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
  // When set, the tool follows this scripted path instead.
  std::shared_ptr<const ScriptedToolPath> path;

  Eigen::Isometry3d X_NdiTool(double t_s) const;
};

// A distinct, deterministic default motion for the i-th tool of a scenario without an
// explicit motion block (tools stay about 1.5 m in front of the camera, inside the volume).
ToolMotion default_motion(int tool_index);

}  // namespace arnav::hil
