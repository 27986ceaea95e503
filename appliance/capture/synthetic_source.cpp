#include "appliance/capture/synthetic_source.hpp"

#include <opencv2/imgcodecs.hpp>

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "appliance/capture/opencv_sources.hpp"
#include "protocol/clock.hpp"

namespace arnav::capture {

SyntheticSource::SyntheticSource(SyntheticSettings settings) : settings_(std::move(settings)) {
  if (!(settings_.fps > 0.0 && settings_.fps <= 1000.0)) throw CaptureError("synthetic camera: fps must be in (0, 1000]");
  if (settings_.boards.empty()) throw CaptureError("synthetic camera: no board to render (add camera.synthetic.boards)");
  try {
    markers::validate(settings_.camera);
    for (const auto& b : settings_.boards) {
      markers::validate(b.board);
      camera_sim::validate(b.trajectory);
    }
  } catch (const std::invalid_argument& e) {
    throw CaptureError(std::string("synthetic camera: ") + e.what());
  }
  for (const auto& b : settings_.boards) {
    centres_.push_back(markers::paper_outline(b.board, 0.0).center());
  }
  if (settings_.readout_s > 1.0) throw CaptureError("synthetic camera: readout_ms must be at most 1000 (a sensor reads out within a second)");
  if (settings_.render_nice < -20 || settings_.render_nice > 19) throw CaptureError("synthetic camera: render_nice must be in [-20, 19]");
  if (settings_.render_ahead_frames < 1 || settings_.render_ahead_frames > 16)
    throw CaptureError("synthetic camera: render_ahead_frames must be in [1, 16]");
  if (settings_.phantom) {
    const auto& ph = *settings_.phantom;
    if (!ph.recording || ph.recording->frames.empty()) throw CaptureError("synthetic camera: phantom recording without frames");
    if (ph.board_index >= settings_.boards.size()) throw CaptureError("synthetic camera: phantom fixed to a board that is not rendered");
  }
}

SyntheticSource::~SyntheticSource() { stop_renderer(); }

bool SyntheticSource::in_outage(std::int64_t now_us) const {
  if (settings_.outage_at_s < 0 || start_us_ < 0) return false;
  const double t = 1e-6 * static_cast<double>(now_us - start_us_);
  return t >= settings_.outage_at_s && t < settings_.outage_at_s + settings_.outage_duration_s;
}

double SyntheticSource::readout_us() const { return 1e6 * (settings_.readout_s >= 0 ? settings_.readout_s : 1.0 / settings_.fps); }

std::int64_t SyntheticSource::exposure_us(std::int64_t sequence) const {
  return start_us_ + static_cast<std::int64_t>(std::llround(static_cast<double>(sequence) * 1e6 / settings_.fps));
}

std::int64_t SyntheticSource::readout_end_us(std::int64_t sequence) const {
  return exposure_us(sequence) + static_cast<std::int64_t>(std::llround(readout_us()));
}

SyntheticCounters SyntheticSource::counters() const {
  std::lock_guard lock(stats_mutex_);
  return counters_;
}

void SyntheticSource::open() {
  if (in_outage(monotonic_us())) throw CaptureError("synthetic camera: device absent (scheduled outage)");
  if (!renderer_) {
    try {
      renderer_ = std::make_unique<camera_sim::SyntheticRenderer>(settings_.camera);
    } catch (const std::invalid_argument& e) {
      throw CaptureError(std::string("synthetic camera: ") + e.what());
    }
  }
  if (!settings_.frames_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(settings_.frames_dir, ec);
    if (ec) throw CaptureError("synthetic camera: cannot create frames folder " + settings_.frames_dir.string() + ": " + ec.message());
  }
  if (!truth_ && !settings_.ground_truth_csv.empty()) {
    try {
      truth_ = std::make_unique<camera_sim::GroundTruthWriter>(settings_.ground_truth_csv, settings_.phantom ? 2 : 1);
    } catch (const camera_sim::GroundTruthError& e) {
      throw CaptureError(std::string("synthetic camera: ") + e.what());
    }
  }
  if (!timing_.is_open() && !settings_.timing_csv.empty()) {
    timing_.open(settings_.timing_csv);
    if (!timing_) throw CaptureError("synthetic camera: cannot write the timing file " + settings_.timing_csv.string() + " (check the folder)");
    timing_ << kTimingCsvHeader << "\n";
  }
  // On the bench's world clock the camera's frames count from the epoch (frame k captured at
  // epoch + k / fps; a camera that opens later skips the frames already due, like late ones).
  if (start_us_ < 0) start_us_ = settings_.phantom && settings_.phantom->epoch_mono_us ? *settings_.phantom->epoch_mono_us : monotonic_us();
  if (settings_.realtime) {
    // Frames whose readout ended while the camera was unplugged: absent (counted); before the
    // first open the camera was not running yet and nothing is counted.
    const std::int64_t now = monotonic_us();
    while (readout_end_us(next_) + static_cast<std::int64_t>(1e6 / settings_.fps) <= now) {
      if (opened_before_) note_absent(next_);
      ++next_;
    }
    std::lock_guard lock(mutex_);
    ready_.clear();
    next_render_ = next_;
    render_stop_ = false;
    render_ended_ = false;
    render_error_.clear();
    render_thread_ = std::thread([this] { render_loop(); });
  }
  opened_before_ = true;
  open_ = true;
}

void SyntheticSource::stop_renderer() {
  {
    std::lock_guard lock(mutex_);
    render_stop_ = true;
    cv_.notify_all();
  }
  if (render_thread_.joinable()) render_thread_.join();
}

void SyntheticSource::close() {
  open_ = false;
  stop_renderer();
  if (!settings_.realtime) return;
  // Rendered, never read out: exposed already (absent: the camera went away) or not yet
  // (rendered again after a reopen). The reader resumes at the first frame without a row.
  const std::int64_t now = monotonic_us();
  std::lock_guard lock(mutex_);
  std::optional<std::int64_t> first_future;
  for (const auto& f : ready_) {
    if (readout_end_us(f.sequence) <= now) note(f, readout_end_us(f.sequence), -1, -1, "absent");
    else if (!first_future) first_future = f.sequence;
  }
  ready_.clear();
  next_ = first_future.value_or(std::max(next_, next_render_));
  next_render_ = next_;  // a second close (the reader's, after a loss) changes nothing
}

Eigen::Isometry3d SyntheticSource::X_CamBoard(size_t board_index, std::int64_t sequence) const {
  const double t = static_cast<double>(sequence) / settings_.fps;
  const auto& b = settings_.boards.at(board_index);
  return b.trajectory.X_CamBoard(t, centres_.at(board_index), markers::front_side(b.board));
}

SyntheticSource::Rendered SyntheticSource::render(std::int64_t seq, std::int64_t exposure) {
  Rendered f;
  f.sequence = seq;
  f.exposure_us = exposure;
  f.render_start_us = monotonic_us();
  std::vector<camera_sim::BoardInScene> scene;
  for (size_t b = 0; b < settings_.boards.size(); ++b) {
    f.X_CamBoards.push_back(X_CamBoard(b, seq));
    scene.push_back({&settings_.boards[b].board, f.X_CamBoards.back()});
  }
  camera_sim::RenderOptions opt = settings_.render;
  opt.noise_seed = settings_.render.noise_seed + static_cast<std::uint64_t>(seq);
  std::vector<camera_sim::SurfaceInScene> surfaces;
  Eigen::Matrix3Xd organ_Cam_mm;
  if (settings_.phantom) {
    const auto& ph = *settings_.phantom;
    const double t_s = ph.epoch_mono_us ? 1e-6 * static_cast<double>(exposure - *ph.epoch_mono_us) : static_cast<double>(seq) / settings_.fps;
    const camera_sim::PhantomFrame pf = ph.recording->at(ph.start_s + t_s);
    const Eigen::Isometry3d X_CamModel = scene[ph.board_index].X_CamBoard * ph.X_BoardModel;
    organ_Cam_mm = X_CamModel * pf.vertices_Model_mm;
    for (const auto& p : pf.targets_Model_mm) f.targets_Cam_mm.push_back(X_CamModel * p);
    surfaces.push_back({&organ_Cam_mm, &ph.recording->faces, ph.reflectance});
  }
  // A static scene (the same board poses and organ as the last frame) is only re-exposed:
  // the same image a full render gives, with this frame's noise.
  std::vector<Eigen::Matrix4d> poses;
  for (const auto& X : f.X_CamBoards) poses.push_back(X.matrix());
  if (scene_cache_ && scene_cache_->X_CamBoards == poses && scene_cache_->organ_Cam_mm.cols() == organ_Cam_mm.cols() &&
      scene_cache_->organ_Cam_mm == organ_Cam_mm) {
    f.image = camera_sim::expose_radiance(scene_cache_->radiance, opt);
    f.tags = scene_cache_->tags;
    std::lock_guard lock(stats_mutex_);
    ++counters_.reexposed;
  } else {
    opt.keep_radiance = true;
    camera_sim::RenderResult r = renderer_->render(scene, surfaces, opt);
    f.image = r.image;
    f.tags = r.tags;
    scene_cache_ = SceneCache{std::move(poses), organ_Cam_mm, std::move(r.radiance), std::move(r.tags)};
  }
  f.render_done_us = monotonic_us();
  return f;
}

void SyntheticSource::note(const Rendered& f, std::int64_t readout_end, std::int64_t delivered, std::int64_t handed, const char* status) {
  {
    std::lock_guard lock(stats_mutex_);
    const std::string st = status;
    if (st == "delivered") {
      ++counters_.delivered;
      if (delivered > readout_end) ++counters_.delivered_late;
    } else if (st == "dropped_render_late") {
      ++counters_.dropped_render_late;
    } else if (st == "dropped_reader_late") {
      ++counters_.dropped_reader_late;
    } else {
      ++counters_.absent;
    }
    if (timing_.is_open())
      timing_ << f.sequence << ',' << f.exposure_us << ',' << f.render_start_us << ',' << f.render_done_us << ',' << readout_end << ','
              << delivered << ',' << handed << ',' << status << '\n' << std::flush;
  }
}

void SyntheticSource::note_absent(std::int64_t sequence) {
  Rendered f;
  f.sequence = sequence;
  f.exposure_us = exposure_us(sequence);
  note(f, readout_end_us(sequence), -1, -1, "absent");
}

void SyntheticSource::render_loop() {
  const auto period_us = static_cast<std::int64_t>(std::llround(1e6 / settings_.fps));
  const auto depth = static_cast<std::size_t>(std::max(1, settings_.render_ahead_frames));
  // A real camera costs the appliance's CPUs nothing: with render_nice the bench's renderer
  // yields them to the product (Linux: a thread's own nice value).
  if (settings_.render_nice != 0 && ::setpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)), settings_.render_nice) != 0) {
    std::lock_guard lock(mutex_);
    render_error_ = "synthetic camera: cannot set the renderer's nice value " + std::to_string(settings_.render_nice) + ": " +
                    std::strerror(errno) + " (render_nice below 0 needs CAP_SYS_NICE)";
    cv_.notify_all();
    return;
  }
  // The renderer's recent wall time per frame: a frame is only started when it can still be
  // delivered once rendered (rendering ahead, into the future when the reader is ahead).
  double render_us = static_cast<double>(period_us);
  for (;;) {
    std::int64_t k = 0;
    bool reader_behind = false;  // the queue was full: the reader had not taken the frames rendered ahead
    {
      std::unique_lock lock(mutex_);
      reader_behind = ready_.size() >= depth;
      cv_.wait(lock, [&] { return render_stop_ || ready_.size() < depth; });
      if (render_stop_) return;
      k = next_render_;
    }
    // A frame that can no longer be delivered before its successor's readout, once rendered,
    // is dropped (counted, never rendered late for nothing): the reader's fault when it kept
    // the renderer waiting, else the renderer's.
    const std::int64_t now = monotonic_us();
    const auto lead_us = static_cast<std::int64_t>(1.25 * render_us);
    while (readout_end_us(k) + period_us <= now + lead_us && (settings_.frame_count == 0 || k < settings_.frame_count)) {
      Rendered skipped;
      skipped.sequence = k;
      skipped.exposure_us = exposure_us(k);
      const bool reader_fault = reader_behind && readout_end_us(k) + period_us <= now;
      note(skipped, readout_end_us(k), -1, -1, reader_fault ? "dropped_reader_late" : "dropped_render_late");
      ++k;
    }
    if (settings_.frame_count > 0 && k >= settings_.frame_count) {
      std::lock_guard lock(mutex_);
      next_render_ = k;
      render_ended_ = true;
      cv_.notify_all();
      return;
    }
    Rendered f;
    try {
      f = render(k, exposure_us(k));
    } catch (const std::exception& e) {
      std::lock_guard lock(mutex_);
      render_error_ = std::string("synthetic camera: rendering frame ") + std::to_string(k) + " failed: " + e.what();
      cv_.notify_all();
      return;
    }
    render_us = 0.8 * render_us + 0.2 * static_cast<double>(f.render_done_us - f.render_start_us);
    std::lock_guard lock(mutex_);
    next_render_ = k + 1;
    ready_.push_back(std::move(f));
    cv_.notify_all();
  }
}

ReadResult SyntheticSource::deliver(Rendered f, Frame& frame, std::int64_t delivered_us) {
  const std::int64_t seq = f.sequence;
  frame.image = f.image;
  frame.sequence = seq;
  frame.capture_time_mono_us = f.exposure_us;
  frame.delivered_time_mono_us = delivered_us;
  frame.origin.clear();

  std::string file;
  if (!settings_.frames_dir.empty()) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%06lld.png", static_cast<long long>(seq));
    file = name;
    if (!cv::imwrite((settings_.frames_dir / file).string(), frame.image)) {
      return {ReadStatus::Lost, "synthetic camera: cannot write " + (settings_.frames_dir / file).string()};
    }
    frame.origin = (settings_.frames_dir / file).string();
  }
  if (truth_) {
    for (size_t b = 0; b < settings_.boards.size(); ++b) {
      int visible = 0;
      for (const auto& t : f.tags) {
        if (t.board == settings_.boards[b].board.name && t.in_image && t.facing && t.occluded_fraction < 0.1) ++visible;
      }
      truth_->write({seq, static_cast<double>(seq) / settings_.fps, settings_.boards[b].board.name, f.X_CamBoards[b], visible, file});
    }
    if (settings_.phantom && !f.targets_Cam_mm.empty()) {
      const auto& targets_Cam_mm = f.targets_Cam_mm;
      const auto px = settings_.camera.project(targets_Cam_mm);
      for (std::size_t i = 0; i < targets_Cam_mm.size(); ++i) {
        camera_sim::GroundTruthRow row;
        row.sequence = seq;
        row.time_s = static_cast<double>(seq) / settings_.fps;
        row.board = "target:" + settings_.phantom->recording->target_names[i];
        row.X_CamBoard.translation() = targets_Cam_mm[i];
        const bool in_front = targets_Cam_mm[i].z() > 1e-6;
        row.has_px = true;
        row.u_px = in_front ? px[i].x : 0.0;
        row.v_px = in_front ? px[i].y : 0.0;
        row.tags_visible = in_front && row.u_px >= 0 && row.v_px >= 0 && row.u_px <= settings_.camera.width - 1 &&
                                   row.v_px <= settings_.camera.height - 1
                               ? 1
                               : 0;
        row.frame_file = file;
        truth_->write(row);
      }
    }
  }
  return {};
}

ReadResult SyntheticSource::read(Frame& frame) {
  if (!open_) return {ReadStatus::Lost, "synthetic camera: not open"};
  if (!settings_.realtime) {
    if (settings_.frame_count > 0 && next_ >= settings_.frame_count) {
      return {ReadStatus::EndOfStream, "synthetic camera: " + std::to_string(settings_.frame_count) + " frames rendered"};
    }
    // As fast as the reader asks: exposed when asked for, delivered when rendered.
    const std::int64_t seq = next_++;
    Rendered f = render(seq, monotonic_us());
    const std::int64_t done_us = f.render_done_us;
    return deliver(std::move(f), frame, done_us);
  }
  const auto period_us = static_cast<std::int64_t>(std::llround(1e6 / settings_.fps));
  for (;;) {
    Rendered f;
    {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [&] { return !ready_.empty() || render_ended_ || !render_error_.empty(); });
      if (!render_error_.empty() && ready_.empty()) return {ReadStatus::Lost, render_error_};
      if (ready_.empty()) {
        return {ReadStatus::EndOfStream, "synthetic camera: " + std::to_string(settings_.frame_count) + " frames rendered"};
      }
      f = std::move(ready_.front());
      ready_.pop_front();
      cv_.notify_all();
    }
    next_ = f.sequence + 1;
    const std::int64_t readout_end = readout_end_us(f.sequence);
    const std::int64_t available = std::max(readout_end, f.render_done_us);
    const std::int64_t now = monotonic_us();
    // The next frame is read out already: a real camera's buffer holds only the newest.
    if (readout_end + period_us <= now) {
      note(f, readout_end, -1, -1, f.render_done_us >= readout_end + period_us ? "dropped_render_late" : "dropped_reader_late");
      continue;
    }
    sleep_until_mono_us(readout_end);
    // The first read at or after the outage start reports the loss, even when a slow
    // consumer only comes back after the outage window (the device was gone meanwhile).
    const double t_s = 1e-6 * static_cast<double>(monotonic_us() - start_us_);
    if (!outage_reported_ && settings_.outage_at_s >= 0 && t_s >= settings_.outage_at_s) {
      outage_reported_ = true;
      note(f, readout_end, -1, -1, "absent");  // read out as the camera went away
      close();
      return {ReadStatus::Lost, "synthetic camera: device stopped delivering (scheduled outage)"};
    }
    note(f, readout_end, available, monotonic_us(), "delivered");
    return deliver(std::move(f), frame, available);
  }
}

std::string SyntheticSource::describe() const {
  return "synthetic " + std::to_string(settings_.camera.width) + "x" + std::to_string(settings_.camera.height) + "@" +
         std::to_string(static_cast<int>(std::lround(settings_.fps))) + " (" + std::to_string(settings_.boards.size()) +
         " board(s)" + (settings_.phantom ? ", deforming phantom" : "") + ")";
}

}  // namespace arnav::capture
