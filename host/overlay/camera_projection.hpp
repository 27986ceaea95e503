#pragma once
// The calibrated camera as the overlay renders it. Frame Cam is OpenCV's (x right, y down,
// z forward, origin at the optical centre); pixels follow OpenCV (pixel (0,0)'s centre at
// integer coordinates (0,0)). Units: px, mm.
//
// OpenGL renders a pinhole image; the lens distortion is applied afterwards by a warp:
// every output (distorted) pixel looks up the pinhole pixel its ray hits. A barrel lens
// sees more than the pinhole image of the same K, so the pinhole image is rendered on an
// enlarged "canvas" (principal point shifted by `offset_px`) that holds every ray of the
// output image.
#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <vector>

namespace arnav::host::overlay {

struct OverlayCamera {
  int width = 0;   // px, of the image the overlay is drawn on
  int height = 0;
  cv::Matx33d K = cv::Matx33d::eye();  // [fx 0 cx; 0 fy cy; 0 0 1], px
  std::vector<double> distortion;      // OpenCV order k1 k2 p1 p2 [k3 ...]; empty: none

  // The same camera for an image scaled to width x height (e.g. a downscaled JPEG).
  OverlayCamera scaled_to(int new_width, int new_height) const;
};

// Throws OverlayError for a non-positive size or focal length or a coefficient count
// OpenCV does not know (4, 5, 8, 12, 14).
void validate(const OverlayCamera& camera);

// OpenGL projection (column-major 4x4, as glUniformMatrix4fv wants it) for points in Cam.
// Window x = u + 0.5 + offset_x, window y = v + 0.5 + offset_y (OpenGL pixel centres are at
// +0.5; rows are read back bottom-up, so row r of the read-back image is pixel row v = r:
// no flip). Depth from near_mm to far_mm along z.
Eigen::Matrix4f gl_projection(const cv::Matx33d& K, int canvas_width, int canvas_height, const cv::Point2d& offset_px,
                              double near_mm, double far_mm);

// The distortion warp of a camera: canvas size and principal-point offset, and the
// remap tables (output pixel -> canvas pixel), fixed-point for cv::remap's fast path.
struct DistortionWarp {
  bool identity = true;    // no distortion: the canvas is the image
  int canvas_width = 0;
  int canvas_height = 0;
  cv::Point2d offset_px{0, 0};
  cv::Mat map1, map2;      // cv::convertMaps(CV_16SC2) output

  // Computes the tables (about 0.2 s at 1280x720). max_canvas_scale caps the canvas at
  // that multiple of the image size (a strong barrel lens sends corner rays far out).
  static DistortionWarp make(const OverlayCamera& camera, double max_canvas_scale = 2.0);
  // Applies the warp to a canvas image (any type); identity returns the input.
  cv::Mat apply(const cv::Mat& canvas) const;
};

}  // namespace arnav::host::overlay
