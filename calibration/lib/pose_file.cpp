#include "calibration/lib/pose_file.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <Eigen/SVD>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/numeric_lines.hpp"

namespace arnav::calib {


std::vector<Eigen::Vector3d> parse_point_list(const std::string& text, const std::string& source) {
  std::vector<Eigen::Vector3d> points;
  for_each_numeric_line(text, source, [&](const std::vector<double>& v, int, const std::string& at) {
    if (v.size() != 3) {
      throw CalibError(at + "expected 3 numbers (x y z, mm), found " + std::to_string(v.size()));
    }
    points.emplace_back(v[0], v[1], v[2]);
  });
  return points;
}

std::vector<Eigen::Vector3d> read_point_list(const std::filesystem::path& path) {
  return parse_point_list(read_text_file(path, "the point file"), path.string());
}

std::vector<PoseSample> parse_pose_list(const std::string& text, const std::string& source) {
  std::vector<PoseSample> poses;
  for_each_numeric_line(text, source, [&](const std::vector<double>& values, int line_no, const std::string& at) {
    if (values.size() != 16) {
      throw CalibError(at + "expected 16 numbers (row-major 4x4 pose, mm), found " +
                       std::to_string(values.size()));
    }
    Eigen::Matrix4d M;
    for (int i = 0; i < 16; ++i) M(i / 4, i % 4) = values[static_cast<std::size_t>(i)];
    if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) {
      throw CalibError(at + "last row must be 0 0 0 1 (is the matrix transposed?)");
    }
    const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
    const double orth_err = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
    if (orth_err > 1e-3 || R.determinant() < 0.0) {
      throw CalibError(at + "rotation part is not a rotation (|R^T R - I| = " +
                       std::to_string(orth_err) + ")");
    }
    Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
    PoseSample s;
    s.X_ParentChild.setIdentity();
    s.X_ParentChild.linear() = svd.matrixU() * svd.matrixV().transpose();
    s.X_ParentChild.translation() = M.topRightCorner<3, 1>();
    s.line = line_no;
    poses.push_back(s);
  });
  return poses;
}

std::vector<PoseSample> read_pose_list(const std::filesystem::path& path) {
  return parse_pose_list(read_text_file(path, "the pose file"), path.string());
}

void write_pose_list(const std::filesystem::path& path, const std::vector<Eigen::Isometry3d>& poses,
                     const std::string& header_comment) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw CalibError(path.string() + ": cannot write the pose file");
  out << std::setprecision(17);
  std::istringstream header(header_comment);
  std::string line;
  while (std::getline(header, line)) out << "# " << line << "\n";
  for (const auto& X : poses) {
    const Eigen::Matrix4d M = X.matrix();
    for (int i = 0; i < 16; ++i) out << (i ? " " : "") << M(i / 4, i % 4);
    out << "\n";
  }
  if (!out) throw CalibError(path.string() + ": write failed");
}

}  // namespace arnav::calib
