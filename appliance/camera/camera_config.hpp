#pragma once
// The `camera:` and `frames:` sections of the appliance configuration (YAML; documented
// in docs/camera.md). Every problem is "<file>:<line>: key 'camera.<key>': <what is wrong>";
// unknown keys are errors (a typo must not silently fall back to a default).
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "appliance/capture/opencv_sources.hpp"
#include "appliance/capture/synthetic_source.hpp"
#include "appliance/frames/reference_frames.hpp"
#include "appliance/markers/board_pose.hpp"
#include "appliance/markers/board_tracker.hpp"
#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"
#include "appliance/markers/tag_detector.hpp"

namespace arnav::camera {

class CameraConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

enum class SourceKind { V4l2, File, Folder, Synthetic };

struct ToolConfig {
  markers::TagBoard board;  // board.name is the tool name (ARNAV_POSE_<name>)
  int tool_id = 0;          // published tool_id: the first tag id of the board
};

struct FramePublishConfig {
  bool enabled = false;
  int every = 1;            // publish every n-th frame
  int jpeg_quality = 80;
  int max_width = 1280;     // scaled down (keeping aspect) above this width
};

struct CameraConfig {
  std::string name = "cam0";          // ARNAV_FRAME_<name>; health is ARNAV_HEALTH_camera
  SourceKind source = SourceKind::V4l2;
  capture::V4l2Settings v4l2;
  std::filesystem::path path;         // file / folder
  bool realtime = true;               // file / folder pacing
  double folder_fps = 0.0;
  bool loop = false;
  double retry_interval_s = 1.0;
  std::optional<capture::SyntheticSettings> synthetic;
  markers::CameraModel camera;        // from camera.intrinsics (synthetic: may be generated)
  std::filesystem::path intrinsics_file;
  markers::DetectorSettings detector;
  markers::PoseSettings pose;
  markers::TrackerSettings tracker;
  std::vector<ToolConfig> tools;
  FramePublishConfig publish_frames;
  double health_rate_hz = 1.0;
  std::string source_file;            // the configuration file, for messages
};

// Reads `camera:` of the configuration text; nullopt when the key is absent. Relative
// paths (intrinsics, boards, video, folder, ground truth) are resolved against base_dir.
// Loads the intrinsics and board files (their errors name those files).
std::optional<CameraConfig> parse_camera_config(const std::string& yaml_text, const std::string& source,
                                                const std::filesystem::path& base_dir);
// Reads `frames:` (absent: reference Cam, no hand-eye).
frames::FramesConfig parse_frames_config(const std::string& yaml_text, const std::string& source,
                                         const std::filesystem::path& base_dir);

}  // namespace arnav::camera
