#pragma once
// LCM channel names. One channel per tool and per device so that subscribers can pick
// with a regex (e.g. "ARNAV_POSE_.*"). Documented in docs/protocol.md.
#include <string>
#include <string_view>

namespace arnav::channels {

inline constexpr std::string_view kPosePrefix = "ARNAV_POSE_";      // + tool name
inline constexpr std::string_view kHealthPrefix = "ARNAV_HEALTH_";  // + device ("ndi", "camera")
inline constexpr std::string_view kEvents = "ARNAV_EVENT";
inline constexpr std::string_view kFramePrefix = "ARNAV_FRAME_";    // + camera name
inline constexpr std::string_view kInput = "ARNAV_INPUT";           // input_event_t (CAN pedal, buttons)
inline constexpr std::string_view kCloudPrefix = "ARNAV_CLOUD_";    // + source ("pointer", ...)
inline constexpr std::string_view kInputState = "ARNAV_INPUT_STATE"; // input_event_t snapshots
inline constexpr std::string_view kSurfacePrefix = "ARNAV_SURFACE_"; // + surface ("organ", "tumour", "cut"), surface_mesh_t
inline constexpr std::string_view kPoseRegex = "ARNAV_POSE_.*";
inline constexpr std::string_view kHealthRegex = "ARNAV_HEALTH_.*";

inline std::string pose(std::string_view tool_name) { return std::string(kPosePrefix) + std::string(tool_name); }
inline std::string health(std::string_view device) { return std::string(kHealthPrefix) + std::string(device); }
inline std::string cloud(std::string_view source) { return std::string(kCloudPrefix) + std::string(source); }
inline std::string frame(std::string_view camera) { return std::string(kFramePrefix) + std::string(camera); }
inline std::string surface(std::string_view name) { return std::string(kSurfacePrefix) + std::string(name); }

}  // namespace arnav::channels
