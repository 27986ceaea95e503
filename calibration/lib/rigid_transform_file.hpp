#pragma once
// Rigid transform files: one named calibration result X_AB (pose of frame B in frame A,
// maps B coordinates into A, millimetres) with its frame names, method, residuals and
// date. YAML (yaml-cpp); the appliance loads these at start (docs/calibration.md).
//
//   arnav_transform_version: 1
//   name: X_CamNdi                 # always "X_" + parent_frame + child_frame
//   parent_frame: Cam
//   child_frame: Ndi
//   units: mm
//   matrix_row_major: [r00, r01, r02, tx, r10, r11, r12, ty, r20, r21, r22, tz, 0, 0, 0, 1]
//   method: "hand-eye AX=ZB (OpenCV Shah)"
//   date: "2026-11-21T10:07:55Z"
//   residuals: {rms_mm: 0.31, max_mm: 0.72, rms_deg: 0.08}   # names free, values numbers
//   samples: 24
#include <filesystem>
#include <map>
#include <string>

#include <Eigen/Geometry>

namespace arnav::calib {

struct RigidTransformRecord {
  std::string parent_frame;          // A in X_AB
  std::string child_frame;           // B in X_AB
  Eigen::Isometry3d X_ParentChild = Eigen::Isometry3d::Identity();  // mm
  std::string method;
  std::string date;                  // ISO 8601 UTC
  std::map<std::string, double> residuals;  // e.g. rms_mm, max_mm, rms_deg
  int samples = 0;

  std::string name() const { return "X_" + parent_frame + child_frame; }
};

// Throws CalibError naming file, line and key. The rotation must be orthonormal with
// det +1 (tolerance 1e-6) and the last row 0 0 0 1; it is re-orthonormalised on load.
RigidTransformRecord read_transform(const std::filesystem::path& path);
RigidTransformRecord parse_transform(const std::string& yaml_text, const std::string& source);
// Also checks that the file's name matches `expected_name` (e.g. "X_CamNdi").
RigidTransformRecord read_transform(const std::filesystem::path& path,
                                    const std::string& expected_name);
void write_transform(const std::filesystem::path& path, const RigidTransformRecord& record);
std::string format_transform(const RigidTransformRecord& record);

// Frame names: letters and digits, starting with an upper-case letter ("Cam", "Ndi",
// "Tool", "Board", "Ref2").
bool valid_frame_name(const std::string& name);

}  // namespace arnav::calib
