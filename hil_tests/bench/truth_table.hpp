#pragma once
// Reads the simulator's ground truth (--truth CSV) and compares published poses with it
// at the wire format's resolution.
#include <cstdint>
#include <map>
#include <string>
#include <utility>

#include <Eigen/Geometry>

#include "arnav/tool_pose_t.hpp"

namespace arnav::hil {

// q/p_NdiTool: what the simulated device reported (with the realistic measurement model,
// the pose fitted to noisy markers; docs/hil.md "Sensor errors"), which the wire must carry
// unchanged; q/p_NdiTool_true: the tool's true pose. Equal under the ideal model.
struct TruthEntry {
  bool valid = false;
  std::uint32_t port_status = 0;
  Eigen::Quaterniond q_NdiTool;
  Eigen::Vector3d p_NdiTool_mm;
  Eigen::Quaterniond q_NdiTool_true;
  Eigen::Vector3d p_NdiTool_true_mm;
  double rms_error_mm = 0.0;
  bool dropout = false;
};

// Key: (frame number, tool name). Frame numbers restart after a device reset, so the
// simulator's motion is a function of the frame number alone: equal keys, equal truth.
using TruthTable = std::map<std::pair<std::uint32_t, std::string>, TruthEntry>;

// Throws std::runtime_error naming the file and line on malformed input.
TruthTable read_truth_csv(const std::string& path);

struct Resolution {
  double position_mm;   // BX float32: ~1e-4 mm at 1.5 m; TX: 0.005 mm (0.01 mm steps)
  double quaternion;    // BX float32: ~1e-7; TX: 5e-5 per component (1e-4 steps), more after normalising
};
inline constexpr Resolution kBxResolution{1e-3, 1e-6};
inline constexpr Resolution kTxResolution{0.0051, 2e-4};

// Empty if the pose agrees with the truth within `res`, else what differs.
std::string compare_to_truth(const tool_pose_t& pose, const TruthTable& truth, Resolution res);

}  // namespace arnav::hil
