#pragma once
// Finds a calibration board in an image and pairs image corners with board points:
// chessboards with cv::findChessboardCorners + cornerSubPix, AprilTag grids and marker
// boards with the appliance's AprilTag detector (appliance/markers TagDetector, ids
// matched against the layout). Pixels use OpenCV's convention (pixel centres at integer
// coordinates). Separate target (arnav_calibration_detect): appliance/markers links
// arnav_calibration for the file formats, so the core library cannot link it back.
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "calibration/lib/board_layout.hpp"

namespace arnav::calib {

struct BoardObservation {
  bool found = false;
  std::string reason;                     // why not found (for the report)
  std::vector<cv::Point2f> image_px;      // corners in the image
  std::vector<cv::Point3f> board_mm;      // the same corners in the Board frame
  std::vector<int> tag_ids;               // AprilTag boards: ids seen
};

struct DetectionOptions {
  int min_tags = 4;                 // AprilTag boards: fewer tags = not found
  double quad_decimate = 1.0;       // AprilTag decimation (1 = full resolution)
};

// gray: CV_8UC1. Never throws for a board that is not there: found = false + reason.
BoardObservation detect_board(const cv::Mat& gray, const BoardLayout& layout,
                              const DetectionOptions& options = {});

}  // namespace arnav::calib
