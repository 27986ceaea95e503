#pragma once
// Pointer swab (docs/register.md, docs/appliance.md): while a configured input (foot
// pedal, instrument button of the CAN path) is held - or always, when configured
// continuous - the tip of a tracked NDI tool is sampled once per device frame and
// published as arnav.point_cloud_t on ARNAV_CLOUD_<source>, in the frame the appliance
// publishes poses in (Ref, Cam or Ndi: appliance/frames). A sample closer than
// min_spacing_mm to the last one taken is skipped (a resting tip adds nothing); points
// go out in batches of points_per_message, and a release (or a change of frame, e.g. the
// reference tool hidden) sends what is pending at once. Units: mm, microseconds.
// Configuration section (read from the appliance's YAML, errors "<file>:<line>: key ..."):
//   swab:
//     tool: pointer              # an NDI tool under tools:
//     tip_mm: [0, 0, -160]       # tip in the tool frame (pivot calibration)
//     input: pedal_swab          # a CAN input under can.inputs (held while swabbing)
//     continuous: false          # true: sample whenever the tool is seen (no input)
//     min_spacing_mm: 1.0
//     points_per_message: 20
//     source: pointer            # channel ARNAV_CLOUD_pointer
#include <Eigen/Geometry>
#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "arnav/point_cloud_t.hpp"
#include "protocol/seal/sealed_lcm.hpp"

namespace arnav::app {

struct SwabConfig {
  std::string tool;
  Eigen::Vector3d tip_Tool_mm = Eigen::Vector3d::Zero();
  std::string input;                 // empty with continuous
  bool continuous = false;
  double min_spacing_mm = 1.0;
  int points_per_message = 20;
  std::string source = "pointer";
  std::string channel() const;
};

// Reads `swab:` from the configuration text (std::nullopt when absent). tool_names: the
// NDI tools configured; input_names: the CAN inputs configured. Throws ConfigError
// ("<file>:<line>: key 'swab.<key>': <what>").
std::optional<SwabConfig> parse_swab_config(const std::string& text, const std::string& source, const std::vector<std::string>& tool_names,
                                            const std::vector<std::string>& input_names);
// The same from the configuration file (as the camera and CAN sections load theirs).
std::optional<SwabConfig> load_swab_config(const std::string& path, const std::vector<std::string>& tool_names,
                                           const std::vector<std::string>& input_names);

class SwabSampler {
 public:
  SwabSampler(seal::SealedLcm& lcm, SwabConfig config);
  const SwabConfig& config() const { return config_; }

  // The swab input changed (any thread; the CAN thread calls it).
  void set_input(const std::string& input_name, bool pressed);
  bool active() const { return config_.continuous || pressed_.load(); }

  // One device frame (the NDI thread): the swab tool's pose in `frame` (X_FrameTool), or
  // nullopt when it was not seen. capture_wall_us: when the frame was measured.
  void on_frame(const std::optional<Eigen::Isometry3d>& X_FrameTool, const std::string& frame, std::int64_t capture_wall_us);
  // Publishes what is pending (also done on release and on a change of frame).
  void flush();

  std::int64_t points_published() const { return points_published_; }
  std::int64_t messages_published() const { return sequence_; }

 private:
  seal::SealedLcm& lcm_;
  SwabConfig config_;
  std::string channel_;
  std::atomic<bool> pressed_{false};
  std::atomic<bool> release_pending_{false};
  point_cloud_t msg_{};
  std::optional<Eigen::Vector3d> last_;
  std::int64_t sequence_ = 0;
  std::int64_t points_published_ = 0;
};

}  // namespace arnav::app
