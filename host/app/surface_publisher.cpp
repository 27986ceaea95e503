#include "host/app/surface_publisher.hpp"

#include <algorithm>
#include <chrono>

#include "host/app/cpu_partition.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "protocol/channels.hpp"
#include "protocol/clock.hpp"

namespace arnav::host {
namespace {

// The triangles' vertices only (a cut volume's surface indexes the whole tet mesh), in Ref.
surface_mesh_t to_message(const std::string& name, const TriMesh& mesh, const Eigen::Isometry3d& X_RefModel, const overlay::Rgba& colour) {
  surface_mesh_t m;
  m.name = name;
  m.frame_name = "Ref";
  std::vector<std::int32_t> new_index(static_cast<std::size_t>(mesh.positions_World_mm.cols()), -1);
  m.triangles.reserve(mesh.tris.size());
  for (const auto& t : mesh.tris) {
    std::vector<std::int32_t> tri(3);
    for (std::size_t k = 0; k < 3; ++k) {
      std::int32_t& id = new_index[static_cast<std::size_t>(t[k])];
      if (id < 0) {
        id = static_cast<std::int32_t>(m.positions_mm.size());
        const Eigen::Vector3d p_Ref = X_RefModel * mesh.positions_World_mm.col(t[k]);
        m.positions_mm.push_back({static_cast<float>(p_Ref.x()), static_cast<float>(p_Ref.y()), static_cast<float>(p_Ref.z())});
      }
      tri[k] = id;
    }
    m.triangles.push_back(std::move(tri));
  }
  m.num_vertices = static_cast<std::int32_t>(m.positions_mm.size());
  m.num_triangles = static_cast<std::int32_t>(m.triangles.size());
  m.rgba[0] = colour.r;
  m.rgba[1] = colour.g;
  m.rgba[2] = colour.b;
  m.rgba[3] = colour.a;
  return m;
}

}  // namespace

std::vector<surface_mesh_t> surface_messages(const ModelSnapshot& snap, const Eigen::Isometry3d& X_RefModel, std::int64_t step_wall_us,
                                             std::int64_t publish_wall_us) {
  const overlay::OverlayStyle style;
  std::vector<surface_mesh_t> out;
  out.push_back(to_message("organ", snap.organ, X_RefModel, style.organ_veil));
  for (std::size_t i = 0; i < snap.tumours.size(); ++i)
    out.push_back(to_message(i == 0 ? "tumour" : "tumour" + std::to_string(i + 1), snap.tumours[i], X_RefModel, style.tumour));
  if (snap.cut_surface && !snap.cut_surface->tris.empty()) out.push_back(to_message("cut", *snap.cut_surface, X_RefModel, style.cut));
  for (auto& m : out) {
    m.model_time_us = snap.step_device_time_us;
    m.model_step = snap.step;
    m.model_step_wall_us = step_wall_us;
    m.publish_time_wall_us = publish_wall_us;
  }
  return out;
}

SurfacePublisher::SurfacePublisher(double rate_hz, Source source, Sink sink, std::vector<int> cpus, std::int64_t model_started_mono_us)
    : rate_hz_(rate_hz),
      source_(std::move(source)),
      sink_(std::move(sink)),
      cpus_(std::move(cpus)),
      model_started_mono_us_(model_started_mono_us >= 0 ? model_started_mono_us : monotonic_us()),
      thread_([this] { loop(); }) {}

std::string SurfacePublisher::pin_error() const {
  std::lock_guard lock(mutex_);
  return pin_error_;
}

SurfacePublisher::~SurfacePublisher() { stop(); }

void SurfacePublisher::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
}

SurfacePublisherStats SurfacePublisher::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

void SurfacePublisher::loop() {
  if (!cpus_.empty()) {
    const std::string e = pin_current_thread(cpus_);
    std::lock_guard lock(mutex_);
    pin_error_ = e;
  }
  const auto period = std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / rate_hz_));
  auto next = std::chrono::steady_clock::now();
  for (;;) {
    {
      std::unique_lock lock(mutex_);
      if (wake_.wait_until(lock, next, [&] { return stopping_; })) return;
    }
    publish_round();
    next += period;
    if (const auto now = std::chrono::steady_clock::now(); next < now) next = now;  // late: no burst to catch up
  }
}

void SurfacePublisher::publish_round() {
  const SurfaceSource src = source_();
  if (!src.snapshot || !src.X_RefModel) {
    std::lock_guard lock(mutex_);
    ++stats_.rounds;
    ++stats_.rounds_unregistered;
    return;
  }
  const auto t0 = std::chrono::steady_clock::now();
  const std::int64_t wall_now = wall_us();
  // The step's UTC time (when the host ran it), mapped once per step: a step published again
  // keeps its time stamp. The rest state (step_done_mono_us -1) holds from the model's start
  // until the first step: it carries the start (not the publish time, which could be later
  // than the first step's own time while that step is still being computed).
  const bool new_step = src.snapshot->step != last_step_;
  if (new_step) {
    last_step_ = src.snapshot->step;
    const std::int64_t mono = src.snapshot->step_done_mono_us >= 0 ? src.snapshot->step_done_mono_us : model_started_mono_us_;
    last_step_wall_us_ = mono + (wall_now - monotonic_us());
  }
  const std::int64_t step_wall_us = last_step_wall_us_;
  std::vector<surface_mesh_t> messages = surface_messages(*src.snapshot, *src.X_RefModel, step_wall_us, wall_now);
  const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  std::int64_t sent = 0, failed = 0;
  for (auto& m : messages) {
    const std::string channel = channels::surface(m.name);
    m.sequence = ++sequence_[channel];
    ++(sink_(channel, m) ? sent : failed);
  }
  std::lock_guard lock(mutex_);
  ++stats_.rounds;
  stats_.model_steps += new_step ? 1 : 0;
  stats_.messages += sent;
  stats_.publish_failures += failed;
  stats_.build_ms_max = std::max(stats_.build_ms_max, build_ms);
}

}  // namespace arnav::host
