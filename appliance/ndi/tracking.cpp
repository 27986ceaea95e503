#include "appliance/ndi/tracking.hpp"

namespace arnav::ndi {

std::uint32_t TrackingReply::frame_number() const {
  if (has_frame) return frame;
  for (std::size_t i = 0; i < count; ++i)
    if (handles[i].has_status) return handles[i].frame_number;
  return 0;
}

const HandleRecord* TrackingReply::find(std::uint8_t handle) const {
  for (std::size_t i = 0; i < count; ++i)
    if (handles[i].handle == handle) return &handles[i];
  return nullptr;
}

Eigen::Isometry3d X_NdiTool(const HandleRecord& record) {
  Eigen::Quaterniond q(record.q_NdiTool_wxyz[0], record.q_NdiTool_wxyz[1], record.q_NdiTool_wxyz[2],
                       record.q_NdiTool_wxyz[3]);
  if (q.norm() < 1e-9) q = Eigen::Quaterniond::Identity();  // device never sends this for Valid
  q.normalize();
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = q.toRotationMatrix();
  X.translation() = Eigen::Vector3d(record.p_NdiTool_mm[0], record.p_NdiTool_mm[1], record.p_NdiTool_mm[2]);
  return X;
}

}  // namespace arnav::ndi
