#pragma once
// Named point files of arnav-register (CSV, mm):
//   landmarks: name,model_x,model_y,model_z,intraop_x,intraop_y,intraop_z
//              anatomical landmarks in the scene (Model) frame and touched with the
//              tracked pointer in the intraoperative frame (Intraop); >= 3, unique names.
//   targets:   name,x_mm,y_mm,z_mm in the scene (Model) frame; written back with the same
//              header and names, carried into the Intraop frame.
// Blank lines and '#' comment lines are skipped. Errors are LoadErrors naming file and line.
#include <Eigen/Core>

#include <string>
#include <string_view>
#include <vector>

namespace arnav::host {

struct Landmark {
  std::string name;
  Eigen::Vector3d p_Model_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_Intraop_mm = Eigen::Vector3d::Zero();
  int line = 0;
};

struct NamedPoint {
  std::string name;
  Eigen::Vector3d p_mm = Eigen::Vector3d::Zero();
  int line = 0;
};

// parse_landmarks also requires at least 3 landmarks and unique names.
std::vector<Landmark> parse_landmarks(std::string_view content, const std::string& source);
std::vector<Landmark> read_landmarks(const std::string& path);
// Unique names; may be empty.
std::vector<NamedPoint> parse_targets(std::string_view content, const std::string& source);
std::vector<NamedPoint> read_targets(const std::string& path);
// Writes name,x_mm,y_mm,z_mm. Throws LoadError when the file cannot be written.
void write_targets(const std::string& path, const std::vector<NamedPoint>& targets);

}  // namespace arnav::host
