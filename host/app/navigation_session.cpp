#include "host/app/navigation_session.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "host/app/status_report.hpp"
#include "host/overlay/egl_context.hpp"
#include "host/overlay/overlay_geometry.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "host/overlay/overlay_window.hpp"
#include "host/sim/model_factory.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host {
namespace {

constexpr std::size_t kHistory = 240;  // poses kept per tool (4 s at 60 Hz)

unsigned layer_mask(const std::vector<std::string>& layers) {
  unsigned m = 0;
  for (const auto& l : layers) {
    if (l == "tumour") m |= overlay::kTumour;
    else if (l == "margin") m |= overlay::kMargin;
    else if (l == "vessels") m |= overlay::kVessels;
    else if (l == "cut") m |= overlay::kCut;
    else if (l == "organ") m |= overlay::kOrganVeil;
    else if (l == "outline") m |= overlay::kOutline;
    else if (l == "scalpel") m |= overlay::kScalpel;
  }
  return m;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

// Issue 29: a scene setting the tissue model cannot hold at the session's step rate is refused
// here, before anything starts (arnav-host exit 2), not stopped mid-session. at_scene names the
// session file, its line and key 'scene'.
void refuse_setting_that_cannot_hold(const Scene& scene, double rate_hz, const std::string& at_scene) {
  const double dt_s = 1.0 / rate_hz;
  char rate[96];
  std::snprintf(rate, sizeof rate, "the session's model.rate_hz %g (%.6f s a step)", rate_hz, dt_s);
  try {
    check_setting_holds(scene.problem, scene.model, dt_s, rate);
  } catch (const std::invalid_argument& e) {
    throw SessionError(at_scene + scene.source + ":" + std::to_string(scene.model_line) +
                       ": the tissue model cannot hold this setting (refused before the session starts): " + e.what());
  }
}

}  // namespace

void add_flag(std::string& flags, std::string_view flag) {
  if (!flags.empty()) flags += '|';
  flags += flag;
}

std::vector<std::string> split_flags(const std::string& flags) {
  std::vector<std::string> out;
  std::stringstream ss(flags);
  std::string f;
  while (std::getline(ss, f, '|'))
    if (!f.empty()) out.push_back(f);
  return out;
}

struct NavigationSession::Resolved {
  std::optional<Eigen::Isometry3d> X_CamRef;
  std::optional<Eigen::Isometry3d> X_RefScalpel;
  std::int64_t pose_time_us = -1;  // newest pose used (its receive time)
  std::string flags;
  std::vector<overlay::Banner> banners;
};

NavigationSession::NavigationSession(const SessionConfig& config, std::unique_ptr<Scene> scene, const SessionOptions& options)
    : config_(config),
      options_(options),
      scene_(std::move(scene)),
      tracker_(static_cast<std::int64_t>(config.stale_after_ms * 1000.0)) {
  X_RefModel_ = config_.X_RefModel;
  const std::string at_scene = config_.source + ":" + std::to_string(config_.scene_line) + ": key 'scene': ";
  const std::string at_cutting = config_.source + ":" + std::to_string(config_.cutting.line) + ": key 'cutting': ";
  std::optional<cut::CutSessionSettings> cutting;
  if (scene_ && scene_->cutting && config_.scalpel) {
    // The scene declares cutting and the session has a scalpel: the model is a cut session.
    if (config_.cutting.mode.empty())
      throw SessionError(at_scene + *config_.scene_path +
                         " declares cutting: say when the scalpel cuts: 'inputs: {cut_enable: <pedal input>}' (while held) or "
                         "'cutting: {mode: always}' / 'cutting: {mode: off}' (the blade only pushes)");
    const CuttingSpec& spec = *scene_->cutting;
    cut::CutSessionSettings settings = cut::cut_settings_from(spec);
    // Live: the model is rebuilt on the new mesh on a worker thread while the previous one
    // keeps stepping (the cut shows at once; a bundled-liver rebuild takes ~0.5 s here).
    // Replay (unthreaded): inline, so every replay of a log cuts the same way.
    settings.rebuild_in_background = options_.threaded;
    cutting = settings;
  } else if (!config_.cutting.mode.empty() && config_.cutting.line > 0) {
    throw SessionError(at_cutting + (scene_ ? "the scene " + *config_.scene_path + " declares no 'cutting:' section (docs/cut.md): add it there"
                                            : std::string("cutting needs a scene with a 'cutting:' section")));
  } else if (config_.inputs.cut_enable && !(scene_ && scene_->cutting)) {
    throw SessionError(config_.source + ":" + std::to_string(config_.inputs.cut_enable->line) +
                       ": key 'inputs.cut_enable': the scene declares no 'cutting:' section (docs/cut.md): add it there or drop cut_enable");
  }
  if (scene_) {
    refuse_setting_that_cannot_hold(*scene_, config_.model.rate_hz, at_scene);
    try {
      ModelClockSettings clock;
      clock.input_wait_ms = config_.model.input_wait_ms;
      clock.catch_up_ms = std::max(1000.0, 2.0 * config_.model.input_wait_ms);
      clock.cut_catch_up_ms = std::max(clock.catch_up_ms, config_.model.cut_catch_up_ms);
      if (config_.scalpel) clock.blade_stale_ms = config_.scalpel->stale_after_ms;
      clock.tool_gap_ms = std::max(config_.scalpel ? config_.scalpel->stale_after_ms : 0.0, config_.grasper ? config_.grasper->stale_after_ms : 0.0);
      if (clock.tool_gap_ms <= 0.0) clock.tool_gap_ms = 100.0;
      model_ = std::make_unique<ModelRunner>(*scene_, config_.model.rate_hz, config_.model.gravity, config_.overlay.margin_mm,
                                             config_.model.nice.value_or(cutting ? kCuttingModelNice : kModelNice), cutting, clock);
      if (config_.scalpel && model_->cutting()) model_->expect_blade();
    } catch (const std::exception& e) {
      throw SessionError(at_scene + "the tissue model cannot be built: " + e.what());
    }
  }
  if (config_.grasper) {
    const std::string at = config_.source + ":" + std::to_string(config_.grasper->line) + ": key 'tools.grasper': ";
    if (!model_) throw SessionError(at + "a grasper needs a scene with a tissue model");
    try {
      model_->enable_grasper(*config_.grasper);
    } catch (const std::invalid_argument& e) {
      throw SessionError(at + e.what());
    }
  }
  if (config_.live_registration) {
    const Eigen::Vector3d target = scene_ && !scene_->tumours.empty()
                                       ? tumour_centroid_World_mm(*scene_, 0, scene_->problem.mesh.rest_positions_World_mm)
                                       : Eigen::Vector3d::Zero();
    if (!config_.live_registration->landmarks_Model_mm.empty())
      live_ = std::make_unique<LiveRegistration>(*config_.live_registration, target);
    if (config_.live_registration->swab) {
      if (!scene_)
        throw SessionError(config_.source + ":" + std::to_string(config_.live_registration->swab->line) +
                           ": key 'registration.live.swab': a swab registration needs a scene (scene: <file>)");
      swab_ = std::make_unique<SwabRegistration>(*config_.live_registration->swab, scene_->organ_surface.positions_World_mm,
                                                 scene_->organ_surface.tris, target);
      if (config_.live_registration->X_RefModel_initial) {
        X_RefModel_ = config_.live_registration->X_RefModel_initial;
        swab_->begin(*X_RefModel_, "prior (" + config_.live_registration->initial_pose_path + ")");
      }
    }
  }
  if (options_.threaded) {
    try {
      cpu_plan_ = plan_cpu_partition(config_.model.cpu_partition, config_.camera.has_value(), model_ != nullptr);
    } catch (const std::invalid_argument& e) {
      throw SessionError(config_.source + ":" + std::to_string(config_.model.cpu_partition_line) + ": key 'model.cpu_partition': " + e.what());
    }
  } else {
    cpu_plan_.reason = "off (replay: one thread)";
  }
  if (!options_.record_dir.empty()) {
    if (!config_.camera) throw SessionError("--record " + options_.record_dir + ": the session " + config_.source + " has no camera: nothing to record");
    recorder_ = std::make_unique<Recorder>(options_.record_dir, config_.record);
  }
}

NavigationSession::~NavigationSession() {
  try {
    stop();
  } catch (const std::exception&) {  // stop() reports failures to an explicit caller
  }
}

void NavigationSession::start() {
  if (!options_.threaded) return;
  if (cpu_plan_.active) {  // before any thread of the session starts (setenv)
    // llvmpipe sizes its rasteriser thread pool from LP_NUM_THREADS when the GL context is
    // made (default: every CPU of the machine): as many as the rendering side has, and with
    // one CPU none at all (rasterised on the rendering thread, no hand-offs). An explicit
    // LP_NUM_THREADS in the environment is kept.
    if (!std::getenv("LP_NUM_THREADS")) {
      const std::size_t n = cpu_plan_.render_cpus.size();
      setenv("LP_NUM_THREADS", n == 1 ? "0" : std::to_string(n).c_str(), 1);
    }
    // OpenCV's worker threads (lens warp, compositing) would run on the model's CPU:
    // one rendering CPU, OpenCV runs serially (process-wide setting).
    if (cpu_plan_.render_cpus.size() == 1) cv::setNumThreads(1);
  }
  if (const char* lp = std::getenv("LP_NUM_THREADS")) lp_num_threads_ = lp;
  if (model_ && cpu_plan_.active) model_->set_cpus(cpu_plan_.model_cpus);
  if (model_) model_->start();
  if (!config_.camera) return;
  // The GL context belongs to the rendering thread: it is made there, before any frame
  // arrives (building it and the lens tables takes a few hundred ms), and start() waits.
  std::string error;
  bool ready = false, display_error = false;
  render_thread_ = std::thread([this, &error, &ready, &display_error] {
    std::string failed;  // error and ready live in start(): not touched after ready is set
    if (cpu_plan_.active) {
      // Before the GL context: llvmpipe's threads are started by this thread and inherit it.
      const std::string e = pin_current_thread(cpu_plan_.render_cpus);
      std::lock_guard lock(mutex_);
      render_pin_error_ = e;
    }
    bool no_display = false;
    try {
      ensure_renderer(config_.camera->intrinsics.image_width, config_.camera->intrinsics.image_height);
      open_window();
    } catch (const DisplayUnavailable& e) {
      failed = e.what();
      no_display = true;
    } catch (const std::exception& e) {
      failed = e.what();
    }
    if (!failed.empty()) {
      window_.reset();
      renderer_.reset();  // the GL objects die on the thread that made them
    }
    {
      std::lock_guard lock(frame_mutex_);
      error = failed;
      display_error = no_display;
      ready = true;
      frame_cv_.notify_all();
    }
    if (failed.empty()) render_loop();
  });
  std::unique_lock lock(frame_mutex_);
  frame_cv_.wait(lock, [&] { return ready; });
  if (!error.empty()) {
    lock.unlock();
    render_thread_.join();
    if (display_error) throw DisplayUnavailable(error);
    throw SessionError(config_.source + ": camera '" + config_.camera->name + "': the overlay renderer cannot start: " + error);
  }
}

void NavigationSession::open_window() {
  if (!config_.display.window || window_) return;
  try {
    const CameraSettings& cam = *config_.camera;
    window_ = std::make_unique<overlay::OverlayWindow>(cam.intrinsics.image_width, cam.intrinsics.image_height, config_.display.title);
  } catch (const overlay::DisplayError& e) {
    throw DisplayUnavailable(config_.source + ":" + std::to_string(config_.display.line) + ": key 'display.window': " + e.what());
  }
  std::lock_guard lock(mutex_);
  window_description_ = window_->description();
}

std::int64_t NavigationSession::window_frames() const { return window_frames_.load(); }

GLFWwindow* NavigationSession::window_handle() const { return window_ ? window_->handle() : nullptr; }

overlay::OverlayCamera NavigationSession::ensure_renderer(int width, int height) {
  const CameraSettings& cam = *config_.camera;
  overlay::OverlayCamera camera;
  camera.width = cam.intrinsics.image_width;
  camera.height = cam.intrinsics.image_height;
  camera.K = cam.intrinsics.camera_matrix;
  camera.distortion = cam.intrinsics.distortion;
  if (width != camera.width || height != camera.height) camera = camera.scaled_to(width, height);
  if (!renderer_ || renderer_->camera().width != camera.width || renderer_->camera().height != camera.height) {
    overlay::OverlayStyle style;
    style.msaa_samples = config_.overlay.msaa;
    renderer_ = std::make_unique<overlay::OverlayRenderer>(camera, style);
  }
  return camera;
}

void NavigationSession::stop() {
  {
    std::lock_guard lock(frame_mutex_);
    stopping_ = true;
    frame_cv_.notify_all();
  }
  if (render_thread_.joinable()) render_thread_.join();
  if (swab_thread_.joinable()) swab_thread_.join();
  if (model_) model_->stop();
  if (recorder_) {
    auto rec = std::move(recorder_);
    recorded_files_ = rec->close();
    video_frames_skipped_ = rec->video_frames_skipped();
    if (model_ && model_->cutting()) recorded_files_.push_back(write_cut_vertices());
  }
}

std::string NavigationSession::write_cut_vertices() const {
  const std::string path = options_.record_dir + "/cut_vertices.csv";
  std::ofstream out(path);
  out << "vertex,rest_x_mm,rest_y_mm,rest_z_mm,x_Model_mm,y_Model_mm,z_Model_mm\n";
  char line[256];
  for (const auto& v : model_->cut_vertices()) {
    std::snprintf(line, sizeof line, "%d,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f\n", v.id, v.rest_mm.x(), v.rest_mm.y(), v.rest_mm.z(), v.now_mm.x(),
                  v.now_mm.y(), v.now_mm.z());
    out << line;
  }
  if (!out) throw SessionError("--record " + options_.record_dir + ": cannot write " + path + " (disk full or not writable?)");
  return path;
}

void NavigationSession::on_pose(const tool_pose_t& msg, std::int64_t now_us) {
  std::lock_guard lock(mutex_);
  tracker_.on_pose(msg, now_us);
  PoseHistory& h = poses_[msg.tool_name];
  h.recent.push_back({msg, now_us});
  if (h.recent.size() > kHistory) h.recent.pop_front();
  // The scalpel's and the grasper's poses drive the model, at the time they were measured.
  if (model_) queue_model_pose(msg, now_us);
  if (config_.grasper && model_) drain_grasp();
}

void NavigationSession::on_health(const device_health_t& msg, std::int64_t now_us) {
  std::lock_guard lock(mutex_);
  tracker_.on_health(msg, now_us);
}

void NavigationSession::on_event(const appliance_event_t& msg) {
  std::lock_guard lock(mutex_);
  tracker_.on_event(msg);
}

void NavigationSession::say(const std::string& text) {
  messages_.push_back(text);
  if (options_.print_events) std::printf("%s\n", text.c_str()), std::fflush(stdout);
}

std::vector<std::string> NavigationSession::messages() {
  std::lock_guard lock(mutex_);
  return messages_;
}

std::optional<Eigen::Isometry3d> NavigationSession::X_RefModel() {
  std::lock_guard lock(mutex_);
  return X_RefModel_;
}

std::shared_ptr<const ModelSnapshot> NavigationSession::model_snapshot() const { return model_ ? model_->snapshot() : nullptr; }

CpuPlan NavigationSession::cpu_plan() const { return cpu_plan_; }

std::optional<TriMesh> NavigationSession::cut_surface() const { return last_cut_surface_; }

std::vector<TipSample> NavigationSession::pointer_tips_Ref(std::int64_t now_us) {
  std::vector<TipSample> out;
  const LiveRegistrationSettings& l = *config_.live_registration;
  auto it = poses_.find(l.pointer);
  if (it == poses_.end()) return out;
  const auto ref_it = poses_.find(config_.reference->name);
  for (const auto& s : it->second.recent) {
    if (s.msg.status != tool_pose_t::STATUS_VALID || s.arrival_us > now_us) continue;
    Eigen::Isometry3d X_RefPointer = get_pose(s.msg);
    if (s.msg.frame_parent != "Ref") {
      // The reference in the same parent frame, nearest in time.
      if (ref_it == poses_.end()) continue;
      const PoseSample* best = nullptr;
      for (const auto& r : ref_it->second.recent) {
        if (r.msg.status != tool_pose_t::STATUS_VALID || r.msg.frame_parent != s.msg.frame_parent || r.arrival_us > now_us) continue;
        if (!best || std::llabs(r.msg.receive_time_mono_us - s.msg.receive_time_mono_us) <
                         std::llabs(best->msg.receive_time_mono_us - s.msg.receive_time_mono_us))
          best = &r;
      }
      if (!best || std::llabs(best->msg.receive_time_mono_us - s.msg.receive_time_mono_us) > 50'000) continue;
      X_RefPointer = get_pose(best->msg).inverse() * X_RefPointer;
    }
    out.push_back({s.arrival_us, X_RefPointer * l.tip_Tool_mm});
  }
  return out;
}

// A model more than model.cut_catch_up_ms behind during a stroke applied several cutting
// samples to one tissue state (docs/overlay.md, "Model clock"): the cut drawn since may lie
// off the blade's path. Flagged on the frames that show such a step and said in a banner for
// 5 s after the latest one.
void NavigationSession::cut_merge_warning(const ModelSnapshot& snap, std::int64_t capture_us, std::string& flags,
                                          std::vector<overlay::Banner>& banners) {
  if (snap.clock.cut_samples_merged > cut_merged_seen_) {
    cut_merged_seen_ = snap.clock.cut_samples_merged;
    cut_merged_since_us_ = capture_us;
    add_flag(flags, "cut_samples_merged");
  }
  if (cut_merged_since_us_ < 0 || capture_us - cut_merged_since_us_ > 5'000'000) return;
  banners.push_back({"CUT MAY BE OFF THE BLADE'S PATH: the model fell " + std::to_string(std::lround(snap.clock.max_lag_ms)) +
                         " ms behind (" + std::to_string(cut_merged_seen_) + " blade samples merged)",
                     cv::Scalar(0, 140, 230)});
}

bool NavigationSession::cutting_armed(std::int64_t now_us, std::string* banner) {
  if (config_.cutting.mode == "always") return true;
  if (config_.cutting.mode != "input") return false;
  const InputBinding& b = *config_.inputs.cut_enable;
  const HeldState h = inputs_.held(b.input, b.state_stale_after_ms, now_us);
  const bool stale = h == HeldState::kStale || h == HeldState::kNeverSeen;
  const InputLevel* l = inputs_.level(b.input);
  if (stale) {
    char text[200];
    if (!l)
      std::snprintf(text, sizeof text, "INPUT: cut_enable '%s' - no state yet: cutting disarmed", b.input.c_str());
    else
      std::snprintf(text, sizeof text, "INPUT STALE: cut_enable '%s' - no state for %.0f ms (limit %.0f): cutting disarmed", b.input.c_str(),
                    static_cast<double>(now_us - l->last_seen_us) * 1e-3, b.state_stale_after_ms);
    if (banner) *banner = text;
    if (l && !disarmed_) {
      ++disarm_episodes_;
      say(text);
    }
  }
  disarmed_ = stale && l != nullptr;
  if (disarmed_) ++disarmed_frames_;
  return h == HeldState::kHeld;
}

void NavigationSession::drain_cut(FrameRow* row) {
  if (!model_ || !model_->cutting()) return;
  if (const auto snap = model_->snapshot()) {
    std::lock_guard lock(mutex_);
    last_cut_faces_ = snap->cut_faces;
    last_cut_area_mm2_ = snap->cut_area_mm2;
    last_cut_surface_ = snap->cut_surface;
    last_cut_rim_ = snap->cut_rim_mm;
  }
  const auto steps = model_->cut_steps(cut_steps_seen_);  // the counters are written by this thread only
  const auto events = model_->events(events_seen_);
  std::lock_guard lock(mutex_);  // summary_json reads them
  cut_steps_seen_ += steps.size();
  events_seen_ += events.size();
  for (const auto& st : steps) {
    if (st.new_cut_vertices == 0) continue;
    cut_path_error_mm_.push_back(st.path_error_mm);
    if (row) row->cut_path_error_mm = std::max(row->cut_path_error_mm.value_or(0.0), st.path_error_mm);
  }
  for (const auto& e : events) {
    if (row) row->cut_events += (row->cut_events.empty() ? "" : ";") + e.event.kind + ":" + e.event.structure;
    char text[200];
    std::snprintf(text, sizeof text, "cut event: %s %s at model step %lld (blade %.1f mm from the tumour; at [%.1f, %.1f, %.1f] mm in Model)",
                  e.event.kind.c_str(), e.event.structure.c_str(), static_cast<long long>(e.step), e.event.distance_mm,
                  e.event.location_World_mm.x(), e.event.location_World_mm.y(), e.event.location_World_mm.z());
    say(text);
    cut_events_.push_back(e);
  }
}

void NavigationSession::on_input(const input_event_t& msg, std::int64_t now_us) {
  std::lock_guard lock(mutex_);
  const bool press = inputs_.on_input(msg, now_us);
  if (config_.grasper && model_) grasp_request(now_us);
  if (!press) return;
  const bool landmark_accept = (live_ && msg.input_name == config_.live_registration->accept_input) ||
                               (config_.inputs.accept && msg.input_name == config_.inputs.accept->input);
  const bool swab_press = swab_ && msg.input_name == swab_->settings().accept_input;
  if (!landmark_accept && !swab_press) return;
  ++accept_presses_;
  if (landmark_accept && live_ && !live_->done()) {
    const LandmarkTake t = live_->take(pointer_tips_Ref(now_us), now_us);
    say(t.message);
    if (live_->done()) {
      X_RefModel_ = live_->X_RefModel();
      registration_changed_ = true;
      swab_begin_after_landmarks();
    }
    return;
  }
  if (swab_press) {
    swab_accept(now_us);
    return;
  }
  if (!live_) {
    say("accept '" + msg.input_name + "' pressed: nothing to accept (no live registration in this session)");
    return;
  }
  say("accept '" + msg.input_name + "' pressed: registration already complete");
}

void NavigationSession::advance_model(std::int64_t now_us) {
  if (model_) model_->advance_to(now_us);
}

void NavigationSession::submit_frame(const image_frame_t& msg, std::int64_t now_us) {
  // Decoded here, on the receiving thread: the JPEG of frame k+1 is decoded while the
  // rendering thread still draws frame k (same latency per frame, more frames per second).
  const auto t0 = std::chrono::steady_clock::now();
  {
    std::lock_guard lock(mutex_);
    latency_.received(msg.sequence);
  }
  PendingFrame f{msg, now_us, cv::imdecode(msg.data, cv::IMREAD_COLOR), 0.0, 0};
  f.decode_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  f.decoded_us = monotonic_us();
  f.msg.data.clear();  // decoded: the bytes are not needed again
  f.msg.size = 0;
  bool dropped = false;
  {
    std::lock_guard lock(frame_mutex_);
    dropped = pending_.has_value();
    pending_ = std::move(f);
    frame_cv_.notify_one();
  }
  if (dropped) {
    std::lock_guard lock(mutex_);
    ++frames_dropped_;
    latency_.dropped_by_host();
  }
}

void NavigationSession::render_loop() {
  struct ReleaseGl {  // the window and the GL context belong to this thread: destroyed here
    NavigationSession& s;
    ~ReleaseGl() {
      s.window_.reset();
      s.renderer_.reset();
    }
  } release{*this};
  for (;;) {
    PendingFrame item;
    {
      std::unique_lock lock(frame_mutex_);
      frame_cv_.wait(lock, [this] { return stopping_ || pending_.has_value(); });
      if (stopping_) return;
      item = std::move(*pending_);
      pending_.reset();
    }
    try {
      render_decoded(item.msg, std::move(item.image), item.decode_ms, item.decoded_us, item.now_us);
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      render_error_ = std::string("overlay: ") + e.what();
      return;
    }
  }
}

NavigationSession::Resolved NavigationSession::resolve_poses(const image_frame_t& frame, std::int64_t now_us) {
  Resolved r;
  std::lock_guard lock(mutex_);
  const auto history = [&](const std::string& tool) -> PoseHistory* {
    auto it = poses_.find(tool);
    return it == poses_.end() ? nullptr : &it->second;
  };
  // Newest valid sample with receive time at or before t (or the newest valid at all).
  const auto nearest_valid = [&](PoseHistory* h, std::int64_t t_us) -> const PoseSample* {
    if (!h) return nullptr;
    const PoseSample* best = nullptr;
    std::int64_t best_dt = 0;
    for (const auto& s : h->recent) {
      if (s.msg.status != tool_pose_t::STATUS_VALID || s.arrival_us > now_us) continue;
      const std::int64_t dt = std::llabs(s.msg.receive_time_mono_us - t_us);
      if (!best || dt < best_dt) {
        best = &s;
        best_dt = dt;
      }
    }
    return best;
  };
  // Fresh/lost/stale of a role as known when the frame arrived (now_us): messages that came
  // in later (the rendering thread may run behind) do not count, so live == replay.
  const auto check = [&](const ToolRole& role, const char* what, const char* flag, cv::Scalar colour) -> bool {
    PoseHistory* h = history(role.name);
    std::int8_t last_status = -1;
    std::int64_t last_valid_arrival_us = -1;
    if (h)
      for (auto it = h->recent.rbegin(); it != h->recent.rend(); ++it) {
        if (it->arrival_us > now_us) continue;
        if (last_status == -1) last_status = it->msg.status;
        if (it->msg.status == tool_pose_t::STATUS_VALID) {
          last_valid_arrival_us = it->arrival_us;
          break;
        }
      }
    if (h && last_status != -1 && last_status != tool_pose_t::STATUS_VALID) {
      add_flag(r.flags, std::string(flag) + "_lost");
      r.banners.push_back({std::string("TRACKING LOST: ") + what + " '" + role.name + "'", colour});
      return false;
    }
    const double age_ms = last_valid_arrival_us >= 0 ? static_cast<double>(now_us - last_valid_arrival_us) * 1e-3 : -1.0;
    if (age_ms < 0 || age_ms > role.stale_after_ms) {
      add_flag(r.flags, std::string(flag) + "_stale");
      char text[160];
      if (age_ms < 0)
        std::snprintf(text, sizeof text, "STALE: %s '%s' - no pose yet", what, role.name.c_str());
      else
        std::snprintf(text, sizeof text, "STALE: %s '%s' - last pose %.0f ms old (limit %.0f)", what, role.name.c_str(), age_ms,
                      role.stale_after_ms);
      r.banners.push_back({text, colour});
      return false;
    }
    return true;
  };
  const cv::Scalar red(0, 0, 200), amber(0, 140, 230);
  const ToolRole& ref_role = *config_.reference;
  const bool ref_ok = check(ref_role, "reference", "reference", red);
  PoseHistory* ref_h = history(ref_role.name);
  const CameraSettings& cam = *config_.camera;
  const auto use = [&](const PoseSample* s) { r.pose_time_us = std::max(r.pose_time_us, s->msg.receive_time_mono_us); };
  // Reference sample in a given parent frame, nearest to the frame's capture.
  const auto reference_in = [&](const std::string& parent) -> const PoseSample* {
    const PoseSample* s = nearest_valid(ref_h, frame.capture_time_mono_us);
    return s && s->msg.frame_parent == parent ? s : nullptr;
  };
  // X_Ref<tool> from a sample of that tool, whatever its parent frame.
  const auto to_ref = [&](const PoseSample& s) -> std::optional<Eigen::Isometry3d> {
    const Eigen::Isometry3d X = get_pose(s.msg);
    if (s.msg.frame_parent == "Ref") return X;
    if (const PoseSample* ref = reference_in(s.msg.frame_parent)) {
      use(ref);
      return get_pose(ref->msg).inverse() * X;
    }
    return std::nullopt;
  };

  if (ref_ok) {
    if (cam.pose_from == "reference") {
      // The reference board seen in this very frame: same camera sequence.
      const PoseSample* match = nullptr;
      if (ref_h)
        for (auto it = ref_h->recent.rbegin(); it != ref_h->recent.rend(); ++it)
          if (it->msg.source == tool_pose_t::SOURCE_CAMERA && it->msg.device_frame_number == frame.sequence) {
            match = &*it;
            break;
          }
      if (match && match->msg.status != tool_pose_t::STATUS_VALID) {
        add_flag(r.flags, "reference_lost");
        r.banners.push_back({"TRACKING LOST: reference '" + ref_role.name + "' not seen in this frame", red});
      } else {
        if (!match) {
          add_flag(r.flags, "pose_not_matched");
          match = nearest_valid(ref_h, frame.capture_time_mono_us);
        }
        if (match && match->msg.frame_parent == "Cam") {
          r.X_CamRef = get_pose(match->msg);
          use(match);
        } else if (match) {
          add_flag(r.flags, "camera_pose_lost");
          r.banners.push_back({"NO CAMERA POSE: reference '" + ref_role.name + "' arrives in frame " + match->msg.frame_parent +
                                   "; pose_from: reference needs it in Cam",
                               red});
        }
      }
    } else {
      const ToolRole cam_role{cam.pose_tool, cam.stale_after_ms};
      if (check(cam_role, "camera marker", "camera_pose", red)) {
        const PoseSample* s = nearest_valid(history(cam.pose_tool), frame.capture_time_mono_us);
        std::optional<Eigen::Isometry3d> X_RefTool = s ? to_ref(*s) : std::nullopt;
        if (X_RefTool) {
          use(s);
          r.X_CamRef = (*X_RefTool * cam.X_ToolCam).inverse();
        } else {
          add_flag(r.flags, "camera_pose_lost");
          r.banners.push_back({"NO CAMERA POSE: camera marker '" + cam.pose_tool + "' cannot be related to the reference", red});
        }
      }
    }
  }
  if (config_.scalpel && check(*config_.scalpel, "scalpel", "scalpel", amber)) {
    const PoseSample* s = nearest_valid(history(config_.scalpel->name), frame.capture_time_mono_us);
    if (s) {
      r.X_RefScalpel = to_ref(*s);
      if (r.X_RefScalpel) use(s);
      else add_flag(r.flags, "scalpel_lost");
    }
  }
  return r;
}

FrameResult NavigationSession::render_frame(const image_frame_t& msg, std::int64_t now_us) {
  {
    std::lock_guard lock(mutex_);
    latency_.received(msg.sequence);
  }
  const auto t0 = std::chrono::steady_clock::now();
  cv::Mat image = cv::imdecode(msg.data, cv::IMREAD_COLOR);
  const double decode_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const std::int64_t decoded_us = options_.threaded ? monotonic_us() : now_us + static_cast<std::int64_t>(decode_ms * 1000.0);
  return render_decoded(msg, std::move(image), decode_ms, decoded_us, now_us);
}

FrameResult NavigationSession::render_decoded(const image_frame_t& msg, cv::Mat image, double decode_ms, std::int64_t decoded_us,
                                              std::int64_t now_us) {
  // The frame's time starts with its decode (done by the caller: live, the thread that
  // received it, while this thread may still draw the previous frame).
  const auto t0 = std::chrono::steady_clock::now() - std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                        std::chrono::duration<double, std::milli>(decode_ms));
  const double cpu0 = thread_cpu_ms();
  FrameResult out;
  out.row.camera_sequence = msg.sequence;
  out.row.capture_time_mono_us = msg.capture_time_mono_us;
  {
    std::lock_guard lock(mutex_);
    ++frames_received_;
  }
  if (image.empty()) {
    std::lock_guard lock(mutex_);
    ++decode_failures_;
    latency_.undecodable();
    return out;
  }
  const overlay::OverlayCamera camera = ensure_renderer(image.cols, image.rows);

  Resolved r = resolve_poses(msg, now_us);
  // A gap in the camera's frames longer than its limit (unplugged, stalled): the first
  // frame after it says so, and the summary counts it.
  if (last_capture_us_ >= 0) {
    const double gap_ms = static_cast<double>(msg.capture_time_mono_us - last_capture_us_) * 1e-3;
    if (gap_ms > config_.camera->stale_after_ms) {
      add_flag(r.flags, "camera_gap");
      std::lock_guard lock(mutex_);
      camera_gaps_ms_.push_back(gap_ms);
    }
  }
  last_capture_us_ = msg.capture_time_mono_us;
  // With a grasper the model moves with the tool: the state as the tool was when the frame was captured.
  std::shared_ptr<const ModelSnapshot> snap = !model_ ? nullptr
                                              : model_->has_inputs() ? model_->snapshot_at(msg.capture_time_mono_us)
                                                                      : model_->snapshot();
  out.row.pose_time_mono_us = r.pose_time_us;
  if (snap) out.row.model_step_time_mono_us = snap->step_done_mono_us;
  if (snap && !snap->healthy) {
    add_flag(r.flags, "model_unhealthy");
    r.banners.push_back({"MODEL: " + snap->warning, cv::Scalar(0, 0, 160)});
  }
  if (snap) cut_merge_warning(*snap, msg.capture_time_mono_us, r.flags, r.banners);
  if (model_ && model_->has_grasper()) {
    std::vector<std::string> grasp_banners;
    grasp_frame(r.flags, grasp_banners);
    for (const auto& b : grasp_banners) r.banners.push_back({b, cv::Scalar(0, 140, 230)});
  }
  // Registration (file, or live once all landmarks are taken), inputs and cutting state as
  // known when the frame arrived.
  std::optional<Eigen::Isometry3d> X_RefModel;
  std::string registration_status;
  bool cutting_enabled = false;
  const bool cut_model = model_ && model_->cutting();
  {
    std::lock_guard lock(mutex_);
    X_RefModel = X_RefModel_;
    if (live_) registration_status = live_->status();
    if (swab_ && swab_->started()) {
      const std::string st = swab_->status();
      registration_status = registration_status.empty() ? st : registration_status + "; " + st;
      if (!swab_->done()) add_flag(r.flags, swab_->running() ? "swab_registering" : "swab");
    }
    // Messages the sealed bus rejected: the banner on top (the dropped messages themselves
    // never reach the session; navigation_session_security.cpp).
    std::vector<std::string> security_banners;
    security_frame(now_us, r.flags, security_banners);
    if (!security_banners.empty()) {
      std::vector<overlay::Banner> banners;
      for (auto& text : security_banners) banners.emplace_back(overlay::Banner{std::move(text), cv::Scalar(120, 0, 170)});
      std::move(r.banners.begin(), r.banners.end(), std::back_inserter(banners));
      r.banners = std::move(banners);
    }
    if (registration_changed_ && X_RefModel_) {
      add_flag(r.flags, "registration_changed");
      registration_changed_ = false;
    }
    if (cut_model) {
      std::string banner;
      cutting_enabled = cutting_armed(now_us, &banner);
      if (!banner.empty()) {
        add_flag(r.flags, "input_stale");
        r.banners.push_back({banner, cv::Scalar(0, 140, 230)});
      }
    }
  }
  if (!X_RefModel) {
    add_flag(r.flags, "unregistered");
    r.banners.push_back({registration_status.empty() ? std::string("NOT REGISTERED") : registration_status, cv::Scalar(0, 140, 230)});
  } else if ((live_ && !live_->done()) || (swab_ && swab_->started() && !swab_->done())) {
    r.banners.push_back({registration_status, cv::Scalar(0, 140, 230)});
  }
  // The blade in Model: handed to the model (cutting/pushing) whether or not the camera pose is known.
  std::optional<std::array<Eigen::Vector3d, 2>> blade_Model;
  if (r.X_RefScalpel && X_RefModel) {
    const Eigen::Isometry3d X_ModelTool = X_RefModel->inverse() * *r.X_RefScalpel;
    blade_Model = std::array<Eigen::Vector3d, 2>{X_ModelTool * config_.scalpel->tip_Tool_mm, X_ModelTool * config_.scalpel->heel_Tool_mm};
  }
  if (cut_model) {
    out.row.cutting = cutting_enabled && blade_Model.has_value();
    if (*out.row.cutting) ++cutting_frames_;
  }

  std::optional<double> distance;
  double overlay_ms = 0.0;
  if (r.X_CamRef && snap && X_RefModel) {
    const Eigen::Isometry3d X_CamModel = *r.X_CamRef * *X_RefModel;
    overlay::OverlayContent content;
    content.X_CamModel = X_CamModel;
    content.layers = layer_mask(config_.overlay.layers);
    content.organ = &snap->organ;
    for (const auto& t : snap->tumours) content.tumours.push_back(&t);
    for (const auto& m : snap->margins) content.margins.push_back(&m);
    if (snap->vessels) content.vessels = &*snap->vessels;
    if (snap->cut_surface) content.cut_surface = &*snap->cut_surface;
    if (blade_Model) {
      const Eigen::Vector3d tip = (*blade_Model)[0], heel = (*blade_Model)[1];
      content.scalpel_mm = *blade_Model;
      for (const auto& t : snap->tumours) {
        const double d = overlay::blade_to_margin_mm(tip, heel, t, config_.overlay.margin_mm, 1.0);
        distance = distance ? std::min(*distance, d) : d;
      }
      // Without cutting the overlay shows the blade tip's trace through the tissue.
      if (!cut_model) cut_trace_.add(scene_->problem.mesh, snap->volume_positions_World_mm, tip);
    }
    if (cut_model)
      for (const auto& seg : snap->cut_rim_mm) content.cut_paths_mm.push_back({seg[0], seg[1]});
    if (!cut_model && cut_trace_.size() > 0) {
      last_strokes_ = cut_trace_.strokes(snap->volume_positions_World_mm, scene_->problem.mesh);
      content.cut_paths_mm = last_strokes_;
    }
    overlay::RenderTiming timing;
    const cv::Mat layer = renderer_->render(content, &timing);
    overlay_ms = timing.total_ms;
    overlay::composite(image, layer, timing.drawn_px);
    if (!snap->tumour_centroids_mm.empty()) {
      const Eigen::Vector3d p = X_CamModel * snap->tumour_centroids_mm[0];
      std::vector<cv::Point3d> in{{p.x(), p.y(), p.z()}};
      std::vector<cv::Point2d> px;
      cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(camera.K), cv::Mat(camera.distortion), px);
      out.row.tumour_px = px[0];
      out.row.tumour_Cam_mm = cv::Point3d(p.x(), p.y(), p.z());
      if (recorder_ && !snap->tumours.empty()) {
        auto surface = std::make_shared<TriMesh>(snap->tumours[0]);
        surface->positions_World_mm = X_CamModel * surface->positions_World_mm;  // now in Cam
        out.row.tumour_surface_Cam = std::move(surface);
      }
    }
  }
  if (cut_model && snap) {
    // Cut statistics of the model state drawn, events and cutting steps since the last frame.
    out.row.cut_faces = snap->cut_faces;
    out.row.cut_area_mm2 = snap->cut_area_mm2;
    drain_cut(&out.row);
  }
  out.row.blade_to_margin_mm = distance;
  char footer[300];
  std::snprintf(footer, sizeof footer, "seq %lld  model step %lld", static_cast<long long>(msg.sequence),
                static_cast<long long>(snap ? snap->step : -1));
  std::string footer_text = footer;
  if (cut_model)
    footer_text += std::string(out.row.cutting.value_or(false) ? "  CUTTING" : "  cutting off") + "  cut " +
                   std::to_string(static_cast<int>(std::lround(out.row.cut_area_mm2))) + " mm2";
  if ((live_ && live_->done() && !swab_) || (swab_ && swab_->done())) footer_text += "  " + registration_status;
  overlay::draw_status(image, r.banners, distance, config_.overlay.warn_mm, footer_text);
  const double render_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  out.row.render_done_mono_us = options_.threaded ? monotonic_us() : now_us + static_cast<std::int64_t>(render_ms * 1000.0);
  out.row.motion_to_photon_ms = static_cast<double>(out.row.render_done_mono_us - msg.capture_time_mono_us) * 1e-3;
  out.row.publish_time_mono_us = msg.publish_time_mono_us;
  out.row.receive_time_mono_us = now_us;
  out.row.decode_done_mono_us = decoded_us;
  out.row.flags = r.flags;
  for (const auto& b : r.banners) out.banners.push_back(b.text);
  {
    std::lock_guard lock(mutex_);
    ++frames_displayed_;
    render_ms_.push_back(render_ms);
    decode_ms_.push_back(decode_ms);
    overlay_ms_.push_back(overlay_ms);
    render_cpu_ms_.push_back(thread_cpu_ms() - cpu0);
    note_flags(out.row);
  }
  double show_ms = 0.0;
  if (window_) {
    // After "overlay ready": upload to the window's texture and swap (the display stage).
    const auto d0 = std::chrono::steady_clock::now();
    window_->show(image);
    window_frames_ = window_->frames_shown();
    if (window_->close_requested()) window_closed_ = true;
    show_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - d0).count();
    std::lock_guard lock(mutex_);
    display_ms_.push_back(show_ms);
  }
  // Shown: the buffer swap done (window), or the frame handed to the recorder / the caller.
  out.row.shown_mono_us = options_.threaded ? monotonic_us() : out.row.render_done_mono_us + static_cast<std::int64_t>(show_ms * 1000.0);
  {
    std::lock_guard lock(mutex_);
    latency_.shown({msg.sequence, msg.capture_time_mono_us, msg.publish_time_mono_us, now_us, decoded_us, out.row.render_done_mono_us,
                    out.row.shown_mono_us});
  }
  if (recorder_) recorder_->add(out.row, options_.keep_last_frame ? image.clone() : image);
  if (options_.keep_last_frame) {
    out.image = image;
    std::lock_guard lock(mutex_);
    last_ = out;
  }
  return out;
}

void NavigationSession::note_flags(const FrameRow& row) {
  std::set<std::string> now;
  for (const auto& f : split_flags(row.flags)) now.insert(f);
  for (const auto& f : now) {
    ++flag_frames_[f];
    if (!active_flags_.count(f)) {
      ++flag_episodes_[f];
      flag_spans_[f].push_back({row.capture_time_mono_us, -1});
    }
  }
  for (const auto& f : active_flags_)
    if (!now.count(f)) flag_spans_[f].back().second = row.capture_time_mono_us;
  active_flags_ = now;
}

std::string NavigationSession::failure() {
  std::lock_guard lock(mutex_);
  return render_error_;
}

ToolFreshnessTracker NavigationSession::tracker_at(std::int64_t now_us) {
  std::lock_guard lock(mutex_);
  tracker_.update(now_us);
  return tracker_;
}

std::optional<FrameResult> NavigationSession::last_frame() {
  std::lock_guard lock(mutex_);
  return last_;
}

std::string NavigationSession::status_table(std::int64_t now_us) {
  std::lock_guard lock(mutex_);
  tracker_.update(now_us);
  security_check_over(now_us);
  return format_status_table(tracker_, now_us);
}

nlohmann::json NavigationSession::summary_json(double run_s) {
  if (!config_.camera) drain_cut(nullptr);  // no rendering thread: the caller's thread takes the model's reports
  std::lock_guard lock(mutex_);
  nlohmann::json j;
  j["frames_received"] = frames_received_;
  j["frames_displayed"] = frames_displayed_;
  j["frames_dropped"] = frames_dropped_;
  j["camera_gaps"] = {{"count", camera_gaps_ms_.size()},
                      {"max_ms", camera_gaps_ms_.empty() ? 0.0 : *std::max_element(camera_gaps_ms_.begin(), camera_gaps_ms_.end())}};
  j["decode_failures"] = decode_failures_;
  if (!options_.record_dir.empty()) j["video_frames_skipped"] = video_frames_skipped_;
  // Exposure -> shown by stage, misses (frame_latency.hpp); host processing latency =
  // received -> overlay ready (what arnav-host-latency-bench measures).
  j["latency"] = latency_.json();
  j["host_processing_latency_ms"] = j["latency"]["host_processing_latency_ms"];
  j["render_ms"] = {{"p50", percentile(render_ms_, 0.5)}, {"p99", percentile(render_ms_, 0.99)}};  // whole frame
  j["jpeg_decode_ms"] = {{"p50", percentile(decode_ms_, 0.5)}, {"p99", percentile(decode_ms_, 0.99)}};
  j["overlay_render_ms"] = {{"p50", percentile(overlay_ms_, 0.5)}, {"p99", percentile(overlay_ms_, 0.99)}};  // OverlayRenderer::render
  // The rendering thread's own CPU time per frame (without llvmpipe's or OpenCV's worker threads).
  j["render_thread_cpu_ms"] = {{"p50", percentile(render_cpu_ms_, 0.5)}, {"p99", percentile(render_cpu_ms_, 0.99)}};
  {
    nlohmann::json cp = {{"active", cpu_plan_.active}, {"mode", config_.model.cpu_partition}, {"reason", cpu_plan_.reason},
                         {"render_cpus", cpu_plan_.render_cpus}, {"model_cpus", cpu_plan_.model_cpus},
                         {"lp_num_threads", lp_num_threads_.empty() ? nlohmann::json() : nlohmann::json(lp_num_threads_)}};
    if (!render_pin_error_.empty()) cp["render_pin_error"] = render_pin_error_;
    if (model_ && !model_->pin_error().empty()) cp["model_pin_error"] = model_->pin_error();
    j["cpu_partition"] = cp;
  }
  if (config_.display.window)
    j["display"] = {{"window", true}, {"context", window_description_}, {"frames_shown", window_frames_.load()},
                    {"closed_by_user", window_closed_.load()},
                    {"show_ms", {{"p50", percentile(display_ms_, 0.5)}, {"p99", percentile(display_ms_, 0.99)}}}};
  if (model_) {
    const auto steps = model_->step_times_ms();
    j["model"] = {{"steps", steps.size()},
                  {"rate_hz", run_s > 0 ? static_cast<double>(steps.size()) / run_s : 0.0},
                  {"step_ms_p50", percentile(steps, 0.5)},
                  {"step_ms_p99", percentile(steps, 0.99)},
                  {"step_control_steps", model_->step_control_steps()},
                  {"nice", model_->nice()}};
    if (!model_->nice_error().empty()) j["model"]["nice_error"] = model_->nice_error();
    if (model_->has_inputs()) {
      // The model's clock (docs/overlay.md, "Model clock"): steps run without a late input,
      // grid steps skipped to catch up, samples that came after their step, the largest lag.
      const ModelClockCounters c = model_->clock_counters();
      j["model"]["clock"] = {{"steps", c.steps}, {"waited_out", c.steps_waited_out}, {"skipped", c.steps_skipped},
                             {"kept_for_cut", c.steps_kept_for_cut}, {"cut_samples_merged", c.cut_samples_merged},
                             {"late_samples", c.late_samples}, {"max_lag_ms", c.max_lag_ms}};
    }
  }
  if (model_ && model_->has_grasper()) j["grasper"] = grasp_summary();
  if (model_ && model_->cutting()) {
    std::map<std::string, int> by_kind;
    nlohmann::json events = nlohmann::json::array();
    for (const auto& e : cut_events_) {
      ++by_kind[e.event.kind];
      events.push_back({{"kind", e.event.kind}, {"structure", e.event.structure}, {"model_step", e.step},
                        {"distance_mm", e.event.distance_mm},
                        {"location_World_mm", {e.event.location_World_mm.x(), e.event.location_World_mm.y(), e.event.location_World_mm.z()}}});
    }
    j["cutting"] = {{"mode", config_.cutting.mode},
                    {"frames_cutting", cutting_frames_},
                    {"cut_steps", cut_steps_seen_},
                    {"steps_with_new_cut_vertices", cut_path_error_mm_.size()},
                    {"cut_faces", last_cut_faces_},
                    {"cut_area_mm2", last_cut_area_mm2_},
                    {"path_error_mm", {{"p50", percentile(cut_path_error_mm_, 0.5)}, {"p95", percentile(cut_path_error_mm_, 0.95)},
                                       {"max", cut_path_error_mm_.empty() ? 0.0 : *std::max_element(cut_path_error_mm_.begin(), cut_path_error_mm_.end())}}},
                    {"events_by_kind", by_kind},
                    {"events", events},
                    {"disarmed_by_stale_input", {{"episodes", disarm_episodes_}, {"frames", disarmed_frames_}}}};
  }
  if (!inputs_.levels().empty() || config_.inputs.cut_enable || config_.inputs.accept || live_ || swab_) {
    nlohmann::json in = nlohmann::json::object();
    for (const auto& [name, l] : inputs_.levels())
      in[name] = {{"presses", l.presses}, {"resyncs", l.resyncs}, {"pressed_at_exit", l.pressed}};
    j["inputs"] = {{"messages", inputs_.messages()}, {"accept_presses", accept_presses_}, {"by_input", in}};
  }
  if (live_) {
    nlohmann::json reg = {{"method", "live landmarks"}, {"landmarks_taken", live_->taken()}, {"landmarks", live_->total()},
                          {"refused", live_->refused()}, {"done", live_->done()}};
    if (live_->done()) {
      reg["fre_mm"] = live_->fre_mm();
      reg["predicted_tre_mm"] = live_->predicted_tre_mm();
      const Eigen::Isometry3d X = live_->X_RefModel();
      std::vector<double> m;
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m.push_back(X.matrix()(r, c));
      reg["X_RefModel"] = m;
    }
    if (swab_) {
      reg["method"] = "live landmarks + swab";
      reg["swab"] = swab_summary();
    }
    j["registration"] = reg;
  } else if (swab_) {
    j["registration"] = {{"method", "prior pose + swab"}, {"initial_pose", config_.live_registration->initial_pose_path}, {"swab", swab_summary()}};
  } else if (config_.X_RefModel) {
    j["registration"] = {{"method", "file"}, {"file", config_.registration_path}};
  }
  if (config_.security.mode == seal::SecuritySettings::Mode::Sealed) j["security_banner"] = security_summary();
  for (const auto& [f, n] : flag_frames_) {
    nlohmann::json spans = nlohmann::json::array();
    for (const auto& [a, b] : flag_spans_[f]) spans.push_back({{"onset_capture_us", a}, {"recovered_capture_us", b}});
    j["flags"][f] = {{"frames", n}, {"episodes", flag_episodes_[f]}, {"spans", spans}};
  }
  return j;
}

std::string NavigationSession::format_summary(double run_s) {
  const nlohmann::json j = summary_json(run_s);
  std::ostringstream os;
  if (config_.camera)
    os << "navigation: " << j["frames_displayed"] << " frames displayed of " << j["frames_received"] << " received, "
     << j["frames_dropped"] << " dropped, " << j["decode_failures"] << " undecodable; " << j["camera_gaps"]["count"]
     << " camera gap(s) over " << config_.camera->stale_after_ms << " ms (longest " << j["camera_gaps"]["max_ms"] << " ms)\n";
  else
    os << "navigation: no camera (model only)\n";
  char line[256];
  if (config_.camera) {
  const auto& lat = j["latency"];
  const auto& st = lat["stages_ms"];
  std::snprintf(line, sizeof line,
                "  host processing latency (frame received -> overlay ready): p50 %.1f ms, p99 %.1f ms, max %.1f ms\n",
                lat["host_processing_latency_ms"]["p50"].get<double>(), lat["host_processing_latency_ms"]["p99"].get<double>(),
                lat["host_processing_latency_ms"]["max"].get<double>());
  os << line;
  {
    std::lock_guard lock(mutex_);
    os << "  " << latency_.summary_line() << "\n";
  }
  std::snprintf(line, sizeof line,
                "    stages p50/p99 ms: exposure->published %.1f/%.1f, transport %.1f/%.1f, decode %.1f/%.1f, render %.1f/%.1f, "
                "display %.1f/%.1f\n",
                st["exposure_to_published"]["p50"].get<double>(), st["exposure_to_published"]["p99"].get<double>(),
                st["transport"]["p50"].get<double>(), st["transport"]["p99"].get<double>(), st["decode"]["p50"].get<double>(),
                st["decode"]["p99"].get<double>(), st["render"]["p50"].get<double>(), st["render"]["p99"].get<double>(),
                st["display"]["p50"].get<double>(), st["display"]["p99"].get<double>());
  os << line;
  }
  if (j.contains("model")) {
    std::snprintf(line, sizeof line, "  model: %lld steps, %.1f Hz, step p50 %.2f ms, p99 %.2f ms, %lld under step control\n",
                  static_cast<long long>(j["model"]["steps"].get<std::int64_t>()), j["model"]["rate_hz"].get<double>(),
                  j["model"]["step_ms_p50"].get<double>(), j["model"]["step_ms_p99"].get<double>(),
                  static_cast<long long>(j["model"]["step_control_steps"].get<std::int64_t>()));
    os << line;
  }
  if (j.contains("registration") && j["registration"]["method"].get<std::string>().rfind("live landmarks", 0) == 0) {
    const auto& g = j["registration"];
    if (g["done"].get<bool>())
      std::snprintf(line, sizeof line, "  registration (live, %d landmarks, %d refused): FRE %.2f mm, predicted TRE %.2f mm at the tumour\n",
                    g["landmarks"].get<int>(), g["refused"].get<int>(), g["fre_mm"].get<double>(), g["predicted_tre_mm"].get<double>());
    else
      std::snprintf(line, sizeof line, "  registration (live): incomplete, %d/%d landmarks taken, %d refused\n", g["landmarks_taken"].get<int>(),
                    g["landmarks"].get<int>(), g["refused"].get<int>());
    os << line;
  }
  if (j.contains("registration") && j["registration"].contains("swab")) os << format_swab_summary(j["registration"]["swab"]);
  if (j.contains("cutting")) {
    const auto& c = j["cutting"];
    std::snprintf(line, sizeof line,
                  "  cutting (%s): %lld frames cutting, %zu cutting steps, cut area %.0f mm2, cut-path error p50 %.3f mm, p95 %.3f mm, max %.3f mm\n",
                  c["mode"].get<std::string>().c_str(), static_cast<long long>(c["frames_cutting"].get<std::int64_t>()),
                  c["cut_steps"].get<std::size_t>(), c["cut_area_mm2"].get<double>(), c["path_error_mm"]["p50"].get<double>(),
                  c["path_error_mm"]["p95"].get<double>(), c["path_error_mm"]["max"].get<double>());
    os << line;
    os << "  cut events: " << c["events"].size();
    for (const auto& [k, n] : c["events_by_kind"].items()) os << ", " << k << " " << n;
    os << "; disarmed by stale input: " << c["disarmed_by_stale_input"]["episodes"] << " episode(s)\n";
  }
  if (j.contains("grasper")) {
    const auto& g = j["grasper"];
    std::snprintf(line, sizeof line,
                  "  grasper '%s': %lld grasp(s), %lld released, %lld released stale, %lld refused; %lld steps grasping, tip travel up to %.1f mm\n",
                  g["name"].get<std::string>().c_str(), static_cast<long long>(g["grasps"].get<std::int64_t>()),
                  static_cast<long long>(g["releases"].get<std::int64_t>()), static_cast<long long>(g["stale_releases"].get<std::int64_t>()),
                  static_cast<long long>(g["refused"].get<std::int64_t>()), static_cast<long long>(g["steps_grasping"].get<std::int64_t>()),
                  g["max_tip_travel_mm"].get<double>());
    os << line;
  }
  if (j.contains("security_banner")) {
    const auto& sb = j["security_banner"];
    os << "  security: " << sb["alerts"] << " alert(s) (banner while messages were rejected, held " << sb["hold_s"] << " s); rejected "
       << sb["dropped"] << " (forged " << sb["forged"] << ", tampered " << sb["tampered"] << ", replayed " << sb["replayed"] << ", stale "
       << sb["stale"] << ", unsealed " << sb["unsealed"] << ", malformed " << sb["malformed"] << ")\n";
  }
  if (j.contains("flags"))
    for (const auto& [f, v] : j["flags"].items())
      os << "  " << f << ": " << v["frames"] << " frames in " << v["episodes"] << " episode(s)\n";
  return os.str();
}

}  // namespace arnav::host
