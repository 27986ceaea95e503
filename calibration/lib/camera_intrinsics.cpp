#include "calibration/lib/camera_intrinsics.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

constexpr int kFormatVersion = 1;

bool valid_distortion_count(std::size_t n) {
  return n == 4 || n == 5 || n == 8 || n == 12 || n == 14;
}

CameraIntrinsics from_storage(cv::FileStorage& fs, const std::string& source) {
  auto need = [&](const char* key) {
    cv::FileNode node = fs[key];
    if (node.empty()) {
      throw CalibError(source + ": missing key '" + key +
                       "' (an ARNav intrinsics file is written by `arnav-calib intrinsics`)");
    }
    return node;
  };
  auto need_number = [&](const char* key) {
    cv::FileNode node = need(key);
    if (!node.isReal() && !node.isInt()) {
      throw CalibError(source + ": key '" + key + "' must be a number");
    }
    return static_cast<double>(node);
  };
  CameraIntrinsics in;
  const double version = need_number("arnav_intrinsics_version");
  if (version != kFormatVersion) {
    throw CalibError(source + ": arnav_intrinsics_version " + std::to_string(version) +
                     " is not supported (this build reads version 1)");
  }
  if (!fs["camera_name"].empty() && fs["camera_name"].isString()) {
    in.camera_name = static_cast<std::string>(fs["camera_name"]);
  }
  cv::FileNode model = need("model");
  if (!model.isString()) throw CalibError(source + ": key 'model' must be a string");
  in.model = static_cast<std::string>(model);
  if (in.model != "opencv_radtan") {
    throw CalibError(source + ": model '" + in.model +
                     "' is not supported (only opencv_radtan: pinhole + OpenCV distortion)");
  }
  in.image_width = static_cast<int>(need_number("image_width"));
  in.image_height = static_cast<int>(need_number("image_height"));

  cv::Mat K;
  cv::Mat dist;
  try {
    need("camera_matrix") >> K;
    need("distortion_coefficients") >> dist;
  } catch (const cv::Exception& e) {
    throw CalibError(source + ": camera_matrix/distortion_coefficients must be "
                     "!!opencv-matrix entries (" + e.msg + ")");
  }
  if (K.rows != 3 || K.cols != 3) {
    throw CalibError(source + ": camera_matrix must be 3x3, found " + std::to_string(K.rows) +
                     "x" + std::to_string(K.cols));
  }
  K.convertTo(K, CV_64F);
  in.camera_matrix = cv::Matx33d(K);
  if (dist.empty() || (dist.rows != 1 && dist.cols != 1)) {
    throw CalibError(source + ": distortion_coefficients must be a 1xN or Nx1 matrix");
  }
  dist.convertTo(dist, CV_64F);
  in.distortion.assign(dist.begin<double>(), dist.end<double>());
  in.rms_reprojection_error_px = need_number("rms_reprojection_error_px");
  if (!fs["views_used"].empty()) in.views_used = static_cast<int>(fs["views_used"]);
  cv::FileNode date = need("calibration_date");
  if (!date.isString()) throw CalibError(source + ": key 'calibration_date' must be a string");
  in.calibration_date = static_cast<std::string>(date);
  validate_intrinsics(in, source);
  return in;
}

}  // namespace

cv::Mat CameraIntrinsics::distortion_mat() const {
  cv::Mat m(1, static_cast<int>(distortion.size()), CV_64F);
  for (std::size_t i = 0; i < distortion.size(); ++i) m.at<double>(0, static_cast<int>(i)) = distortion[i];
  return m;
}

void validate_intrinsics(const CameraIntrinsics& in, const std::string& source) {
  const auto& K = in.camera_matrix;
  auto fail = [&](const std::string& what) { throw CalibError(source + ": " + what); };
  if (in.image_width <= 0 || in.image_height <= 0 || in.image_width > 100000 ||
      in.image_height > 100000) {
    fail("image size " + std::to_string(in.image_width) + "x" + std::to_string(in.image_height) +
         " is not a plausible camera image size");
  }
  for (int i = 0; i < 9; ++i) {
    if (!std::isfinite(K.val[i])) fail("camera_matrix has a non-finite entry");
  }
  if (!(K(0, 0) > 0.0) || !(K(1, 1) > 0.0)) fail("focal lengths fx, fy must be positive");
  if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0) {
    fail("camera_matrix must have the form [fx s cx; 0 fy cy; 0 0 1]");
  }
  if (K(0, 2) < 0.0 || K(0, 2) > in.image_width || K(1, 2) < 0.0 || K(1, 2) > in.image_height) {
    fail("principal point (cx, cy) lies outside the image");
  }
  if (!valid_distortion_count(in.distortion.size())) {
    fail("distortion_coefficients has " + std::to_string(in.distortion.size()) +
         " entries; OpenCV uses 4, 5, 8, 12 or 14");
  }
  for (double d : in.distortion) {
    if (!std::isfinite(d)) fail("distortion_coefficients has a non-finite entry");
  }
  if (!std::isfinite(in.rms_reprojection_error_px) || in.rms_reprojection_error_px < 0.0) {
    fail("rms_reprojection_error_px must be a finite number >= 0");
  }
}

CameraIntrinsics parse_intrinsics(const std::string& yaml_text, const std::string& source) {
  cv::FileStorage fs;
  try {
    if (!fs.open(yaml_text, cv::FileStorage::READ | cv::FileStorage::MEMORY |
                                cv::FileStorage::FORMAT_YAML)) {
      throw CalibError(source + ": not an OpenCV FileStorage YAML document");
    }
    return from_storage(fs, source);
  } catch (const cv::Exception& e) {
    // OpenCV's parser reports the offending line in its message.
    throw CalibError(source + ": unreadable FileStorage YAML: " + e.msg);
  }
}

CameraIntrinsics read_intrinsics(const std::filesystem::path& path) {
  std::string content = read_text_file(path, "the intrinsics file (run `arnav-calib intrinsics` to make one)");
  if (content.rfind("%YAML", 0) != 0) content = "%YAML:1.0\n" + content;
  return parse_intrinsics(content, path.string());
}

void write_intrinsics(const std::filesystem::path& path, const CameraIntrinsics& in) {
  validate_intrinsics(in, path.string());
  cv::FileStorage fs(path.string(), cv::FileStorage::WRITE | cv::FileStorage::FORMAT_YAML);
  if (!fs.isOpened()) throw CalibError(path.string() + ": cannot write the intrinsics file");
  fs.writeComment("ARNav camera intrinsics (docs/calibration.md). Pixels; frame Cam = "
                  "OpenCV camera frame (x right, y down, z forward).");
  fs << "arnav_intrinsics_version" << kFormatVersion;
  fs << "camera_name" << in.camera_name;
  fs << "frame" << "Cam";
  fs << "model" << in.model;
  fs << "image_width" << in.image_width;
  fs << "image_height" << in.image_height;
  fs << "camera_matrix" << cv::Mat(in.camera_matrix);
  fs << "distortion_coefficients" << in.distortion_mat();
  fs << "rms_reprojection_error_px" << in.rms_reprojection_error_px;
  fs << "views_used" << in.views_used;
  fs << "calibration_date" << in.calibration_date;
  fs.release();
}

Eigen::Isometry3d board_pose_pnp(const std::vector<cv::Point3f>& board_mm, const std::vector<cv::Point2f>& image_px,
                                 const CameraIntrinsics& intrinsics, const std::string& what) {
  cv::Mat rvec, tvec, R;
  const cv::Mat K(intrinsics.camera_matrix);
  const cv::Mat dist = intrinsics.distortion_mat();
  if (!cv::solvePnP(board_mm, image_px, K, dist, rvec, tvec, false, cv::SOLVEPNP_IPPE))
    throw CalibError(what + ": solvePnP failed");
  cv::solvePnPRefineLM(board_mm, image_px, K, dist, rvec, tvec);
  cv::Rodrigues(rvec, R);
  Eigen::Matrix3d R_CamBoard;
  Eigen::Vector3d t_CamBoard_mm;
  cv::cv2eigen(R, R_CamBoard);
  cv::cv2eigen(tvec, t_CamBoard_mm);
  Eigen::Isometry3d X_CamBoard = Eigen::Isometry3d::Identity();
  X_CamBoard.linear() = R_CamBoard;
  X_CamBoard.translation() = t_CamBoard_mm;
  return X_CamBoard;
}

}  // namespace arnav::calib
