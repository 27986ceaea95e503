#pragma once
// --record DIR of a navigation session: overlay.avi (OpenCV VideoWriter, MJPG), overlay.csv
// (one row per displayed frame) and contact_sheet.png (thumbnails every few seconds).
// Writing runs on its own thread so that encoding never delays the next overlay.
//
// overlay.csv columns:
//   camera_sequence, capture_time_mono_us, pose_time_mono_us (newest pose used),
//   model_step_time_mono_us (model state drawn), render_done_mono_us (overlay ready),
//   motion_to_photon_ms (exposure -> overlay ready; the name kept for old readers), tumour_u_px, tumour_v_px (projected tumour centroid, empty
//   when not drawn), blade_to_margin_mm (empty without a fresh scalpel), flags
//   ('|'-separated: reference_lost, reference_stale, scalpel_lost, scalpel_stale,
//   camera_pose_lost, camera_pose_stale, camera_gap, model_unhealthy, pose_not_matched,
//   input_stale, unregistered; empty when all is well),
//   then the cut columns (cutting sessions; empty otherwise): cutting (1 while the blade
//   cuts: cut_enable held or mode always, 0 otherwise), cut_faces (cut faces on the organ's
//   boundary, both sides), cut_area_mm2, cut_path_error_mm (largest distance of the points
//   the cut steps since the previous frame put on the cut from their swept blade surface;
//   empty when no step cut), cut_events (';'-separated kind:structure raised since the
//   previous frame: margin_entered, tumour_cut, vessel_crossed),
//   then tumour_x_cam_mm, tumour_y_cam_mm, tumour_z_cam_mm: the drawn tumour centroid in the
//   camera frame (the 3-D point tumour_u/v_px projects; empty when not drawn), for the
//   bench's 3-D AR error (hil_tests/scenarios/ar_error.hpp),
//   then the frame's instants (frame_latency.hpp): publish_time_mono_us (the appliance's),
//   receive_time_mono_us, decode_done_mono_us, shown_mono_us (buffer swap done, or handed
//   to the recorder).
// tumour_Cam.bin: the drawn first tumour's surface in the camera frame per frame it was
// drawn, for the bench's surface distance (format: tumour_surface_file.hpp).
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <fstream>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "host/app/session_config.hpp"
#include "host/mesh/tet_mesh.hpp"

namespace arnav::host {

struct FrameRow {
  std::int64_t camera_sequence = 0;
  std::int64_t capture_time_mono_us = 0;
  std::int64_t pose_time_mono_us = -1;
  std::int64_t model_step_time_mono_us = -1;
  std::int64_t render_done_mono_us = 0;
  double motion_to_photon_ms = 0.0;
  std::optional<cv::Point2d> tumour_px;
  std::optional<cv::Point3d> tumour_Cam_mm;  // the drawn centroid in Cam (3-D AR error)
  std::shared_ptr<const TriMesh> tumour_surface_Cam;  // the drawn tumour's surface in Cam (recording only)
  std::optional<double> blade_to_margin_mm;
  std::string flags;
  std::optional<bool> cutting;            // cutting sessions only
  int cut_faces = 0;
  double cut_area_mm2 = 0.0;
  std::optional<double> cut_path_error_mm;
  std::string cut_events;
  std::int64_t publish_time_mono_us = 0;
  std::int64_t receive_time_mono_us = 0;
  std::int64_t decode_done_mono_us = 0;
  std::int64_t shown_mono_us = 0;
};

std::string csv_header();
std::string csv_line(const FrameRow& row);

class Recorder {
 public:
  // Creates DIR (and parents). Throws SessionError naming the folder when it cannot.
  Recorder(const std::string& dir, const RecordSettings& settings);
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;
  void add(const FrameRow& row, cv::Mat frame);  // takes the image (no copy)
  // Flushes, writes the contact sheet; returns the files written.
  std::vector<std::string> close();
  // Video frames left out because encoding fell behind (the CSV has every row).
  std::int64_t video_frames_skipped() {
    std::lock_guard lock(mutex_);
    return video_frames_skipped_;
  }
  static constexpr std::size_t kMaxQueuedFrames = 120;

 private:
  void run();
  std::string dir_;
  RecordSettings settings_;
  std::ofstream csv_;
  std::ofstream tumour_bin_;
  std::vector<std::array<int, 3>> last_tumour_tris_;
  std::unique_ptr<cv::VideoWriter> writer_;
  std::vector<cv::Mat> thumbs_;
  std::int64_t next_thumb_us_ = -1;
  std::deque<std::pair<FrameRow, cv::Mat>> queue_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool closing_ = false;
  std::thread thread_;
  std::vector<std::string> files_;
  std::string error_;
  std::int64_t video_frames_skipped_ = 0;
};

}  // namespace arnav::host
