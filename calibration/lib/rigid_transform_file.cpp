#include "calibration/lib/rigid_transform_file.hpp"

#include <cctype>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <Eigen/SVD>
#include <yaml-cpp/yaml.h>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/versioned_yaml.hpp"

namespace arnav::calib {
namespace {

std::string where(const std::string& source, const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.line < 0) return source;
  return source + ":" + std::to_string(mark.line + 1);
}

template <typename T>
T scalar(const YAML::Node& map, const char* key, const std::string& source) {
  const YAML::Node node = map[key];
  if (!node) throw CalibError(source + ": missing key '" + key + "'");
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    throw CalibError(where(source, node) + ": key '" + key + "' has the wrong type");
  }
}

}  // namespace

bool valid_frame_name(const std::string& name) {
  if (name.empty() || name.size() > 32 || !std::isupper(static_cast<unsigned char>(name[0]))) {
    return false;
  }
  for (char c : name) {
    if (!std::isalnum(static_cast<unsigned char>(c))) return false;
  }
  return true;
}

RigidTransformRecord parse_transform(const std::string& yaml_text, const std::string& source) {
  const YAML::Node root = load_versioned_yaml(yaml_text, source, "an ARNav transform file", "arnav_transform_version");
  RigidTransformRecord r;
  r.parent_frame = scalar<std::string>(root, "parent_frame", source);
  r.child_frame = scalar<std::string>(root, "child_frame", source);
  for (const std::string& f : {r.parent_frame, r.child_frame}) {
    if (!valid_frame_name(f)) {
      throw CalibError(source + ": frame name '" + f +
                       "' is invalid (letters and digits, starting upper-case, e.g. Cam, Ndi)");
    }
  }
  const std::string name = scalar<std::string>(root, "name", source);
  if (name != r.name()) {
    throw CalibError(where(source, root["name"]) + ": name '" + name + "' does not match frames " +
                     r.parent_frame + " -> " + r.child_frame + " (expected '" + r.name() + "')");
  }
  const std::string units = scalar<std::string>(root, "units", source);
  if (units != "mm") {
    throw CalibError(where(source, root["units"]) + ": units '" + units +
                     "' not supported (ARNav transforms are in mm)");
  }
  const YAML::Node m = root["matrix_row_major"];
  if (!m) throw CalibError(source + ": missing key 'matrix_row_major' (16 numbers)");
  if (!m.IsSequence() || m.size() != 16) {
    throw CalibError(where(source, m) + ": matrix_row_major must be a list of 16 numbers");
  }
  Eigen::Matrix4d M;
  for (int i = 0; i < 16; ++i) {
    try {
      M(i / 4, i % 4) = m[i].as<double>();
    } catch (const YAML::Exception&) {
      throw CalibError(where(source, m[i]) + ": matrix_row_major entry " + std::to_string(i + 1) +
                       " is not a number");
    }
    if (!std::isfinite(M(i / 4, i % 4))) {
      throw CalibError(where(source, m[i]) + ": matrix_row_major entry " + std::to_string(i + 1) +
                       " is not finite");
    }
  }
  if (M.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) {
    throw CalibError(where(source, m) + ": last matrix row must be 0 0 0 1");
  }
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  const double orth_err = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (orth_err > 1e-6 || R.determinant() < 0.0) {
    throw CalibError(where(source, m) + ": rotation part is not a rotation (|R^T R - I| = " +
                     std::to_string(orth_err) + ", det = " + std::to_string(R.determinant()) + ")");
  }
  // Remove the rounding left by the decimal text so compositions stay rigid.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  r.X_ParentChild.linear() = svd.matrixU() * svd.matrixV().transpose();
  r.X_ParentChild.translation() = M.topRightCorner<3, 1>();
  if (root["method"]) r.method = scalar<std::string>(root, "method", source);
  if (root["date"]) r.date = scalar<std::string>(root, "date", source);
  if (root["samples"]) r.samples = scalar<int>(root, "samples", source);
  if (const YAML::Node res = root["residuals"]) {
    if (!res.IsMap()) throw CalibError(where(source, res) + ": residuals must be a map name: number");
    for (const auto& kv : res) {
      try {
        r.residuals[kv.first.as<std::string>()] = kv.second.as<double>();
      } catch (const YAML::Exception&) {
        throw CalibError(where(source, kv.second) + ": residual values must be numbers");
      }
    }
  }
  return r;
}

RigidTransformRecord read_transform(const std::filesystem::path& path) {
  return parse_transform(read_text_file(path, "the transform file"), path.string());
}

RigidTransformRecord read_transform(const std::filesystem::path& path,
                                    const std::string& expected_name) {
  RigidTransformRecord r = read_transform(path);
  if (r.name() != expected_name) {
    throw CalibError(path.string() + ": holds " + r.name() + " but " + expected_name +
                     " was expected (check which calibration file is configured)");
  }
  return r;
}

std::string format_transform(const RigidTransformRecord& r) {
  if (!valid_frame_name(r.parent_frame) || !valid_frame_name(r.child_frame)) {
    throw CalibError("transform " + r.name() + ": invalid frame names");
  }
  std::ostringstream out;
  out << std::setprecision(17);
  out << "# ARNav rigid transform (docs/calibration.md): " << r.name() << " = pose of frame "
      << r.child_frame << " in frame " << r.parent_frame << ";\n# p_" << r.parent_frame
      << " = X * p_" << r.child_frame << ", millimetres.\n";
  out << "arnav_transform_version: 1\n";
  out << "name: " << r.name() << "\n";
  out << "parent_frame: " << r.parent_frame << "\n";
  out << "child_frame: " << r.child_frame << "\n";
  out << "units: mm\n";
  const Eigen::Matrix4d M = r.X_ParentChild.matrix();
  out << "matrix_row_major: [";
  for (int i = 0; i < 16; ++i) out << (i ? ", " : "") << (i % 4 == 0 && i ? "\n    " : "") << M(i / 4, i % 4);
  out << "]\n";
  out << "method: " << YAML::Dump(YAML::Node(r.method)) << "\n";
  out << "date: \"" << r.date << "\"\n";
  out << "samples: " << r.samples << "\n";
  out << "residuals:";
  if (r.residuals.empty()) out << " {}";
  out << "\n";
  for (const auto& [key, value] : r.residuals) out << "  " << key << ": " << value << "\n";
  return out.str();
}

void write_transform(const std::filesystem::path& path, const RigidTransformRecord& r) {
  const std::string text = format_transform(r);
  std::ofstream out(path, std::ios::binary);
  if (!out) throw CalibError(path.string() + ": cannot write the transform file");
  out << text;
  if (!out) throw CalibError(path.string() + ": write failed");
}

}  // namespace arnav::calib
