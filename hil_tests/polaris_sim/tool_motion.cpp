#include "hil_tests/polaris_sim/tool_motion.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>

namespace arnav::hil {

Eigen::Isometry3d ToolMotion::X_NdiTool(double t_s) const {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  if (path) return path->X_NdiModel * path->X_ModelTool(path->start_s + t_s - path->t0_s);
  if (phantom) {
    const double t = phantom->start_s + t_s - phantom->t0_s;
    return phantom->X_NdiModel * phantom->recording->tool_pose_at(t, phantom->tool);
  }
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  Eigen::Vector3d p = center_mm;
  for (int i = 0; i < 3; ++i) p[i] += amplitude_mm[i] * std::sin(kTwoPi * frequency_hz[i] * t_s + phase_rad[i]);
  const double angle = rotation_amplitude_rad * std::sin(kTwoPi * rotation_frequency_hz * t_s);
  const Eigen::Quaterniond q = (q_base * Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation_axis.normalized()))).normalized();
  X.linear() = q.toRotationMatrix();
  X.translation() = p;
  return X;
}

Eigen::Isometry3d ScriptedToolPath::X_ModelTool(double t) const {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  if (t_s.empty()) return X;
  std::size_t i = 0;
  double a = 0.0;
  if (t <= t_s.front()) {
    i = 0;
  } else if (t >= t_s.back()) {
    i = t_s.size() - 1;
  } else {
    i = static_cast<std::size_t>(std::upper_bound(t_s.begin(), t_s.end(), t) - t_s.begin()) - 1;
    a = (t - t_s[i]) / (t_s[i + 1] - t_s[i]);
  }
  if (a > 0.0) {
    X.translation() = (1.0 - a) * p_Model_mm[i] + a * p_Model_mm[i + 1];
    X.linear() = q_ModelTool[i].slerp(a, q_ModelTool[i + 1]).normalized().toRotationMatrix();
  } else {
    X.translation() = p_Model_mm[i];
    X.linear() = q_ModelTool[i].toRotationMatrix();
  }
  return X;
}

ScriptedToolPath parse_tool_path_csv(const std::string& text, const std::string& source) {
  ScriptedToolPath path;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  bool first_content = true;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::size_t b = line.find_first_not_of(" \t");
    if (b == std::string::npos || line[b] == '#') continue;
    const std::string where = source + ":" + std::to_string(line_no);
    if (first_content) {
      first_content = false;
      if (line.compare(b, 3, "t_s") == 0) continue;
    }
    std::vector<std::string> cells;
    std::stringstream row(line);
    std::string cell;
    while (std::getline(row, cell, ',')) cells.push_back(cell);
    if (!line.empty() && line.back() == ',') cells.emplace_back();
    if (cells.size() != 4 && cells.size() != 8)
      throw ToolPathError(where + ": expected 4 columns (t_s, x_mm, y_mm, z_mm) or 8 (..., qw, qx, qy, qz), got " +
                          std::to_string(cells.size()));
    double v[8] = {0, 0, 0, 0, 1, 0, 0, 0};
    static const char* names[8] = {"t_s", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"};
    for (std::size_t k = 0; k < cells.size(); ++k) {
      std::string c = cells[k];
      const std::size_t cb = c.find_first_not_of(" \t");
      const std::size_t ce = c.find_last_not_of(" \t");
      c = cb == std::string::npos ? std::string() : c.substr(cb, ce - cb + 1);
      try {
        std::size_t used = 0;
        v[k] = std::stod(c, &used);
        if (used != c.size() || !std::isfinite(v[k])) throw std::invalid_argument(c);
      } catch (const std::exception&) {
        throw ToolPathError(where + ": column " + names[k] + " must be a finite number, got '" + c + "'");
      }
    }
    if (v[0] < 0.0 || v[0] > 86400.0) throw ToolPathError(where + ": t_s " + cells[0] + " is outside [0, 86400] s");
    if (!path.t_s.empty() && !(v[0] > path.t_s.back()))
      throw ToolPathError(where + ": t_s must increase strictly (previous row " + std::to_string(path.t_s.back()) + " s)");
    for (int k = 1; k < 4; ++k)
      if (std::abs(v[k]) > 2000.0) throw ToolPathError(where + ": " + names[k] + " is outside +-2000 mm of the model origin");
    const Eigen::Quaterniond q(v[4], v[5], v[6], v[7]);
    if (std::abs(q.norm() - 1.0) > 1e-3)
      throw ToolPathError(where + ": orientation qw, qx, qy, qz must be a unit quaternion (norm " + std::to_string(q.norm()) + ")");
    path.t_s.push_back(v[0]);
    path.p_Model_mm.emplace_back(v[1], v[2], v[3]);
    path.q_ModelTool.push_back(q.normalized());
  }
  if (path.t_s.empty()) throw ToolPathError(source + ": no path rows (t_s, x_mm, y_mm, z_mm[, qw, qx, qy, qz])");
  return path;
}

ToolMotion default_motion(int tool_index) {
  const double k = static_cast<double>(tool_index);
  ToolMotion m;
  m.center_mm = Eigen::Vector3d(-150.0 + 60.0 * k, 40.0 * std::cos(k), -1400.0 - 25.0 * k);
  m.amplitude_mm = Eigen::Vector3d(60.0, 40.0, 25.0);
  m.frequency_hz = Eigen::Vector3d(0.21 + 0.02 * k, 0.33, 0.13 + 0.01 * k);
  m.phase_rad = Eigen::Vector3d(0.3 * k, 0.0, 1.1 * k);
  m.q_base = Eigen::Quaterniond(Eigen::AngleAxisd(0.4 * k + 0.2, Eigen::Vector3d(1.0, -0.5, 0.3).normalized()));
  m.rotation_axis = Eigen::Vector3d(0.2, 1.0, 0.1 * k).normalized();
  m.rotation_amplitude_rad = 0.6;
  m.rotation_frequency_hz = 0.17 + 0.03 * k;
  return m;
}

}  // namespace arnav::hil
