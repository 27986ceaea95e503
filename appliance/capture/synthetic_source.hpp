#pragma once
// The synthetic camera of the bench as a capture source (config `camera: {source:
// synthetic}`): boards move along scripted trajectories and are rendered through the
// calibrated (or a generated) camera model by appliance/synthetic_camera. Frame k shows the
// scene at t = k / fps. Ground truth (X_CamBoard per frame and board) is written to a CSV
// beside the frames, and the frames themselves optionally as PNG files.
//
// Real-time mode behaves like a real camera (docs/camera.md, "Timestamps"): frame k is
// exposed at start + k / fps (its capture_time_mono_us, the world time of the scene it
// shows) and delivered at its exposure plus a modelled sensor readout (one frame period by
// default, readout_s). A rendering thread renders ahead (up to render_ahead_frames, the
// phantom is a recording, so the scene is known in advance), so the bench's own rendering
// cost is not the product's latency; a frame rendered after its readout end is delivered
// when it is ready and that lateness is measured (bench_late). A frame not taken before the
// next one is read out (its reader or its renderer late) is dropped and counted by cause,
// never silently skipped (counters(), timing_csv). A scheduled outage makes the camera
// "unplugged" for a while (read reports Lost, open fails) to exercise reconnection.
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
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
  // Real time only: sensor readout after the exposure, s (< 0: one frame period).
  double readout_s = -1.0;
  int render_ahead_frames = 2;                // frames rendered ahead of the reader (>= 1)
  int render_nice = 0;                        // the rendering thread's nice value (10: the product first)
  // Per frame: exposure, rendering, readout end, delivery and what became of it (empty: not
  // written). Columns: see kTimingCsvHeader.
  std::filesystem::path timing_csv;
};

// The timing CSV's header; status: delivered, dropped_render_late (rendered after the next
// frame's readout end), dropped_reader_late (ready in time, not taken before the next frame
// replaced it), absent (the camera was unplugged). -1: no such instant.
inline constexpr const char* kTimingCsvHeader =
    "sequence,exposure_mono_us,render_start_mono_us,render_done_mono_us,readout_end_mono_us,delivered_mono_us,"
    "handed_mono_us,status";

// What became of the frames of a real-time synthetic camera so far.
struct SyntheticCounters {
  std::int64_t delivered = 0;
  std::int64_t dropped_render_late = 0;   // the bench's renderer could not keep up
  std::int64_t dropped_reader_late = 0;   // the consumer (the appliance) could not keep up
  std::int64_t absent = 0;                // exposed while the camera was unplugged
  std::int64_t delivered_late = 0;        // delivered after their readout end (rendering late)
  std::int64_t reexposed = 0;             // a static scene's radiance re-exposed instead of rendered
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
  SyntheticCounters counters() const;
  double readout_us() const;

 private:
  // One rendered frame with what its ground truth needs.
  struct Rendered {
    std::int64_t sequence = 0;
    std::int64_t exposure_us = 0, render_start_us = -1, render_done_us = -1;
    cv::Mat image;
    std::vector<camera_sim::TagTruth> tags;
    std::vector<Eigen::Isometry3d> X_CamBoards;
    std::vector<Eigen::Vector3d> targets_Cam_mm;
  };
  bool in_outage(std::int64_t now_us) const;
  std::int64_t exposure_us(std::int64_t sequence) const;
  std::int64_t readout_end_us(std::int64_t sequence) const;
  Rendered render(std::int64_t sequence, std::int64_t exposure_us);
  void render_loop();
  void stop_renderer();
  void note(const Rendered& f, std::int64_t readout_end, std::int64_t delivered, std::int64_t handed, const char* status);
  void note_absent(std::int64_t sequence);
  ReadResult deliver(Rendered f, Frame& frame, std::int64_t delivered_us);

  SyntheticSettings settings_;
  std::unique_ptr<camera_sim::SyntheticRenderer> renderer_;
  std::unique_ptr<camera_sim::GroundTruthWriter> truth_;
  std::vector<Eigen::Vector2d> centres_;
  std::int64_t start_us_ = -1;   // time of frame 0 (kept across reopen: the scene goes on)
  std::int64_t next_ = 0;        // next frame index to hand out (or drop)
  bool open_ = false;
  bool opened_before_ = false;
  bool outage_reported_ = false;

  // Real time: the rendering thread and its queue (rendered, not yet handed out).
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Rendered> ready_;
  std::int64_t next_render_ = 0;
  bool render_stop_ = false;
  bool render_ended_ = false;    // frame_count reached
  std::string render_error_;
  std::thread render_thread_;
  mutable std::mutex stats_mutex_;
  SyntheticCounters counters_;
  std::ofstream timing_;
  // The last scene rendered (board poses, organ vertices) and its radiance before noise: a
  // frame of the same scene is only re-exposed (bit-identical to a full render).
  struct SceneCache {
    std::vector<Eigen::Matrix4d> X_CamBoards;
    Eigen::Matrix3Xd organ_Cam_mm;
    cv::Mat radiance;
    std::vector<camera_sim::TagTruth> tags;
  };
  std::optional<SceneCache> scene_cache_;
};

}  // namespace arnav::capture
