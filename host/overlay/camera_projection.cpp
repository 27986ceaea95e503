#include "host/overlay/camera_projection.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "host/overlay/egl_context.hpp"

namespace arnav::host::overlay {

OverlayCamera OverlayCamera::scaled_to(int new_width, int new_height) const {
  OverlayCamera out = *this;
  const double sx = static_cast<double>(new_width) / width, sy = static_cast<double>(new_height) / height;
  out.width = new_width;
  out.height = new_height;
  // Pixel centres at integers: u' + 0.5 = s (u + 0.5).
  out.K(0, 0) *= sx;
  out.K(0, 2) = sx * (K(0, 2) + 0.5) - 0.5;
  out.K(1, 1) *= sy;
  out.K(1, 2) = sy * (K(1, 2) + 0.5) - 0.5;
  out.K(0, 1) *= sx;
  return out;
}

void validate(const OverlayCamera& camera) {
  if (camera.width <= 0 || camera.height <= 0)
    throw OverlayError("overlay camera: image size " + std::to_string(camera.width) + "x" + std::to_string(camera.height) +
                       " must be positive (check the intrinsics file's image_width/image_height)");
  if (!(camera.K(0, 0) > 0) || !(camera.K(1, 1) > 0))
    throw OverlayError("overlay camera: focal lengths must be positive (check camera_matrix of the intrinsics file)");
  const auto n = camera.distortion.size();
  if (!(n == 0 || n == 4 || n == 5 || n == 8 || n == 12 || n == 14))
    throw OverlayError("overlay camera: " + std::to_string(n) + " distortion coefficients; OpenCV takes 4, 5, 8, 12 or 14");
}

Eigen::Matrix4f gl_projection(const cv::Matx33d& K, int canvas_width, int canvas_height, const cv::Point2d& offset_px,
                              double near_mm, double far_mm) {
  const double W = canvas_width, H = canvas_height;
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  // x_ndc = 2 (fx x/z + s y/z + cx + 0.5 + ox) / W - 1, same for y (no flip: see header).
  P(0, 0) = 2.0 * K(0, 0) / W;
  P(0, 1) = 2.0 * K(0, 1) / W;
  P(0, 2) = 2.0 * (K(0, 2) + 0.5 + offset_px.x) / W - 1.0;
  P(1, 1) = 2.0 * K(1, 1) / H;
  P(1, 2) = 2.0 * (K(1, 2) + 0.5 + offset_px.y) / H - 1.0;
  P(2, 2) = (far_mm + near_mm) / (far_mm - near_mm);
  P(2, 3) = -2.0 * far_mm * near_mm / (far_mm - near_mm);
  P(3, 2) = 1.0;
  return P.cast<float>();
}

DistortionWarp DistortionWarp::make(const OverlayCamera& camera, double max_canvas_scale) {
  validate(camera);
  DistortionWarp warp;
  bool any = false;
  for (double d : camera.distortion) any = any || d != 0.0;
  if (!any) {
    warp.canvas_width = camera.width;
    warp.canvas_height = camera.height;
    return warp;
  }
  warp.identity = false;
  // Output pixel -> ideal (pinhole, same K) pixel, for every pixel of the image.
  std::vector<cv::Point2f> px;
  px.reserve(static_cast<std::size_t>(camera.width) * camera.height);
  for (int v = 0; v < camera.height; ++v)
    for (int u = 0; u < camera.width; ++u) px.emplace_back(static_cast<float>(u), static_cast<float>(v));
  std::vector<cv::Point2f> ideal;
  cv::undistortPoints(px, ideal, cv::Mat(camera.K), cv::Mat(camera.distortion), cv::noArray(), cv::Mat(camera.K),
                      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 1e-6));
  double min_u = 0, min_v = 0, max_u = camera.width - 1.0, max_v = camera.height - 1.0;
  for (const auto& p : ideal) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) continue;
    min_u = std::min(min_u, static_cast<double>(p.x));
    min_v = std::min(min_v, static_cast<double>(p.y));
    max_u = std::max(max_u, static_cast<double>(p.x));
    max_v = std::max(max_v, static_cast<double>(p.y));
  }
  const double pad_x = (max_canvas_scale - 1.0) * camera.width / 2.0, pad_y = (max_canvas_scale - 1.0) * camera.height / 2.0;
  const double left = std::min(std::ceil(-min_u) + 2.0, pad_x), top = std::min(std::ceil(-min_v) + 2.0, pad_y);
  const double right = std::min(std::ceil(max_u - (camera.width - 1)) + 2.0, pad_x);
  const double bottom = std::min(std::ceil(max_v - (camera.height - 1)) + 2.0, pad_y);
  warp.offset_px = {left, top};
  warp.canvas_width = camera.width + static_cast<int>(left + right);
  warp.canvas_height = camera.height + static_cast<int>(top + bottom);
  cv::Mat map_x(camera.height, camera.width, CV_32F), map_y(camera.height, camera.width, CV_32F);
  for (int v = 0; v < camera.height; ++v) {
    auto* mx = map_x.ptr<float>(v);
    auto* my = map_y.ptr<float>(v);
    for (int u = 0; u < camera.width; ++u) {
      const auto& p = ideal[static_cast<std::size_t>(v) * camera.width + u];
      const bool ok = std::isfinite(p.x) && std::isfinite(p.y);
      mx[u] = ok ? p.x + static_cast<float>(left) : -1e4f;
      my[u] = ok ? p.y + static_cast<float>(top) : -1e4f;
    }
  }
  cv::convertMaps(map_x, map_y, warp.map1, warp.map2, CV_16SC2);
  return warp;
}

cv::Mat DistortionWarp::apply(const cv::Mat& canvas) const {
  if (identity) return canvas;
  cv::Mat out;
  cv::remap(canvas, out, map1, map2, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return out;
}

}  // namespace arnav::host::overlay
