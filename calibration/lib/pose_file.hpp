#pragma once
// Pose list files (input of `arnav-calib pivot` and of hand-eye): one rigid pose per
// line as 16 numbers, the row-major 4x4 matrix X_NdiTool in millimetres, separated by
// spaces, tabs or commas. Blank lines and lines starting with '#' are ignored.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Geometry>

namespace arnav::calib {

struct PoseSample {
  Eigen::Isometry3d X_ParentChild;  // e.g. X_NdiTool, mm
  int line = 0;                     // 1-based line in the file
};

// Throws CalibError "FILE:LINE: ..." for a wrong column count, a non-number, a last row
// other than 0 0 0 1 or a rotation part that is not a rotation (|R^T R - I| > 1e-3).
std::vector<PoseSample> parse_pose_list(const std::string& text, const std::string& source);
std::vector<PoseSample> read_pose_list(const std::filesystem::path& path);
// Point lists (registration fiducials): one point per line, 3 numbers x y z in mm.
// Same comment/separator rules; "FILE:LINE: expected 3 numbers ..." on a bad line.
std::vector<Eigen::Vector3d> parse_point_list(const std::string& text, const std::string& source);
std::vector<Eigen::Vector3d> read_point_list(const std::filesystem::path& path);

void write_pose_list(const std::filesystem::path& path, const std::vector<Eigen::Isometry3d>& poses,
                     const std::string& header_comment);

}  // namespace arnav::calib
