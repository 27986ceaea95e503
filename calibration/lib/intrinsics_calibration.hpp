#pragma once
// Camera intrinsics from views of a known board (chessboard or AprilTag grid):
// cv::calibrateCamera, per-view reprojection error, outlier views rejected with the
// reason, coverage of the image by the detected corners.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/solver_summary.hpp"

namespace arnav::calib {

struct CalibrationView {
  std::string name;                   // file name or "frame 12"
  std::vector<cv::Point2f> image_px;
  std::vector<cv::Point3f> board_mm;
};

struct IntrinsicsOptions {
  int min_views = 5;
  int min_points_per_view = 8;
  // A view is an outlier when its RMS exceeds max(outlier_factor * median view RMS,
  // outlier_min_px): blur, a mis-detection or a moving board.
  double outlier_factor = 3.0;
  double outlier_min_px = 1.0;
  bool fix_k3 = false;                // fewer, flatter views: k3 is poorly determined
  int coverage_cols = 8;              // coverage grid over the image
  int coverage_rows = 6;
};

struct ViewReport {
  std::string name;
  bool used = false;
  std::string reason;                 // why rejected (empty when used)
  double rms_px = 0.0;                // with the final intrinsics (0 when never solved)
  int points = 0;
};

struct IntrinsicsResult {
  CameraIntrinsics intrinsics;
  std::vector<ViewReport> views;      // every input view, used or not
  std::vector<cv::Mat> rvecs, tvecs;  // X_CamBoard of the used views (Rodrigues, mm)
  double coverage = 0.0;              // fraction of grid cells holding a corner
  cv::Mat coverage_cells;             // coverage_rows x coverage_cols CV_32S corner counts
  SolverSummary summary;
};

// Throws DegenerateInput when fewer than min_views usable views remain (the message
// lists the rejected ones with their reasons).
IntrinsicsResult calibrate_intrinsics(const std::vector<CalibrationView>& views, cv::Size image_size,
                                      const IntrinsicsOptions& options = {});

}  // namespace arnav::calib
