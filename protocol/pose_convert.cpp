#include "protocol/pose_convert.hpp"

#include <stdexcept>

namespace arnav {

void set_pose(tool_pose_t& msg, const Eigen::Isometry3d& X_ParentChild) {
  const Eigen::Vector3d p = X_ParentChild.translation();
  Eigen::Quaterniond q(X_ParentChild.rotation());
  q.normalize();
  if (q.w() < 0) q.coeffs() *= -1.0;  // one canonical sign: w >= 0
  for (int i = 0; i < 3; ++i) msg.p_ParentChild_mm[i] = p[i];
  msg.q_ParentChild_wxyz[0] = q.w();
  msg.q_ParentChild_wxyz[1] = q.x();
  msg.q_ParentChild_wxyz[2] = q.y();
  msg.q_ParentChild_wxyz[3] = q.z();
}

Eigen::Isometry3d get_pose(const tool_pose_t& msg) {
  Eigen::Quaterniond q(msg.q_ParentChild_wxyz[0], msg.q_ParentChild_wxyz[1], msg.q_ParentChild_wxyz[2],
                       msg.q_ParentChild_wxyz[3]);
  const double n = q.norm();
  if (!(n > 1e-9)) throw std::invalid_argument("tool_pose_t '" + msg.tool_name + "': zero quaternion");
  q.coeffs() /= n;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = q.toRotationMatrix();
  X.translation() = Eigen::Vector3d(msg.p_ParentChild_mm[0], msg.p_ParentChild_mm[1], msg.p_ParentChild_mm[2]);
  return X;
}

}  // namespace arnav
