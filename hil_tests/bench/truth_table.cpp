#include "hil_tests/bench/truth_table.hpp"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace arnav::hil {

TruthTable read_truth_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read ground truth " + path);
  TruthTable table;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line_no == 1) continue;  // header
    std::stringstream ss(line);
    std::vector<std::string> c;
    for (std::string cell; std::getline(ss, cell, ',');) c.push_back(cell);
    if (c.size() != 12 && c.size() != 21)
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": expected 12 columns (true pose) or 21 (true and reported pose)");
    try {
      TruthEntry e;
      e.valid = c[3] == "1";
      e.port_status = static_cast<std::uint32_t>(std::stoul(c[4]));
      e.q_NdiTool_true = Eigen::Quaterniond(std::stod(c[5]), std::stod(c[6]), std::stod(c[7]), std::stod(c[8]));
      e.p_NdiTool_true_mm = Eigen::Vector3d(std::stod(c[9]), std::stod(c[10]), std::stod(c[11]));
      e.q_NdiTool = e.q_NdiTool_true;
      e.p_NdiTool_mm = e.p_NdiTool_true_mm;
      if (c.size() == 21) {
        e.q_NdiTool = Eigen::Quaterniond(std::stod(c[12]), std::stod(c[13]), std::stod(c[14]), std::stod(c[15]));
        e.p_NdiTool_mm = Eigen::Vector3d(std::stod(c[16]), std::stod(c[17]), std::stod(c[18]));
        e.rms_error_mm = std::stod(c[19]);
        e.dropout = c[20] == "1";
      }
      // After a device reset the counter restarts and a frame number comes round again
      // with the same pose (motion is a function of the frame number); the tool may have
      // been hidden in one of those passes only.
      auto [it, inserted] = table.try_emplace({static_cast<std::uint32_t>(std::stoul(c[0])), c[2]}, e);
      if (!inserted) it->second.valid = it->second.valid || e.valid;
    } catch (const std::exception&) {
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": bad number");
    }
  }
  return table;
}

std::string compare_to_truth(const tool_pose_t& pose, const TruthTable& truth, Resolution res) {
  const auto it = truth.find({static_cast<std::uint32_t>(pose.device_frame_number), pose.tool_name});
  const std::string what = pose.tool_name + " frame " + std::to_string(pose.device_frame_number);
  if (it == truth.end()) return what + ": the simulator never reported this frame for this tool";
  const TruthEntry& t = it->second;
  if (!t.valid) return what + ": published as a pose but the simulator reported the tool missing";
  Eigen::Quaterniond q_true = t.q_NdiTool;
  if (q_true.w() < 0) q_true.coeffs() *= -1.0;
  const Eigen::Vector3d p(pose.p_ParentChild_mm[0], pose.p_ParentChild_mm[1], pose.p_ParentChild_mm[2]);
  const Eigen::Vector4d q(pose.q_ParentChild_wxyz[0], pose.q_ParentChild_wxyz[1], pose.q_ParentChild_wxyz[2], pose.q_ParentChild_wxyz[3]);
  const Eigen::Vector4d qt(q_true.w(), q_true.x(), q_true.y(), q_true.z());
  const double dp = (p - t.p_NdiTool_mm).cwiseAbs().maxCoeff();
  // q and -q are the same rotation; near w = 0 either sign may be published.
  const double dq = std::min((q - qt).cwiseAbs().maxCoeff(), (q + qt).cwiseAbs().maxCoeff());
  if (dp > res.position_mm || dq > res.quaternion) {
    std::ostringstream s;
    s << what << ": position off by " << dp << " mm (allowed " << res.position_mm << "), quaternion by " << dq << " (allowed "
      << res.quaternion << ")";
    return s.str();
  }
  return {};
}

}  // namespace arnav::hil
