#pragma once
// What arnav-appliance needs to run the camera path when its configuration has a
// `camera:` section: load (configuration + intrinsics, boards, hand-eye: exit 2 on any
// error) and then start the pipeline on its own thread. The NDI path feeds the reference
// tool's poses into frames() so that camera poses can be expressed in Ref.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "appliance/frames/reference_frames.hpp"
#include "appliance/camera/camera_config.hpp"
#include "appliance/camera/camera_pipeline.hpp"

namespace arnav::camera {

class CameraRuntime {
 public:
  // nullptr when the configuration has no `camera:`; throws CameraConfigError (message
  // "<file>:<line>: key ...: ...") for a bad section or a bad calibration/board file.
  static std::unique_ptr<CameraRuntime> load(const std::filesystem::path& config_file);
  // Only the `frames:` section (the NDI path uses it without a camera); same errors.
  static std::shared_ptr<frames::ReferenceFrames> load_frames(const std::filesystem::path& config_file);

  const CameraConfig& config() const { return config_; }
  const std::shared_ptr<frames::ReferenceFrames>& frames() const { return frames_; }
  std::string summary() const;  // one line for --check and the log

  // Opens LCM and the source, starts the thread. Throws CameraConfigError.
  void start(const std::string& lcm_url, const seal::BusSecurity& security);
  void stop();
  // A finite source (file, folder, synthetic with a frame count) has ended.
  bool finished() const { return pipeline_ && pipeline_->finished(); }

 private:
  CameraRuntime(CameraConfig config, std::shared_ptr<frames::ReferenceFrames> frames);
  CameraConfig config_;
  std::shared_ptr<frames::ReferenceFrames> frames_;
  std::unique_ptr<CameraPipeline> pipeline_;
};

}  // namespace arnav::camera
