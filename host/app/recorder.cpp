#include "host/app/recorder.hpp"

#include "host/app/tumour_surface_file.hpp"

#include <filesystem>
#include <iomanip>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

namespace arnav::host {

std::string csv_header() {
  return "camera_sequence,capture_time_mono_us,pose_time_mono_us,model_step_time_mono_us,render_done_mono_us,"
         "motion_to_photon_ms,tumour_u_px,tumour_v_px,blade_to_margin_mm,flags,cutting,cut_faces,cut_area_mm2,cut_path_error_mm,cut_events,"
         "tumour_x_cam_mm,tumour_y_cam_mm,tumour_z_cam_mm,"
         "publish_time_mono_us,receive_time_mono_us,decode_done_mono_us,shown_mono_us";
}

std::string csv_line(const FrameRow& r) {
  std::ostringstream os;
  os << std::fixed << r.camera_sequence << ',' << r.capture_time_mono_us << ',' << r.pose_time_mono_us << ','
     << r.model_step_time_mono_us << ',' << r.render_done_mono_us << ',' << std::setprecision(3) << r.motion_to_photon_ms << ',';
  if (r.tumour_px) os << r.tumour_px->x << ',' << r.tumour_px->y;
  else os << ',';
  os << ',';
  if (r.blade_to_margin_mm) os << *r.blade_to_margin_mm;
  os << ',' << r.flags << ',';
  if (r.cutting) {
    os << (*r.cutting ? 1 : 0) << ',' << r.cut_faces << ',' << std::setprecision(2) << r.cut_area_mm2 << ',';
    if (r.cut_path_error_mm) os << std::setprecision(4) << *r.cut_path_error_mm;
    os << ',' << r.cut_events;
  } else {
    os << ",,,,";
  }
  os << ',';
  if (r.tumour_Cam_mm) os << std::setprecision(3) << r.tumour_Cam_mm->x << ',' << r.tumour_Cam_mm->y << ',' << r.tumour_Cam_mm->z;
  else os << ",,";
  os << ',' << r.publish_time_mono_us << ',' << r.receive_time_mono_us << ',' << r.decode_done_mono_us << ',' << r.shown_mono_us;
  return os.str();
}

Recorder::Recorder(const std::string& dir, const RecordSettings& settings) : dir_(dir), settings_(settings) {
  std::error_code ec;
  std::filesystem::create_directories(dir_, ec);
  const std::string csv_path = (std::filesystem::path(dir_) / "overlay.csv").string();
  csv_.open(csv_path);
  if (ec || !csv_) throw SessionError("--record " + dir_ + ": cannot create the folder or " + csv_path + " (check the path and permissions)");
  csv_ << csv_header() << "\n";
  files_.push_back(csv_path);
  const std::string tumour_path = (std::filesystem::path(dir_) / "tumour_Cam.bin").string();
  tumour_bin_.open(tumour_path, std::ios::binary);
  if (!tumour_bin_) throw SessionError("--record " + dir_ + ": cannot create " + tumour_path + " (check the path and permissions)");
  write_tumour_surface_header(tumour_bin_);
  files_.push_back(tumour_path);
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() {
  try {
    close();
  } catch (const std::exception&) {  // reported by an explicit close(); a destructor must not throw
  }
}

void Recorder::add(const FrameRow& row, cv::Mat frame) {
  std::lock_guard lock(mutex_);
  if (closing_) return;
  // Encoding slower than the camera (a loaded machine): the CSV row is always kept, the
  // video frame is skipped and counted rather than letting the queue grow without bound.
  if (queue_.size() >= kMaxQueuedFrames && !frame.empty()) {
    frame = cv::Mat();
    ++video_frames_skipped_;
  }
  queue_.emplace_back(row, std::move(frame));
  cv_.notify_one();
}

void Recorder::run() {
  for (;;) {
    std::pair<FrameRow, cv::Mat> item;
    {
      std::unique_lock lock(mutex_);
      cv_.wait(lock, [this] { return closing_ || !queue_.empty(); });
      if (queue_.empty()) return;
      item = std::move(queue_.front());
      queue_.pop_front();
    }
    const auto& [row, frame] = item;
    csv_ << csv_line(row) << "\n";
    if (row.tumour_surface_Cam) {
      const bool same_tris = row.tumour_surface_Cam->tris == last_tumour_tris_;
      write_tumour_surface(tumour_bin_, row.camera_sequence, *row.tumour_surface_Cam, !same_tris);
      if (!same_tris) last_tumour_tris_ = row.tumour_surface_Cam->tris;
    }
    if (!frame.empty()) {
      if (!writer_) {
        const std::string path = (std::filesystem::path(dir_) / "overlay.avi").string();
        writer_ = std::make_unique<cv::VideoWriter>(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), settings_.video_fps, frame.size());
        if (!writer_->isOpened()) error_ = "cannot open " + path + " for writing (OpenCV VideoWriter, MJPG)";
        else files_.push_back(path);
      }
      if (writer_->isOpened()) writer_->write(frame);
      if (static_cast<int>(thumbs_.size()) < settings_.contact_sheet_frames && row.capture_time_mono_us >= next_thumb_us_) {
        cv::Mat thumb;
        cv::resize(frame, thumb, cv::Size(320, std::max(1, 320 * frame.rows / frame.cols)), 0, 0, cv::INTER_AREA);
        thumbs_.push_back(thumb);
        next_thumb_us_ = row.capture_time_mono_us + static_cast<std::int64_t>(settings_.contact_sheet_every_s * 1e6);
      }
    }
  }
}

std::vector<std::string> Recorder::close() {
  {
    std::lock_guard lock(mutex_);
    if (closing_) return files_;
    closing_ = true;
    cv_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
  csv_.flush();
  tumour_bin_.flush();
  if (writer_) {
    writer_->release();
    writer_.reset();
  }
  if (!thumbs_.empty()) {
    const int cols = 4, rows = (static_cast<int>(thumbs_.size()) + cols - 1) / cols;
    const cv::Size t = thumbs_[0].size();
    cv::Mat sheet(rows * t.height, cols * t.width, CV_8UC3, cv::Scalar(0, 0, 0));
    for (std::size_t i = 0; i < thumbs_.size(); ++i) {
      if (thumbs_[i].size() != t) continue;
      thumbs_[i].copyTo(sheet(cv::Rect(static_cast<int>(i % cols) * t.width, static_cast<int>(i / cols) * t.height, t.width, t.height)));
    }
    const std::string path = (std::filesystem::path(dir_) / "contact_sheet.png").string();
    if (cv::imwrite(path, sheet)) files_.push_back(path);
  }
  if (!error_.empty()) throw SessionError("--record: " + error_);
  return files_;
}

}  // namespace arnav::host
