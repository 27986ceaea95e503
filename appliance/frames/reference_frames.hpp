#pragma once
// One reference frame for every published pose. The calibration files say how the camera
// and the tracker sit relative to each other (hand-eye X_CamNdi or X_NdiCam, camera and
// tracker fixed to each other); the configuration picks the frame poses are expressed in:
//
//   Cam  camera poses X_CamBoard as measured; NDI poses X_CamTool = X_CamNdi X_NdiTool
//        (NDI poses stay X_NdiTool when there is no hand-eye file)
//   Ndi  X_NdiBoard = X_NdiCam X_CamBoard; NDI poses as measured
//   Ref  a reference NDI tool (patient/organ marker) defines frame Ref:
//        X_RefTool = X_NdiRef^-1 X_NdiTool, X_RefBoard = X_NdiRef^-1 X_NdiCam X_CamBoard
//
// For Ref the reference tool's poses arrive from the NDI path (update_reference); a camera
// frame uses the sample closest in time to its capture time, and is refused (with the
// reason) when none is within max_reference_age_s. Thread-safe: the NDI thread updates,
// the camera thread converts. Units: mm, monotonic microseconds.
#include <Eigen/Geometry>

#include <cstdint>
#include <deque>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "appliance/frames/pi_mutex.hpp"

namespace arnav::frames {

enum class Reference { Cam, Ndi, Ref };

struct FramesConfig {
  Reference reference = Reference::Cam;
  std::string reference_tool;            // NDI tool name that defines Ref
  std::filesystem::path hand_eye;        // X_CamNdi.yaml or X_NdiCam.yaml; empty: none
  double max_reference_age_s = 0.05;
};

struct Converted {
  std::optional<Eigen::Isometry3d> X_ParentChild;
  std::string frame_parent;  // "Cam", "Ndi" or "Ref"
  std::string reason;        // why X_ParentChild is empty
};

class ReferenceFrames {
 public:
  // X_NdiCam: the hand-eye result, if any (without it, camera poses can only be given in
  // Cam: camera_pose() refuses Ndi/Ref with the reason). Throws std::invalid_argument for
  // Ref without a reference tool.
  ReferenceFrames(Reference reference, std::optional<Eigen::Isometry3d> X_NdiCam, std::string reference_tool,
                  double max_reference_age_s);
  // Loads the hand-eye file (its name must be X_CamNdi or X_NdiCam); errors name the file.
  static std::shared_ptr<ReferenceFrames> load(const FramesConfig& config);

  Reference reference() const { return reference_; }
  const std::string& reference_tool() const { return reference_tool_; }
  bool has_hand_eye() const { return X_NdiCam_.has_value(); }

  // NDI path: the reference tool's pose of a frame (or that it was missing).
  void update_reference(const Eigen::Isometry3d& X_NdiRef, std::int64_t time_us);
  void reference_missing(std::int64_t time_us);

  Converted camera_pose(const Eigen::Isometry3d& X_CamBoard, std::int64_t capture_time_us) const;
  Converted ndi_pose(const Eigen::Isometry3d& X_NdiTool, std::int64_t time_us) const;

 private:
  std::optional<Eigen::Isometry3d> reference_at(std::int64_t time_us, std::string* reason) const;

  Reference reference_;
  std::optional<Eigen::Isometry3d> X_NdiCam_;
  std::string reference_tool_;
  std::int64_t max_age_us_;
  mutable PiMutex mutex_;  // the NDI thread may be real-time, the camera thread is not
  struct Sample {
    std::int64_t time_us;
    std::optional<Eigen::Isometry3d> X_NdiRef;  // empty: the tool was not seen
  };
  std::deque<Sample> history_;
};

const char* to_string(Reference reference);
// "Cam", "Ndi", "Ref"; throws std::invalid_argument listing them for anything else.
Reference parse_reference(const std::string& name);

}  // namespace arnav::frames
