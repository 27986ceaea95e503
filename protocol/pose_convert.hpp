#pragma once
// Conversions between Eigen rigid transforms and the pose fields of tool_pose_t.
// X_AB maps frame-B coordinates into frame A (see docs/conventions.md).
#include <Eigen/Geometry>

#include "arnav/tool_pose_t.hpp"

namespace arnav {

// Writes position (mm) and unit quaternion (w first) of X_ParentChild into msg.
void set_pose(tool_pose_t& msg, const Eigen::Isometry3d& X_ParentChild);
// Reads them back; the quaternion is normalised (a zero quaternion throws).
Eigen::Isometry3d get_pose(const tool_pose_t& msg);

}  // namespace arnav
