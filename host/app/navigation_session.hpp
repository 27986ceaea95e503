#pragma once
// The navigation loop of `arnav-host SESSION.yaml`: tool poses, camera frames, health and
// events in; for every camera frame the overlay (tumour, margin, vessels, cut, organ
// outline, scalpel, blade-to-margin distance) drawn over the image, with status banners;
// recording of what was displayed. Only what the session declares is built: no camera,
// no renderer; no scene, no model.
//
// Frames: a pose message X_<parent><tool> (parent Cam, Ndi or Ref) is brought into Ref,
// the patient reference tool's frame; X_RefModel is the registration; the camera pose
// X_CamRef comes from the reference tool measured in Cam (pose_from: reference, matched to
// the frame by its camera sequence number) or from a tracked camera marker and hand-eye
// (pose_from: tool, nearest in time). X_CamModel = X_CamRef * X_RefModel.
//
// Clocks: `now_us` is the session clock: CLOCK_MONOTONIC live, the log's clock in replay.
// Threads: on_* are thread-safe; live sessions render on their own thread (start/stop),
// the model steps on its own (ModelRunner); replay calls render_frame and advance_model on
// one thread for a deterministic run. The GL context lives on the rendering thread.
#include <opencv2/core.hpp>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "arnav/image_frame_t.hpp"
#include "arnav/input_event_t.hpp"
#include "host/app/cpu_partition.hpp"
#include "host/app/cut_trace.hpp"
#include "host/app/frame_latency.hpp"
#include "host/app/input_state.hpp"
#include "host/app/live_registration.hpp"
#include "host/app/model_runner.hpp"
#include "host/app/recorder.hpp"
#include "host/app/security_alarm.hpp"
#include "host/app/session_config.hpp"
#include "host/app/swab_registration.hpp"
#include "host/app/tool_freshness.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "host/scene/scene.hpp"

struct GLFWwindow;

namespace arnav::host {

namespace overlay {
class OverlayRenderer;
class OverlayWindow;
struct OverlayCamera;
}

// display.window asked for a window and there is no display to open it on (exit 2: the
// session file asks for what this machine cannot give). The text names file:line and the fix.
class DisplayUnavailable : public SessionError {
 public:
  using SessionError::SessionError;
};

struct SessionOptions {
  bool threaded = true;           // live: model and rendering threads; replay: false
  std::string record_dir;         // --record; empty: no recording
  bool keep_last_frame = false;   // tests: keep the last displayed image
  bool print_events = false;      // print cut events, landmark takes and input disarms on stdout
};

struct FrameResult {
  FrameRow row;
  std::vector<std::string> banners;
  cv::Mat image;                  // only with keep_last_frame / render_frame callers
};

class NavigationSession {
 public:
  // Takes the loaded scene (null when the session has none). Throws SessionError.
  NavigationSession(const SessionConfig& config, std::unique_ptr<Scene> scene, const SessionOptions& options);
  ~NavigationSession();
  NavigationSession(const NavigationSession&) = delete;
  NavigationSession& operator=(const NavigationSession&) = delete;

  void on_pose(const tool_pose_t& msg, std::int64_t now_us);
  void on_health(const device_health_t& msg, std::int64_t now_us);
  void on_event(const appliance_event_t& msg);
  // ARNAV_INPUT changes and ARNAV_INPUT_STATE snapshots (input_event_t): cut_enable level,
  // accept presses (a live registration takes a landmark at once).
  void on_input(const input_event_t& msg, std::int64_t now_us);
  // The swab channel's messages (arnav.point_cloud_t bytes; registration.live.swab):
  // decoded and checked, brought into Ref, collected (navigation_session_swab.cpp).
  void on_cloud(const void* data, std::size_t size, const std::string& channel, std::int64_t now_us);
  // A message the sealed bus dropped (forged, tampered, replayed, stale, malformed or
  // unsealed; live: seal::SealedLcm::on_drop, replay: seal::LogOpener), received at now_us.
  // Only its verdict and channel: the message itself never reaches the session. Frames
  // arriving within the hold time carry a SECURITY banner (security_alarm.hpp); the first
  // drop of an alert and the alert's end are said (messages(), stdout with print_events).
  void on_bus_drop(seal::Verdict verdict, const std::string& channel, std::int64_t now_us);
  // The channel on_cloud wants (empty: the session has no swab step).
  std::string swab_channel() const;
  // Live: decodes the frame (on the calling thread) and hands it to the rendering thread;
  // a frame still waiting is replaced and counted as dropped. now_us: when it was received.
  void submit_frame(const image_frame_t& msg, std::int64_t now_us);
  // Renders on the calling thread. render_done = now_us + the time the rendering took
  // (live: the monotonic clock at the end); likewise decoded and shown (frame_latency.hpp).
  FrameResult render_frame(const image_frame_t& msg, std::int64_t now_us);
  // Replay: model steps due by now_us.
  void advance_model(std::int64_t now_us);

  void start();   // live: model and rendering threads (and the window); throws DisplayUnavailable, SessionError
  // Replay (unthreaded): opens the display window on the calling thread (the one that calls
  // render_frame) when the session asks for one. Throws DisplayUnavailable.
  void open_window();
  // The user closed the display window: the caller ends the session.
  bool window_closed() const { return window_closed_.load(); }
  // Frames shown in the window so far (0 without one).
  std::int64_t window_frames() const;
  // The window (null without one; tests read its pixels back from the X server).
  GLFWwindow* window_handle() const;
  void stop();    // joins them, closes the recording (throws SessionError if it failed)

  std::string status_table(std::int64_t now_us);
  // A copy of the per-tool/per-device bookkeeping, updated to now_us (for summaries).
  ToolFreshnessTracker tracker_at(std::int64_t now_us);
  std::string format_summary(double run_s);
  nlohmann::json summary_json(double run_s);
  std::vector<std::string> recorded_files() const { return recorded_files_; }
  bool has_camera() const { return config_.camera.has_value(); }
  bool has_model() const { return model_ != nullptr; }
  std::optional<FrameResult> last_frame();
  // Why the rendering thread stopped (empty while it runs): the caller exits with it.
  std::string failure();
  // The blade tip's path through the tissue so far (Model, at the last drawn model state).
  std::vector<std::vector<Eigen::Vector3d>> cut_strokes() const { return last_strokes_; }
  // Cutting sessions: the cut faces drawn last (Model, mm; empty before the first cut).
  std::optional<TriMesh> cut_surface() const;
  // ... and its rim on the organ surface (segments, Model, mm).
  std::vector<std::array<Eigen::Vector3d, 2>> cut_rim() const { return last_cut_rim_; }
  // The registration in use (file or live, once complete).
  std::optional<Eigen::Isometry3d> X_RefModel();
  // The model's latest snapshot (what the overlay draws; null without a model).
  std::shared_ptr<const ModelSnapshot> model_snapshot() const;
  // Live: the cores of the session (model.cpu_partition), set by start().
  CpuPlan cpu_plan() const;
  const LiveRegistration* live_registration() const { return live_.get(); }
  // The swab step (null without registration.live.swab); read it after stop() or in
  // unthreaded sessions (a live worker may be finishing it).
  const SwabRegistration* swab_registration() const { return swab_.get(); }
  // The grasper coupled to the model (tools.grasper; nullopt without one): its state after the last model step.
  std::optional<GraspStatus> grasp_status() const;
  // Messages printed with print_events (and kept for tests).
  std::vector<std::string> messages();

 private:
  struct PoseSample {
    tool_pose_t msg;
    std::int64_t arrival_us = 0;
  };
  struct PoseHistory {
    std::deque<PoseSample> recent;     // newest last
  };
  // Poses on their way to the model, in the order measured (navigation_session_inputs.cpp):
  // the scalpel's (cutting model) and the grasper's as inputs, the others as the tracker's
  // progress; all with mutex_ held.
  std::deque<PoseSample> model_poses_;
  bool is_blade_tool(const tool_pose_t& msg) const;
  bool is_grasper_tool(const tool_pose_t& msg) const;
  void queue_model_pose(const tool_pose_t& msg, std::int64_t now_us);
  void resolve_model_poses(std::int64_t now_us);
  // X_Ref<tool> at the pose's device time; decided = false: the reference measured at that
  // time may still come (wait).
  std::optional<Eigen::Isometry3d> X_RefTool_at(const PoseSample& p, std::int64_t now_us, bool& decided);
  // The cut pedal held at a device time (and its state fresh now).
  bool cut_pedal_at(std::int64_t device_time_us, std::int64_t now_us) const;
  void hand_blade(const tool_pose_t& msg, const std::optional<Eigen::Isometry3d>& X_RefTool, std::int64_t now_us);
  void hand_grasp(const tool_pose_t& msg, const std::optional<Eigen::Isometry3d>& X_RefTool, std::int64_t now_us);
  struct Resolved;
  Resolved resolve_poses(const image_frame_t& msg, std::int64_t now_us);
  // decoded_us: when the decode ended (session clock); now_us: when the frame was received.
  FrameResult render_decoded(const image_frame_t& msg, cv::Mat image, double decode_ms, std::int64_t decoded_us, std::int64_t now_us);
  void render_loop();
  // The renderer for frames of width x height (intrinsics scaled when they differ).
  overlay::OverlayCamera ensure_renderer(int width, int height);
  void note_flags(const FrameRow& row);
  // --record with a cutting model: DIR/cut_vertices.csv (ModelRunner::cut_vertices); its path.
  std::string write_cut_vertices() const;
  void say(const std::string& text);  // with mutex_ held
  // Flag and banner when the model merged cutting samples (rendering thread).
  void cut_merge_warning(const ModelSnapshot& snap, std::int64_t capture_us, std::string& flags, std::vector<overlay::Banner>& banners);
  // Cutting armed now (mode always, or cut_enable held with a fresh state); sets *banner
  // when the input is stale; counts disarms. With mutex_ held.
  bool cutting_armed(std::int64_t now_us, std::string* banner);
  // Takes the model's cutting steps and events since the last call (rendering thread, or
  // the caller's without a camera); fills row's cut columns when given.
  void drain_cut(FrameRow* row);
  std::vector<TipSample> pointer_tips_Ref(std::int64_t now_us);  // with mutex_ held
  // tools.grasper (navigation_session_grasp.cpp): its poses in Model and the grasp request
  // handed to the model (with mutex_ held); banners/flags for a frame; messages to say().
  void grasp_request(std::int64_t now_us);
  void grasp_frame(std::string& flags, std::vector<std::string>& banners);
  void drain_grasp();  // with mutex_ held
  nlohmann::json grasp_summary();  // with mutex_ held
  // The security banner (navigation_session_security.cpp), with mutex_ held (they take
  // security_mutex_ inside): the frame's banner lines and flags at now_us; the alert's end
  // said once it is over.
  void security_frame(std::int64_t now_us, std::string& flags, std::vector<std::string>& banners);
  void security_check_over(std::int64_t now_us);
  // With security_mutex_ held: the "alert over" text when the open alert has ended by now_us.
  std::string security_over_text(std::int64_t now_us);
  nlohmann::json security_summary();
  // registration.live.swab (navigation_session_swab.cpp), all with mutex_ held.
  void swab_begin_after_landmarks();
  void swab_accept(std::int64_t now_us);
  void swab_apply(const SwabOutcome& outcome);
  std::optional<PointCloud> swab_cloud_to_Ref(const PointCloud& cloud, std::int64_t capture_wall_us, std::int64_t publish_wall_us,
                                              std::string* why);
  nlohmann::json swab_summary();

  SessionConfig config_;
  SessionOptions options_;
  CpuPlan cpu_plan_;                   // model.cpu_partition (live sessions)
  std::string render_pin_error_;       // with mutex_
  std::string lp_num_threads_;         // LP_NUM_THREADS the renderer started with
  std::unique_ptr<Scene> scene_;
  std::unique_ptr<ModelRunner> model_;
  std::unique_ptr<overlay::OverlayRenderer> renderer_;  // created on the rendering thread
  std::unique_ptr<overlay::OverlayWindow> window_;      // display.window: the rendering thread's too
  std::atomic<bool> window_closed_{false};
  std::atomic<std::int64_t> window_frames_{0};
  std::string window_description_;                      // with mutex_
  std::vector<double> display_ms_;                      // with mutex_: window upload + swap per frame
  std::unique_ptr<Recorder> recorder_;
  std::vector<std::string> recorded_files_;
  std::int64_t video_frames_skipped_ = 0;

  std::mutex mutex_;                   // poses, tracker, stats
  ToolFreshnessTracker tracker_;
  std::map<std::string, PoseHistory> poses_;
  InputTracker inputs_;
  std::optional<Eigen::Isometry3d> X_RefModel_;
  std::unique_ptr<LiveRegistration> live_;
  std::unique_ptr<SwabRegistration> swab_;             // with mutex_
  std::thread swab_thread_;                            // live: the refinement off the render/model threads
  std::int64_t swab_corrupt_messages_ = 0;             // with mutex_
  std::set<std::string> swab_reported_;                // refusal kinds already said (with mutex_)
  bool registration_changed_ = false;                  // flag the next frame (with mutex_)
  std::vector<std::string> messages_;
  std::int64_t accept_presses_ = 0;

  // Rendering thread mailbox.
  std::mutex frame_mutex_;
  std::condition_variable frame_cv_;
  struct PendingFrame {
    image_frame_t msg;            // without its JPEG bytes (decoded)
    std::int64_t now_us = 0;      // received
    cv::Mat image;                // empty: undecodable
    double decode_ms = 0.0;
    std::int64_t decoded_us = 0;  // decode done
  };
  std::optional<PendingFrame> pending_;
  bool stopping_ = false;
  std::thread render_thread_;

  // Statistics.
  std::int64_t frames_received_ = 0, frames_displayed_ = 0, frames_dropped_ = 0, decode_failures_ = 0;
  std::vector<double> render_ms_, decode_ms_, overlay_ms_, render_cpu_ms_;
  FrameLatency latency_;                               // with mutex_: exposure -> shown by stage, misses
  std::map<std::string, std::int64_t> flag_frames_;   // frames showing each flag
  std::map<std::string, std::int64_t> flag_episodes_; // onsets
  std::map<std::string, std::vector<std::pair<std::int64_t, std::int64_t>>> flag_spans_;  // capture time onset, recovery (-1 open)
  std::set<std::string> active_flags_;
  std::optional<FrameResult> last_;
  std::string render_error_;
  std::int64_t last_capture_us_ = -1;                   // rendering thread only
  std::int64_t cut_merged_seen_ = 0;                    // rendering thread only: cutting samples merged, as last shown
  std::int64_t cut_merged_since_us_ = -1;               // capture time of the frame that first showed the latest merge
  std::vector<double> camera_gaps_ms_;
  CutTrace cut_trace_;                                  // rendering thread only
  std::size_t events_seen_ = 0, cut_steps_seen_ = 0;    // rendering thread only
  std::vector<ModelCutEvent> cut_events_;
  std::vector<double> cut_path_error_mm_;               // per cutting step
  std::int64_t cutting_frames_ = 0, disarmed_frames_ = 0, disarm_episodes_ = 0;
  bool disarmed_ = false;
  std::optional<TriMesh> last_cut_surface_;
  std::vector<std::array<Eigen::Vector3d, 2>> last_cut_rim_;
  double last_cut_area_mm2_ = 0.0;
  int last_cut_faces_ = 0;
  std::vector<std::vector<Eigen::Vector3d>> last_strokes_;
  // The bus's receive thread reports drops under this small lock only (a flood must not
  // contend for mutex_ with the rendering thread); order: mutex_ before security_mutex_.
  std::mutex security_mutex_;
  SecurityAlarm security_alarm_;                        // with security_mutex_
  bool security_alert_open_ = false;                    // with security_mutex_: an alert said and not yet over
  std::int64_t security_alerts_ = 0;                    // with security_mutex_
  GraspCommand grasp_cmd_;                              // with mutex_
  std::size_t grasp_messages_seen_ = 0;                 // with mutex_
  std::int64_t grasper_stale_frames_ = 0;               // with mutex_
};

// The swab lines of format_summary from summary_json's registration.swab.
std::string format_swab_summary(const nlohmann::json& swab);

// Splits "a|b" flags.
std::vector<std::string> split_flags(const std::string& flags);

// Appends `flag` to "a|b" flags.
void add_flag(std::string& flags, std::string_view flag);

}  // namespace arnav::host
