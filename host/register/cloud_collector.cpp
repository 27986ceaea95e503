#include "host/register/cloud_collector.hpp"

#include <utility>

namespace arnav::host {

int PointCloudCollector::add_message(const void* data, std::size_t size, const std::string& channel) {
  return add(decode_point_cloud_message(data, size, channel));
}

int PointCloudCollector::add(const PointCloud& m) {
  if (m.sequence >= 0) seen_.insert(m.sequence);
  if (frame_.empty()) frame_ = m.frame_name;
  if (m.frame_name != frame_) {
    ++wrong_frame_;
    if (wrong_frame_names_.find("'" + m.frame_name + "'") == std::string::npos)
      wrong_frame_names_ += (wrong_frame_names_.empty() ? "" : ", ") + ("'" + m.frame_name + "'");
    return 0;
  }
  if (m.sequence >= 0 && !sequences_.insert(m.sequence).second) {
    ++duplicates_;
    return 0;
  }
  ++messages_;
  for (int i = 0; i < m.size(); ++i)
    for (int k = 0; k < 3; ++k) points_.push_back(m.points_mm(k, i));
  if (m.size() > 0) {
    if (!m.has_normals()) all_normals_ = false;
    if (m.ids.size() != static_cast<std::size_t>(m.size())) all_ids_ = false;
    if (m.has_normals())
      for (int i = 0; i < m.size(); ++i)
        for (int k = 0; k < 3; ++k) normals_.push_back(m.normals(k, i));
    if (m.ids.size() == static_cast<std::size_t>(m.size())) ids_.insert(ids_.end(), m.ids.begin(), m.ids.end());
  }
  return m.size();
}

long long PointCloudCollector::missed() const {
  if (seen_.size() < 2) return 0;
  const long long span = *seen_.rbegin() - *seen_.begin() + 1;
  return span - static_cast<long long>(seen_.size());
}

PointCloud PointCloudCollector::cloud() const {
  PointCloud c;
  const int n = points();
  c.points_mm = Eigen::Map<const Eigen::Matrix3Xd>(points_.data(), 3, n);
  if (all_normals_ && normals_.size() == points_.size() && n > 0) c.normals = Eigen::Map<const Eigen::Matrix3Xd>(normals_.data(), 3, n);
  if (all_ids_ && ids_.size() == static_cast<std::size_t>(n)) c.ids = ids_;
  c.lines.assign(static_cast<std::size_t>(n), 0);
  c.frame_name = frame_;
  c.source = "live swab (" + std::to_string(messages_) + " messages, frame " + (frame_.empty() ? std::string("?") : frame_) + ")";
  return c;
}

std::string PointCloudCollector::summary() const {
  std::string s = std::to_string(points()) + " points from " + std::to_string(messages_) + " messages in frame '" + frame_ + "'";
  if (missed() > 0) s += ", " + std::to_string(missed()) + " messages lost (sequence gaps)";
  if (duplicates_ > 0) s += ", " + std::to_string(duplicates_) + " duplicates dropped";
  if (wrong_frame_ > 0) s += ", " + std::to_string(wrong_frame_) + " messages refused in frame " + wrong_frame_names_ + " (not '" + frame_ + "')";
  return s;
}

}  // namespace arnav::host
