#include "appliance/markers/tag_detector.hpp"

#include <apriltag/apriltag.h>
#include <opencv2/imgproc.hpp>

#include <stdexcept>

#include "appliance/markers/tag_family.hpp"

namespace arnav::markers {

void validate(const DetectorSettings& s) {
  TagFamily check(s.family);  // throws with the list of supported families
  if (!(s.decimate >= 1.0 && s.decimate <= 8.0)) {
    throw std::invalid_argument("detector: decimate " + std::to_string(s.decimate) + " outside 1..8");
  }
  if (s.threads < 1 || s.threads > 64) {
    throw std::invalid_argument("detector: threads " + std::to_string(s.threads) + " outside 1..64");
  }
  if (!(s.sigma >= 0.0 && s.sigma <= 10.0)) {
    throw std::invalid_argument("detector: sigma " + std::to_string(s.sigma) + " outside 0..10 px");
  }
  if (!(s.sharpening >= 0.0 && s.sharpening <= 10.0)) {
    throw std::invalid_argument("detector: sharpening " + std::to_string(s.sharpening) + " outside 0..10");
  }
  if (s.max_bits_corrected < 0 || s.max_bits_corrected > 2) {
    throw std::invalid_argument("detector: max_bits_corrected " + std::to_string(s.max_bits_corrected) +
                                " outside 0..2 (3 needs gigabytes of tables)");
  }
}

struct TagDetector::Impl {
  std::unique_ptr<TagFamily> family;
  apriltag_detector_t* td = nullptr;
  ~Impl() {
    if (td != nullptr) apriltag_detector_destroy(td);
  }
};

TagDetector::TagDetector(const DetectorSettings& settings) : settings_(settings), impl_(std::make_unique<Impl>()) {
  validate(settings_);
  impl_->family = std::make_unique<TagFamily>(settings_.family);
  impl_->td = apriltag_detector_create();
  apriltag_detector_add_family_bits(impl_->td, impl_->family->get(), settings_.max_bits_corrected);
  impl_->td->nthreads = settings_.threads;
  impl_->td->quad_decimate = static_cast<float>(settings_.decimate);
  impl_->td->quad_sigma = static_cast<float>(settings_.sigma);
  impl_->td->decode_sharpening = settings_.sharpening;
  impl_->td->refine_edges = settings_.refine_edges;
}

TagDetector::~TagDetector() = default;

std::vector<TagDetection> TagDetector::detect(const cv::Mat& image) {
  cv::Mat gray;
  if (image.type() == CV_8UC1) {
    gray = image;
  } else if (image.type() == CV_8UC3) {
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  } else {
    throw std::invalid_argument("tag detector: image type " + std::to_string(image.type()) +
                                " is neither 8-bit gray nor 8-bit BGR");
  }
  if (!gray.isContinuous()) gray = gray.clone();
  image_u8_t im{gray.cols, gray.rows, static_cast<int32_t>(gray.step), gray.data};
  zarray_t* dets = apriltag_detector_detect(impl_->td, &im);
  std::vector<TagDetection> out;
  out.reserve(static_cast<size_t>(zarray_size(dets)));
  for (int i = 0; i < zarray_size(dets); ++i) {
    apriltag_detection_t* d = nullptr;
    zarray_get(dets, i, &d);
    TagDetection det;
    det.id = d->id;
    det.hamming = d->hamming;
    det.decision_margin = static_cast<double>(d->decision_margin);
    for (size_t k = 0; k < 4; ++k) det.corners_px[k] = cv::Point2d(d->p[k][0] - 0.5, d->p[k][1] - 0.5);
    out.push_back(det);
  }
  apriltag_detections_destroy(dets);
  return out;
}

}  // namespace arnav::markers
