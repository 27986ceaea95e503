#include "host/igtl/bridge.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "protocol/pose_convert.hpp"

namespace arnav::igtl {

Bridge::Bridge(BridgeOptions options, Server& server, Server::Log log)
    : options_(std::move(options)), server_(server), log_(std::move(log)), image_thread_([this] { image_loop(); }) {}

Bridge::~Bridge() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  image_wake_.notify_all();
  image_thread_.join();
}

BridgeStats Bridge::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

const std::string* Bridge::device_name(const std::string& tool, const std::string& child, const std::string& parent) {
  const std::string key = tool + "|" + child + "|" + parent;
  if (auto it = names_.find(key); it != names_.end()) return &it->second;
  if (unnamed_.count(key)) return nullptr;
  std::string why;
  std::optional<std::string> name = transform_device_name(child, parent, why);
  if (name) return &names_.emplace(key, *name).first->second;
  unnamed_.insert(key);
  log_("tool " + tool + ": not sent: " + why);
  return nullptr;
}

void Bridge::on_pose(const tool_pose_t& pose) {
  std::lock_guard lock(mutex_);  // stats_ (uncontended: the image thread takes it briefly)
  ++stats_.poses;
  std::vector<TrackedElement> elements;
  if (pose.status != tool_pose_t::STATUS_VALID) {
    ++stats_.not_seen;  // Slicer's watchdog shows the tool stale: never resend a last pose as valid
  } else {
    const auto named = options_.device_names.find(pose.tool_name);
    const std::string* name =
        named != options_.device_names.end() ? &named->second : device_name(pose.tool_name, pose.tool_name, pose.frame_parent);
    if (name == nullptr) {
      ++stats_.unnamed;
    } else {
      const Eigen::Isometry3d X_ParentTool = get_pose(pose);
      elements.push_back({*name, X_ParentTool});
      if (auto tip = options_.tips_Tool_mm.find(pose.tool_name); tip != options_.tips_Tool_mm.end()) {
        Eigen::Isometry3d X_ParentTip = X_ParentTool;
        X_ParentTip.translate(tip->second);
        if (const std::string* tip_name = device_name(pose.tool_name + "#tip", pose.tool_name + "_tip", pose.frame_parent))
          elements.push_back({*tip_name, X_ParentTip});
      }
      for (const auto& e : elements) {
        server_.publish(e.name, pack_transform(e.name, e.X_ParentChild_mm, pose.receive_time_wall_us));
        ++stats_.transforms;
      }
    }
  }
  add_to_frame(pose, elements);
}

// One TDATA per tracker frame: the frame is complete when as many poses of this source
// arrived as in its previous frame (no wait in steady state), or when the next frame starts.
void Bridge::add_to_frame(const tool_pose_t& pose, const std::vector<TrackedElement>& elements) {
  FrameGroup& g = frames_[pose.source];
  if (g.open && g.frame_number != pose.device_frame_number) send_tdata(g);
  if (!g.open) {
    g.open = true;
    g.frame_number = pose.device_frame_number;
    g.wall_us = pose.receive_time_wall_us;
    g.poses_seen = 0;
    g.elements.clear();
  }
  ++g.poses_seen;
  g.elements.insert(g.elements.end(), elements.begin(), elements.end());
  if (g.poses_expected > 0 && g.poses_seen >= g.poses_expected) send_tdata(g);
}

void Bridge::send_tdata(FrameGroup& g) {
  g.open = false;
  g.poses_expected = g.poses_seen;
  if (g.elements.empty()) return;
  server_.publish_tdata(options_.tdata_device_name, pack_tdata(options_.tdata_device_name, g.elements, g.wall_us));
  ++stats_.tdata;
}

void Bridge::flush() {
  std::lock_guard lock(mutex_);
  for (auto& [source, g] : frames_)
    if (g.open) send_tdata(g);
}

void Bridge::on_frame(const image_frame_t& frame) {
  {
    std::lock_guard lock(mutex_);
    ++stats_.frames;
    if (options_.image_rate_hz > 0.0 && last_image_capture_us_ != 0 &&
        static_cast<double>(frame.capture_time_mono_us - last_image_capture_us_) < 1e6 / options_.image_rate_hz) {
      ++stats_.frames_rate_limited;
      return;
    }
    last_image_capture_us_ = frame.capture_time_mono_us;
    if (next_frame_) ++stats_.frames_replaced;
    next_frame_ = frame;
  }
  image_wake_.notify_one();
}

void Bridge::on_surface(const surface_mesh_t& mesh) {
  {
    std::lock_guard lock(mutex_);
    ++stats_.surfaces;
    auto [it, inserted] = next_surfaces_.insert_or_assign(mesh.name, mesh);
    if (!inserted) ++stats_.surfaces_replaced;
  }
  image_wake_.notify_one();
}

// Camera frames and surfaces, the latest of each; surfaces first (packing one takes far
// less than decoding a frame).
void Bridge::image_loop() {
  for (;;) {
    std::optional<image_frame_t> frame;
    std::vector<surface_mesh_t> surfaces;
    {
      std::unique_lock lock(mutex_);
      image_wake_.wait(lock, [&] { return stopping_ || next_frame_.has_value() || !next_surfaces_.empty(); });
      if (stopping_) return;
      for (auto& [name, mesh] : next_surfaces_) surfaces.push_back(std::move(mesh));
      next_surfaces_.clear();
      frame.swap(next_frame_);
    }
    for (const auto& mesh : surfaces) send_surface(mesh);
    if (frame) send_image(*frame);
  }
}

std::optional<Packet> polydata_from_surface(const surface_mesh_t& mesh, std::string& device_name, std::string& why) {
  device_name = plus_frame_name(mesh.name);
  if (mesh.frame_name != "Ref") {
    why = "its vertices are in frame '" + mesh.frame_name + "', arnav-igtl serves surfaces in Ref (the reference tool's frame)";
    return std::nullopt;
  }
  if (device_name.empty() || device_name.size() > kMaxDeviceNameChars) {
    why = "name '" + mesh.name + "' gives no OpenIGTLink device name of 1..20 characters";
    return std::nullopt;
  }
  if (mesh.num_vertices < 0 || static_cast<std::size_t>(mesh.num_vertices) != mesh.positions_mm.size() || mesh.num_triangles < 0 ||
      static_cast<std::size_t>(mesh.num_triangles) != mesh.triangles.size()) {
    why = "counts (" + std::to_string(mesh.num_vertices) + " vertices, " + std::to_string(mesh.num_triangles) +
          " triangles) disagree with its arrays";
    return std::nullopt;
  }
  std::vector<std::array<float, 3>> points(mesh.positions_mm.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto& p = mesh.positions_mm[i];
    if (p.size() != 3 || !std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      why = "vertex " + std::to_string(i) + " is not a finite 3D position";
      return std::nullopt;
    }
    points[i] = {p[0], p[1], p[2]};
  }
  std::vector<std::array<std::uint32_t, 3>> triangles(mesh.triangles.size());
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    const auto& t = mesh.triangles[i];
    for (std::size_t k = 0; k < 3; ++k) {
      if (t.size() != 3 || t[k] < 0 || t[k] >= mesh.num_vertices) {
        why = "triangle " + std::to_string(i) + " indexes a vertex out of 0.." + std::to_string(mesh.num_vertices - 1);
        return std::nullopt;
      }
      triangles[i][k] = static_cast<std::uint32_t>(t[k]);
    }
  }
  const std::int64_t wall_us = mesh.model_step_wall_us > 0 ? mesh.model_step_wall_us : mesh.publish_time_wall_us;
  return pack_polydata(device_name, points, triangles, wall_us);
}

void Bridge::send_surface(const surface_mesh_t& mesh) {
  std::string device_name, why;
  const auto t0 = std::chrono::steady_clock::now();
  const std::optional<Packet> packet = polydata_from_surface(mesh, device_name, why);
  const double pack_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!packet) {
    const bool first = surface_reported_.insert(mesh.name).second;
    if (first) log_("surface '" + mesh.name + "' (ARNAV_SURFACE_" + mesh.name + "): not sent: " + why + " (reported once per name)");
    std::lock_guard lock(mutex_);
    ++stats_.surfaces_rejected;
    return;
  }
  server_.publish_polydata(device_name, *packet);
  std::lock_guard lock(mutex_);
  ++stats_.polydata;
  stats_.polydata_pack_ms_total += pack_ms;
  stats_.polydata_pack_ms_max = std::max(stats_.polydata_pack_ms_max, pack_ms);
}

// Decoded at the reduced size directly when the downscale is 2, 4 or 8 (libjpeg scales in
// the DCT: several times faster than decoding in full and resizing).
void Bridge::send_image(const image_frame_t& frame) {
  const int d = options_.image_downscale;
  const int flags = d == 2 ? cv::IMREAD_REDUCED_COLOR_2 : d == 4 ? cv::IMREAD_REDUCED_COLOR_4 : d == 8 ? cv::IMREAD_REDUCED_COLOR_8 : cv::IMREAD_COLOR;
  cv::Mat bgr;
  if (frame.size > 0 && static_cast<std::size_t>(frame.size) == frame.data.size())
    bgr = cv::imdecode(cv::Mat(1, frame.size, CV_8UC1, const_cast<std::uint8_t*>(frame.data.data())), flags);
  if (bgr.empty()) {
    std::lock_guard lock(mutex_);
    if (stats_.frames_undecodable++ == 0)
      log_("camera " + frame.camera_name + ": frame " + std::to_string(frame.sequence) + " cannot be decoded (encoding " +
           std::to_string(frame.encoding) + ", " + std::to_string(frame.size) + " bytes): no IMAGE sent (reported once)");
    return;
  }
  if (flags == cv::IMREAD_COLOR && d > 1)
    cv::resize(bgr, bgr, cv::Size(bgr.cols / d, bgr.rows / d), 0, 0, cv::INTER_AREA);
  cv::Mat rgb;
  cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
  if (!rgb.isContinuous()) rgb = rgb.clone();
  server_.publish(options_.image_device_name,
                  pack_image_rgb(options_.image_device_name, rgb.cols, rgb.rows, rgb.data, frame.capture_time_wall_us));
  std::lock_guard lock(mutex_);
  ++stats_.images;
}

}  // namespace arnav::igtl
