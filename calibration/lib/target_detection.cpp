#include "calibration/lib/target_detection.hpp"

#include <memory>

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

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

struct FamilyDeleter {
  void (*destroy)(apriltag_family_t*);
  void operator()(apriltag_family_t* f) const { destroy(f); }
};

std::unique_ptr<apriltag_family_t, FamilyDeleter> make_family(const std::string& name) {
  if (name == "tag36h11") return {tag36h11_create(), FamilyDeleter{tag36h11_destroy}};
  if (name == "tag25h9") return {tag25h9_create(), FamilyDeleter{tag25h9_destroy}};
  if (name == "tag16h5") return {tag16h5_create(), FamilyDeleter{tag16h5_destroy}};
  throw CalibError("tag family '" + name + "' is not supported (tag36h11, tag25h9, tag16h5)");
}

BoardObservation detect_tags(const cv::Mat& gray, const BoardLayout& layout, const DetectionOptions& opt) {
  BoardObservation obs;
  auto family = make_family(layout.tag_family);
  apriltag_detector_t* td = apriltag_detector_create();
  apriltag_detector_add_family(td, family.get());
  td->nthreads = 1;
  td->quad_decimate = opt.quad_decimate;
  td->refine_edges = true;
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step), const_cast<uint8_t*>(gray.ptr<uint8_t>())};
  zarray_t* dets = apriltag_detector_detect(td, &im);
  int unknown = 0;
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    // Hamming > 0 on a calibration board is more likely a false positive than a tag.
    if (d->hamming > 0) continue;
    const BoardTag* tag = layout.find_tag(d->id);
    if (!tag) {
      ++unknown;
      continue;
    }
    obs.tag_ids.push_back(d->id);
    for (int k = 0; k < 4; ++k) {
      // AprilTag puts pixel centres at +0.5; OpenCV at integers.
      obs.image_px.emplace_back(static_cast<float>(d->p[k][0] - 0.5), static_cast<float>(d->p[k][1] - 0.5));
      const Eigen::Vector3d& p = tag->p_BoardCorner_mm[static_cast<std::size_t>(k)];
      obs.board_mm.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()));
    }
  }
  apriltag_detections_destroy(dets);
  apriltag_detector_destroy(td);
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
