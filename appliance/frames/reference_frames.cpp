#include "appliance/frames/reference_frames.hpp"

#include <cstdlib>
#include <stdexcept>

#include "calibration/lib/calib_error.hpp"
#include "calibration/lib/rigid_transform_file.hpp"

namespace arnav::frames {
namespace {
constexpr size_t kHistory = 256;  // ~1 s of NDI frames at 250 Hz
}

const char* to_string(Reference r) {
  switch (r) {
    case Reference::Cam: return "Cam";
    case Reference::Ndi: return "Ndi";
    case Reference::Ref: return "Ref";
  }
  return "?";
}

Reference parse_reference(const std::string& name) {
  if (name == "Cam") return Reference::Cam;
  if (name == "Ndi") return Reference::Ndi;
  if (name == "Ref") return Reference::Ref;
  throw std::invalid_argument("reference frame '" + name + "' is not one of Cam, Ndi, Ref");
}

ReferenceFrames::ReferenceFrames(Reference reference, std::optional<Eigen::Isometry3d> X_NdiCam,
                                 std::string reference_tool, double max_reference_age_s)
    : reference_(reference),
      X_NdiCam_(std::move(X_NdiCam)),
      reference_tool_(std::move(reference_tool)),
      max_age_us_(static_cast<std::int64_t>(max_reference_age_s * 1e6)) {
  if (reference_ == Reference::Ref && reference_tool_.empty()) {
    throw std::invalid_argument("reference frame Ref needs frames.reference_tool: the NDI tool on the patient/organ");
  }
  if (!(max_reference_age_s > 0.0)) throw std::invalid_argument("frames.max_reference_age_s must be > 0");
}

std::shared_ptr<ReferenceFrames> ReferenceFrames::load(const FramesConfig& config) {
  std::optional<Eigen::Isometry3d> X_NdiCam;
  if (!config.hand_eye.empty()) {
    calib::RigidTransformRecord rec;
    try {
      rec = calib::read_transform(config.hand_eye);
    } catch (const calib::CalibError& e) {
      throw std::invalid_argument(e.what());
    }
    if (rec.name() == "X_NdiCam") {
      X_NdiCam = rec.X_ParentChild;
    } else if (rec.name() == "X_CamNdi") {
      X_NdiCam = rec.X_ParentChild.inverse();
    } else {
      throw std::invalid_argument(config.hand_eye.string() + ": holds " + rec.name() +
                                  ", expected the hand-eye X_CamNdi or X_NdiCam");
    }
  }
  return std::make_shared<ReferenceFrames>(config.reference, X_NdiCam, config.reference_tool, config.max_reference_age_s);
}

void ReferenceFrames::update_reference(const Eigen::Isometry3d& X_NdiRef, std::int64_t time_us) {
  std::lock_guard lock(mutex_);
  history_.push_back({time_us, X_NdiRef});
  if (history_.size() > kHistory) history_.pop_front();
}

void ReferenceFrames::reference_missing(std::int64_t time_us) {
  std::lock_guard lock(mutex_);
  history_.push_back({time_us, std::nullopt});
  if (history_.size() > kHistory) history_.pop_front();
}

std::optional<Eigen::Isometry3d> ReferenceFrames::reference_at(std::int64_t time_us, std::string* reason) const {
  std::lock_guard lock(mutex_);
  const Sample* best = nullptr;
  for (const auto& s : history_) {
    if (best == nullptr || std::llabs(s.time_us - time_us) < std::llabs(best->time_us - time_us)) best = &s;
  }
  if (best == nullptr) {
    *reason = "reference tool '" + reference_tool_ + "' not seen yet";
    return std::nullopt;
  }
  const std::int64_t dt = std::llabs(best->time_us - time_us);
  if (dt > max_age_us_) {
    *reason = "reference tool '" + reference_tool_ + "': closest pose is " + std::to_string(dt / 1000) +
              " ms from the frame (limit " + std::to_string(max_age_us_ / 1000) + " ms)";
    return std::nullopt;
  }
  if (!best->X_NdiRef) {
    *reason = "reference tool '" + reference_tool_ + "' not visible to the tracker";
    return std::nullopt;
  }
  return best->X_NdiRef;
}

Converted ReferenceFrames::camera_pose(const Eigen::Isometry3d& X_CamBoard, std::int64_t capture_time_us) const {
  Converted out;
  out.frame_parent = to_string(reference_);
  if (reference_ != Reference::Cam && !X_NdiCam_) {
    out.reason = std::string("no hand-eye calibration: camera poses cannot be expressed in ") + to_string(reference_) +
                 " (frames.hand_eye: X_CamNdi.yaml from `arnav-calib handeye`)";
    return out;
  }
  switch (reference_) {
    case Reference::Cam:
      out.X_ParentChild = X_CamBoard;
      break;
    case Reference::Ndi:
      out.X_ParentChild = *X_NdiCam_ * X_CamBoard;
      break;
    case Reference::Ref: {
      const auto X_NdiRef = reference_at(capture_time_us, &out.reason);
      if (X_NdiRef) out.X_ParentChild = X_NdiRef->inverse() * *X_NdiCam_ * X_CamBoard;
      break;
    }
  }
  return out;
}

Converted ReferenceFrames::ndi_pose(const Eigen::Isometry3d& X_NdiTool, std::int64_t time_us) const {
  Converted out;
  switch (reference_) {
    case Reference::Cam:
      if (X_NdiCam_) {
        out.frame_parent = "Cam";
        out.X_ParentChild = X_NdiCam_->inverse() * X_NdiTool;
      } else {
        out.frame_parent = "Ndi";  // nothing relates the tracker to the camera
        out.X_ParentChild = X_NdiTool;
      }
      break;
    case Reference::Ndi:
      out.frame_parent = "Ndi";
      out.X_ParentChild = X_NdiTool;
      break;
    case Reference::Ref: {
      out.frame_parent = "Ref";
      const auto X_NdiRef = reference_at(time_us, &out.reason);
      if (X_NdiRef) out.X_ParentChild = X_NdiRef->inverse() * X_NdiTool;
      break;
    }
  }
  return out;
}

}  // namespace arnav::frames
