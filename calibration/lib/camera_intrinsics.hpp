#pragma once
// Camera intrinsics and their file format: OpenCV FileStorage YAML (readable by
// cv::FileStorage in any OpenCV program). Pixels for the image plane, the camera frame
// "Cam" is OpenCV's: x right, y down, z forward along the optical axis.
//
//   %YAML:1.0
//   arnav_intrinsics_version: 1
//   camera_name: "bench-cam"
//   frame: Cam
//   model: "opencv_radtan"          # pinhole + OpenCV distortion (k1 k2 p1 p2 [k3 ...])
//   image_width: 1280
//   image_height: 720
//   camera_matrix: !!opencv-matrix  {rows: 3, cols: 3, dt: d, data: [fx 0 cx 0 fy cy 0 0 1]}
//   distortion_coefficients: !!opencv-matrix {rows: 1, cols: 5, dt: d, data: [...]}
//   rms_reprojection_error_px: 0.21
//   views_used: 18                  # 0 when not known
//   calibration_date: "2026-11-21T10:07:55Z"
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

namespace arnav::calib {

struct CameraIntrinsics {
  std::string camera_name = "camera";
  std::string model = "opencv_radtan";  // the only model ARNav uses so far
  int image_width = 0;                  // px
  int image_height = 0;                 // px
  cv::Matx33d camera_matrix = cv::Matx33d::eye();  // [fx 0 cx; 0 fy cy; 0 0 1], px
  std::vector<double> distortion;       // 4, 5, 8, 12 or 14 OpenCV coefficients
  double rms_reprojection_error_px = 0.0;
  int views_used = 0;
  std::string calibration_date;         // ISO 8601 UTC

  cv::Mat distortion_mat() const;       // 1xN CV_64F copy for OpenCV calls
};

// Throws CalibError naming the file and the missing/invalid key.
CameraIntrinsics read_intrinsics(const std::filesystem::path& path);
// Parses FileStorage YAML text; `source` names it in errors (for tests and fuzzing).
CameraIntrinsics parse_intrinsics(const std::string& yaml_text, const std::string& source);
// Validates first (throws CalibError on an inconsistent struct), then writes.
void write_intrinsics(const std::filesystem::path& path, const CameraIntrinsics& intrinsics);
// Checks sizes, focal lengths, principal point inside the image, coefficient count.
void validate_intrinsics(const CameraIntrinsics& intrinsics, const std::string& source);

// X_CamBoard from planar board corners (board_mm in the Board frame, z = 0) and their
// pixels: OpenCV IPPE, then Levenberg-Marquardt refinement. Throws CalibError (naming
// `what`) when solvePnP fails.
Eigen::Isometry3d board_pose_pnp(const std::vector<cv::Point3f>& board_mm, const std::vector<cv::Point2f>& image_px,
                                 const CameraIntrinsics& intrinsics, const std::string& what);

}  // namespace arnav::calib
