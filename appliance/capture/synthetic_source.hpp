#pragma once
// The synthetic camera of the bench as a capture source (config `camera: {source:
// synthetic}`): boards move along scripted trajectories and are rendered through the
// calibrated (or a generated) camera model by appliance/synthetic_camera. Frame k shows the
// scene at t = k / fps. Ground truth (X_CamBoard per frame and board) is written to a CSV
// beside the frames, and the frames themselves optionally as PNG files.
//
// Real-time mode paces frames on the monotonic clock like a camera; a consumer that
// falls more than one frame behind loses frames (sequence numbers jump), as with a
// driver's overwritten buffers. A scheduled outage makes the camera "unplugged" for a
// while (read reports Lost, open fails) to exercise reconnection.
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "appliance/capture/frame_source.hpp"
#include "appliance/markers/camera_model.hpp"
#include "appliance/markers/tag_board.hpp"
#include "appliance/synthetic_camera/ground_truth.hpp"
#include "appliance/synthetic_camera/phantom_recording.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"
#include "appliance/synthetic_camera/trajectory.hpp"

namespace arnav::capture {

struct SyntheticBoard {
  markers::TagBoard board;
  camera_sim::Trajectory trajectory;
};

// A deforming organ phantom (phantom_recording.hpp) fixed to one of the boards: frame k
// shows the recording at t = start_s + k / fps (held at its last frame after its end),
// posed X_CamModel = X_CamBoard * X_BoardModel. The ground truth (version 2) then also
// holds the deformed targets (first: the tumour centroid) in Cam, mm and px.
struct SyntheticPhantom {
  std::shared_ptr<const camera_sim::PhantomRecording> recording;
  std::size_t board_index = 0;
  Eigen::Isometry3d X_BoardModel = Eigen::Isometry3d::Identity();  // the host's X_RefModel
  double reflectance = 0.6;
  double start_s = 0.0;
  // The bench's world clock (CLOCK_MONOTONIC, us): when set, the camera's frames count from
  // it (frame k captured at epoch + k / fps, the outage timed from it too) and a frame shows
  // the recording at t = start_s + (its capture time - epoch), the clock the simulated
  // Polaris moves the phantom's tool on when its scenario names the same epoch
  // (docs/hil.md): the tool and the filmed tissue agree however late each device starts.
  std::optional<std::int64_t> epoch_mono_us;
};

struct SyntheticSettings {
  markers::CameraModel camera;
  std::vector<SyntheticBoard> boards;
  camera_sim::RenderOptions render;
  double fps = 30.0;
  bool realtime = true;
  std::int64_t frame_count = 0;               // 0: endless
  std::filesystem::path ground_truth_csv;     // empty: not written
  std::filesystem::path frames_dir;           // empty: frames not written
  double outage_at_s = -1.0;                  // < 0: no outage
  double outage_duration_s = 0.0;
  std::optional<SyntheticPhantom> phantom;    // none: boards only
};

class SyntheticSource : public FrameSource {
 public:
  explicit SyntheticSource(SyntheticSettings settings);
  ~SyntheticSource() override;
  void open() override;
  void close() override;
  ReadResult read(Frame& frame) override;
  std::string describe() const override;
  double nominal_fps() const override { return settings_.fps; }

  // Ground truth of frame `sequence` (available without rendering).
  Eigen::Isometry3d X_CamBoard(size_t board_index, std::int64_t sequence) const;
  const SyntheticSettings& settings() const { return settings_; }

 private:
  bool in_outage(std::int64_t now_us) const;

  SyntheticSettings settings_;
  std::unique_ptr<camera_sim::SyntheticRenderer> renderer_;
  std::unique_ptr<camera_sim::GroundTruthWriter> truth_;
  std::vector<Eigen::Vector2d> centres_;
  std::int64_t start_us_ = -1;   // time of frame 0 (kept across reopen: the scene goes on)
  std::int64_t next_ = 0;        // next frame index
  bool open_ = false;
  bool outage_reported_ = false;
};

}  // namespace arnav::capture
