#pragma once
// AprilTag 3 detection with the settings of the config. Corners come back in OpenCV's
// pixel convention (pixel centres at integers; AprilTag's own output is offset by +0.5)
// and still distorted: undistort them with the calibrated intrinsics before any pose.
#include <opencv2/core.hpp>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace arnav::markers {

struct DetectorSettings {
  std::string family = "tag36h11";
  double decimate = 2.0;       // quad_decimate: >1 speeds up, corners refined at full resolution
  int threads = 1;
  double sigma = 0.0;          // quad_sigma: Gaussian blur before segmentation (noisy images: 0.8)
  double sharpening = 0.25;    // decode_sharpening
  bool refine_edges = true;
  int max_bits_corrected = 2;  // 0..2; more corrects more errors but raises false positives
};

// Throws std::invalid_argument naming the setting when a value is out of range.
void validate(const DetectorSettings& settings);

struct TagDetection {
  int id = 0;
  std::array<cv::Point2d, 4> corners_px{};  // distorted pixels, AprilTag corner order
  int hamming = 0;
  double decision_margin = 0.0;
};

class TagDetector {
 public:
  explicit TagDetector(const DetectorSettings& settings);
  ~TagDetector();
  TagDetector(const TagDetector&) = delete;
  TagDetector& operator=(const TagDetector&) = delete;

  const DetectorSettings& settings() const { return settings_; }
  // gray: CV_8UC1 (a 3-channel image is converted). Not thread-safe: one per thread.
  std::vector<TagDetection> detect(const cv::Mat& gray);

 private:
  struct Impl;
  DetectorSettings settings_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace arnav::markers
