#include "appliance/markers/camera_model.hpp"

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace arnav::markers {
namespace {

// Iterative undistortion with a tight criterion: the default 5 iterations leave
// ~0.1 px errors near the image corners for moderate barrel distortion.
const cv::TermCriteria kUndistortCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 50, 1e-12);

}  // namespace

std::vector<cv::Point2d> CameraModel::project(const std::vector<Eigen::Vector3d>& p_CamQ_mm) const {
  std::vector<cv::Point3d> object;
  object.reserve(p_CamQ_mm.size());
  for (const auto& p : p_CamQ_mm) object.emplace_back(p.x(), p.y(), p.z());
  std::vector<cv::Point2d> px;
  if (object.empty()) return px;
  cv::projectPoints(object, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, distortion, px);
  return px;
}

std::vector<cv::Point2d> CameraModel::normalised(const std::vector<cv::Point2d>& px) const {
  std::vector<cv::Point2d> out;
  if (px.empty()) return out;
  cv::undistortPoints(px, out, K, distortion, cv::noArray(), cv::noArray(), kUndistortCriteria);
  return out;
}

std::vector<cv::Point2d> CameraModel::undistort_pixels(const std::vector<cv::Point2d>& px) const {
  std::vector<cv::Point2d> out = normalised(px);
  for (auto& p : out) p = cv::Point2d(K(0, 0) * p.x + K(0, 1) * p.y + K(0, 2), K(1, 1) * p.y + K(1, 2));
  return out;
}

void validate(const CameraModel& camera) {
  if (camera.width <= 0 || camera.height <= 0) {
    throw std::invalid_argument("camera model: image size " + std::to_string(camera.width) + "x" +
                                std::to_string(camera.height) + " must be positive");
  }
  if (!(camera.K(0, 0) > 0.0) || !(camera.K(1, 1) > 0.0)) {
    throw std::invalid_argument("camera model: focal lengths fx, fy must be > 0");
  }
  const size_t n = camera.distortion.size();
  if (!(n == 0 || n == 4 || n == 5 || n == 8 || n == 12 || n == 14)) {
    throw std::invalid_argument("camera model: " + std::to_string(n) +
                                " distortion coefficients (expected 0, 4, 5, 8, 12 or 14 in OpenCV order)");
  }
  for (double d : camera.distortion) {
    if (!std::isfinite(d)) throw std::invalid_argument("camera model: a distortion coefficient is not finite");
  }
}

CameraModel pinhole_camera(int width, int height, double horizontal_fov_deg) {
  CameraModel cam;
  cam.width = width;
  cam.height = height;
  const double f = 0.5 * width / std::tan(0.5 * horizontal_fov_deg * std::numbers::pi / 180.0);
  cam.K = cv::Matx33d(f, 0, 0.5 * (width - 1), 0, f, 0.5 * (height - 1), 0, 0, 1);
  return cam;
}

}  // namespace arnav::markers
