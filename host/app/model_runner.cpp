#include "host/app/model_runner.hpp"

#include <chrono>

#include <sys/resource.h>
#include <unistd.h>

#include "host/overlay/overlay_geometry.hpp"
#include "host/sim/model_factory.hpp"
#include "protocol/clock.hpp"

namespace arnav::host {

ModelRunner::ModelRunner(const Scene& scene, double rate_hz, bool gravity, double margin_mm, int nice)
    : scene_(scene), rate_hz_(rate_hz), margin_mm_(margin_mm), nice_(nice) {
  SimProblem problem = scene.problem;
  if (!gravity) problem.gravity_World_mm_s2.setZero();
  model_ = make_tissue_model(problem, scene.model);
  step_once(-1);  // the rest state, before the first step
  steps_ = 0;
  step_ms_.clear();
}

ModelRunner::~ModelRunner() { stop(); }

void ModelRunner::start() {
  stop_ = false;
  thread_ = std::thread([this] {
    // The overlay's latency matters more than the model's rate: on a machine with few
    // cores the model thread (and the solver threads it starts) yields to rendering.
    if (nice_ > 0) setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), nice_);
    const auto period = std::chrono::duration<double>(1.0 / rate_hz_);
    auto next = std::chrono::steady_clock::now();
    while (!stop_.load()) {
      step_once(monotonic_us());
      next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
      const auto now = std::chrono::steady_clock::now();
      if (next < now) next = now;  // overrun: no catch-up burst
      std::unique_lock lock(mutex_);
      cv_.wait_until(lock, next, [this] { return stop_.load(); });
    }
  });
}

void ModelRunner::stop() {
  stop_ = true;
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

int ModelRunner::advance_to(std::int64_t now_us, int max_steps) {
  const auto period_us = static_cast<std::int64_t>(1e6 / rate_hz_);
  if (next_step_us_ < 0) next_step_us_ = now_us;
  int done = 0;
  while (next_step_us_ <= now_us && done < max_steps) {
    step_once(next_step_us_);
    next_step_us_ += period_us;
    ++done;
  }
  if (next_step_us_ <= now_us) next_step_us_ = now_us + period_us;  // behind: drop the backlog
  return done;
}

void ModelRunner::set_scalpel(const std::optional<std::array<Eigen::Vector3d, 2>>& blade) {
  std::lock_guard lock(mutex_);
  scalpel_ = blade;
}

std::shared_ptr<const ModelSnapshot> ModelRunner::snapshot() const {
  std::lock_guard lock(mutex_);
  return snapshot_;
}

std::vector<double> ModelRunner::step_times_ms() const {
  std::lock_guard lock(mutex_);
  return step_ms_;
}

void ModelRunner::step_once(std::int64_t now_us) {
  auto snap = std::make_shared<ModelSnapshot>();
  if (now_us >= 0) {
    // Cutting/contact stage (host/cut) goes here: scalpel_ -> attachments and cuts.
    const auto t0 = std::chrono::steady_clock::now();
    const StepSummary s = model_->step(1.0 / rate_hz_);
    snap->step_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    snap->healthy = s.healthy;
    snap->warning = s.warning;
  }
  const Eigen::Matrix3Xd& x = model_->positions_World_mm();
  const TetMesh& mesh = scene_.problem.mesh;
  snap->organ.tris = scene_.organ_surface.tris;
  snap->organ.positions_World_mm = scene_.organ_embedding.apply(mesh, x);
  for (std::size_t i = 0; i < scene_.tumours.size(); ++i) {
    TriMesh t;
    t.tris = scene_.tumours[i].rest.tris;
    t.positions_World_mm = scene_.tumours[i].embedding.apply(mesh, x);
    snap->margins.push_back(overlay::offset_surface(t, margin_mm_));
    snap->tumours.push_back(std::move(t));
    snap->tumour_centroids_mm.push_back(tumour_centroid_World_mm(scene_, static_cast<int>(i), x));
  }
  if (scene_.vessels) {
    VesselTree v = scene_.vessels->rest;
    v.nodes_World_mm = scene_.vessels->embedding.apply(mesh, x);
    snap->vessels = std::move(v);
  }
  snap->volume_positions_mm = x;
  snap->step_done_mono_us = now_us;
  std::lock_guard lock(mutex_);
  snap->step = steps_.load() + (now_us >= 0 ? 1 : 0);
  if (now_us >= 0) {
    ++steps_;
    step_ms_.push_back(snap->step_ms);
  }
  snapshot_ = std::move(snap);
}

}  // namespace arnav::host
