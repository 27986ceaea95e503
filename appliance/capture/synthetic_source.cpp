#include "appliance/capture/synthetic_source.hpp"

#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdio>

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
  if (settings_.phantom) {
    const auto& ph = *settings_.phantom;
    if (!ph.recording || ph.recording->frames.empty()) throw CaptureError("synthetic camera: phantom recording without frames");
    if (ph.board_index >= settings_.boards.size()) throw CaptureError("synthetic camera: phantom fixed to a board that is not rendered");
  }
}

SyntheticSource::~SyntheticSource() = default;

bool SyntheticSource::in_outage(std::int64_t now_us) const {
  if (settings_.outage_at_s < 0 || start_us_ < 0) return false;
  const double t = 1e-6 * static_cast<double>(now_us - start_us_);
  return t >= settings_.outage_at_s && t < settings_.outage_at_s + settings_.outage_duration_s;
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
  // On the bench's world clock the camera's frames count from the epoch (frame k captured at
  // epoch + k / fps; a camera that opens later skips the frames already due, like late ones).
  if (start_us_ < 0) start_us_ = settings_.phantom && settings_.phantom->epoch_mono_us ? *settings_.phantom->epoch_mono_us : monotonic_us();
  open_ = true;
}

void SyntheticSource::close() { open_ = false; }

Eigen::Isometry3d SyntheticSource::X_CamBoard(size_t board_index, std::int64_t sequence) const {
  const double t = static_cast<double>(sequence) / settings_.fps;
  const auto& b = settings_.boards.at(board_index);
  return b.trajectory.X_CamBoard(t, centres_.at(board_index), markers::front_side(b.board));
}

ReadResult SyntheticSource::read(Frame& frame) {
  if (!open_) return {ReadStatus::Lost, "synthetic camera: not open"};
  if (settings_.frame_count > 0 && next_ >= settings_.frame_count) {
    return {ReadStatus::EndOfStream, "synthetic camera: " + std::to_string(settings_.frame_count) + " frames rendered"};
  }
  const double period_us = 1e6 / settings_.fps;
  if (settings_.realtime) {
    // A late consumer does not get old frames: the camera has moved on.
    const std::int64_t now = monotonic_us();
    const auto due = static_cast<std::int64_t>(std::floor(static_cast<double>(now - start_us_) / period_us));
    if (due > next_) next_ = due;
    sleep_until_mono_us(start_us_ + static_cast<std::int64_t>(static_cast<double>(next_) * period_us));
    // The first read at or after the outage start reports the loss, even when a slow
    // consumer only comes back after the outage window (the device was gone meanwhile).
    const double t_s = 1e-6 * static_cast<double>(monotonic_us() - start_us_);
    if (!outage_reported_ && settings_.outage_at_s >= 0 && t_s >= settings_.outage_at_s) {
      outage_reported_ = true;
      open_ = false;
      return {ReadStatus::Lost, "synthetic camera: device stopped delivering (scheduled outage)"};
    }
  }
  const std::int64_t seq = next_++;
  const std::int64_t capture_time_mono_us = settings_.realtime ? start_us_ + static_cast<std::int64_t>(static_cast<double>(seq) * period_us)
                                                               : monotonic_us();
  std::vector<camera_sim::BoardInScene> scene;
  for (size_t b = 0; b < settings_.boards.size(); ++b) scene.push_back({&settings_.boards[b].board, X_CamBoard(b, seq)});
  camera_sim::RenderOptions opt = settings_.render;
  opt.noise_seed = settings_.render.noise_seed + static_cast<std::uint64_t>(seq);
  std::vector<camera_sim::SurfaceInScene> surfaces;
  Eigen::Matrix3Xd organ_Cam_mm;
  std::vector<Eigen::Vector3d> targets_Cam_mm;
  if (settings_.phantom) {
    const auto& ph = *settings_.phantom;
    const double t_s = ph.epoch_mono_us ? 1e-6 * static_cast<double>(capture_time_mono_us - *ph.epoch_mono_us)
                                        : static_cast<double>(seq) / settings_.fps;
    const camera_sim::PhantomFrame pf = ph.recording->at(ph.start_s + t_s);
    const Eigen::Isometry3d X_CamModel = scene[ph.board_index].X_CamBoard * ph.X_BoardModel;
    organ_Cam_mm = X_CamModel * pf.vertices_Model_mm;
    for (const auto& p : pf.targets_Model_mm) targets_Cam_mm.push_back(X_CamModel * p);
    surfaces.push_back({&organ_Cam_mm, &ph.recording->faces, ph.reflectance});
  }
  camera_sim::RenderResult r = renderer_->render(scene, surfaces, opt);
  frame.image = r.image;
  frame.sequence = seq;
  frame.capture_time_mono_us = capture_time_mono_us;
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
      for (const auto& t : r.tags) {
        if (t.board == settings_.boards[b].board.name && t.in_image && t.facing && t.occluded_fraction < 0.1) ++visible;
      }
      truth_->write({seq, static_cast<double>(seq) / settings_.fps, settings_.boards[b].board.name, scene[b].X_CamBoard,
                     visible, file});
    }
    if (settings_.phantom && !targets_Cam_mm.empty()) {
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

std::string SyntheticSource::describe() const {
  return "synthetic " + std::to_string(settings_.camera.width) + "x" + std::to_string(settings_.camera.height) + "@" +
         std::to_string(static_cast<int>(std::lround(settings_.fps))) + " (" + std::to_string(settings_.boards.size()) +
         " board(s)" + (settings_.phantom ? ", deforming phantom" : "") + ")";
}

}  // namespace arnav::capture
