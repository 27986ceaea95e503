#include "calibration/vision/target_detection.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "appliance/markers/tag_detector.hpp"
#include "calibration/lib/calib_error.hpp"

namespace arnav::calib {
namespace {

BoardObservation detect_chessboard(const cv::Mat& gray, const BoardLayout& layout) {
  BoardObservation obs;
  const auto& c = *layout.chessboard;
  const cv::Size pattern(c.inner_corners_cols, c.inner_corners_rows);
  std::vector<cv::Point2f> corners;
  const bool found = cv::findChessboardCorners(
      gray, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
  if (!found) {
    obs.reason = "chessboard " + std::to_string(c.inner_corners_cols) + "x" +
                 std::to_string(c.inner_corners_rows) + " inner corners not found";
    return obs;
  }
  cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 50, 1e-3));
  obs.found = true;
  obs.image_px = corners;
  for (const auto& p : layout.chessboard_corners_mm()) {
    obs.board_mm.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
  }
  return obs;
}

BoardObservation detect_tags(const cv::Mat& gray, const BoardLayout& layout, const DetectionOptions& opt) {
  BoardObservation obs;
  // The appliance's detector (appliance/markers), at full resolution for calibration.
  markers::DetectorSettings settings;
  settings.family = layout.tag_family;
  settings.decimate = opt.quad_decimate;
  settings.max_bits_corrected = 0;  // a corrected bit on a calibration board is more likely a false positive
  markers::TagDetector detector(settings);
  int unknown = 0;
  for (const auto& d : detector.detect(gray)) {
    if (d.hamming > 0) continue;
    const BoardTag* tag = layout.find_tag(d.id);
    if (!tag) {
      ++unknown;
      continue;
    }
    obs.tag_ids.push_back(d.id);
    for (std::size_t k = 0; k < 4; ++k) {
      obs.image_px.emplace_back(static_cast<float>(d.corners_px[k].x), static_cast<float>(d.corners_px[k].y));
      const Eigen::Vector3d& p = tag->p_BoardCorner_mm[k];
      obs.board_mm.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
    }
  }
  if (static_cast<int>(obs.tag_ids.size()) < opt.min_tags) {
    obs.reason = std::to_string(obs.tag_ids.size()) + " tags of board '" + layout.name + "' found (" +
                 std::to_string(opt.min_tags) + " needed)";
    if (unknown > 0) obs.reason += "; " + std::to_string(unknown) + " tags with ids not on this board";
    obs.image_px.clear();
    obs.board_mm.clear();
    return obs;
  }
  obs.found = true;
  return obs;
}

}  // namespace

BoardObservation detect_board(const cv::Mat& gray, const BoardLayout& layout, const DetectionOptions& opt) {
  if (gray.empty() || gray.type() != CV_8UC1) {
    BoardObservation obs;
    obs.reason = "image is empty or not 8-bit gray";
    return obs;
  }
  if (layout.type == BoardType::Chessboard) return detect_chessboard(gray, layout);
  return detect_tags(gray, layout, opt);
}

}  // namespace arnav::calib
