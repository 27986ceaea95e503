#pragma once
// Pinhole camera with OpenCV lens distortion: what the synthetic camera renders through
// and what corner undistortion and pose estimation use. Frame Cam: origin at the optical
// centre, x right, y down, z along the optical axis (OpenCV). Units: pixels, millimetres.
#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <vector>

namespace arnav::markers {

struct CameraModel {
  int width = 0;
  int height = 0;
  cv::Matx33d K = cv::Matx33d::eye();
  // OpenCV order: k1 k2 p1 p2 [k3 [k4 k5 k6]]; empty means no distortion.
  std::vector<double> distortion;

  // Pixel coordinates (distorted, as the sensor sees it) of points given in Cam (mm).
  std::vector<cv::Point2d> project(const std::vector<Eigen::Vector3d>& p_CamQ_mm) const;
  // Distorted pixels -> ideal pinhole pixels with the same K (distortion removed).
  std::vector<cv::Point2d> undistort_pixels(const std::vector<cv::Point2d>& px) const;
  // Distorted pixels -> normalised image coordinates (x/z, y/z).
  std::vector<cv::Point2d> normalised(const std::vector<cv::Point2d>& px) const;
};

// Throws std::invalid_argument when sizes, focal lengths or the distortion count are invalid.
void validate(const CameraModel& camera);

// A distortion-free camera with the given horizontal field of view, centred principal point.
CameraModel pinhole_camera(int width, int height, double horizontal_fov_deg);

}  // namespace arnav::markers
