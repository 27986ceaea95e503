#pragma once
// Accumulates live point clouds (arnav.point_cloud_t messages, e.g. the appliance's
// pointer swab on ARNAV_CLOUD_pointer) into one cloud for registration. Each message is
// decoded and checked (decode_point_cloud_message); a message repeated with a sequence
// number already taken is dropped (UDP may duplicate), a gap in the numbers is counted
// (lost messages: fewer points, not wrong ones), and a message in another frame than the
// first one (or than the expected frame) is refused and counted - points of two frames
// must never be mixed. Normals and ids are kept only when every message had them.
// Frame: the messages' frame (Intraop for arnav-register). Units: mm.
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "host/register/point_cloud.hpp"

namespace arnav::host {

class PointCloudCollector {
 public:
  // expected_frame: empty to take the first message's frame.
  explicit PointCloudCollector(std::string expected_frame = {}) : frame_(std::move(expected_frame)) {}

  // Adds one encoded message. Throws LoadError for a corrupt message (naming the
  // channel and its sequence number); returns the number of points taken (0 for a
  // duplicate or a refused frame).
  int add_message(const void* data, std::size_t size, const std::string& channel);
  // Adds a decoded cloud (same rules).
  int add(const PointCloud& message);

  PointCloud cloud() const;                        // everything taken so far
  int points() const { return static_cast<int>(points_.size() / 3); }
  int messages() const { return messages_; }       // taken
  int duplicates() const { return duplicates_; }
  int wrong_frame() const { return wrong_frame_; }
  long long missed() const;                        // gaps in the sequence numbers received
  const std::string& frame_name() const { return frame_; }
  std::string summary() const;                     // one line for people

 private:
  std::string frame_;
  std::vector<double> points_;                     // x y z per point, flattened
  std::vector<double> normals_;
  std::vector<long long> ids_;
  bool all_normals_ = true, all_ids_ = true;
  std::set<long long> sequences_;              // taken
  std::set<long long> seen_;                   // taken or refused (for the gaps)
  int messages_ = 0, duplicates_ = 0, wrong_frame_ = 0;
  std::string wrong_frame_names_;
};

}  // namespace arnav::host
