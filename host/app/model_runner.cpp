#include "host/app/model_runner.hpp"

#include <algorithm>
#include <chrono>
#include <set>
#include <stdexcept>

#include <sys/resource.h>
#include <unistd.h>

#include "host/overlay/overlay_geometry.hpp"
#include "host/sim/model_factory.hpp"
#include "protocol/clock.hpp"

namespace arnav::host {
namespace {

// Volume centroid of a closed, outward triangle surface (divergence theorem).
Eigen::Vector3d closed_centroid(const TriMesh& m) {
  double volume = 0.0;
  Eigen::Vector3d moment = Eigen::Vector3d::Zero();
  for (const auto& t : m.tris) {
    const Eigen::Vector3d a = m.positions_World_mm.col(t[0]), b = m.positions_World_mm.col(t[1]), c = m.positions_World_mm.col(t[2]);
    const double v = a.dot(b.cross(c)) / 6.0;
    volume += v;
    moment += v * (a + b + c) / 4.0;
  }
  return std::abs(volume) > 0 ? Eigen::Vector3d(moment / volume) : Eigen::Vector3d(m.positions_World_mm.rowwise().mean());
}

}  // namespace

ModelRunner::ModelRunner(const Scene& scene, double rate_hz, bool gravity, double margin_mm, int nice,
                         std::optional<cut::CutSessionSettings> cutting)
    : scene_(scene), rate_hz_(rate_hz), margin_mm_(margin_mm), nice_(nice) {
  if (cutting) {
    Scene copy = scene;
    if (!gravity) copy.problem.gravity_World_mm_s2.setZero();
    cut_ = cut::make_cut_session(copy, scene.model, *cutting);
  } else {
    SimProblem problem = scene.problem;
    if (!gravity) problem.gravity_World_mm_s2.setZero();
    model_ = make_tissue_model(problem, scene.model);
  }
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

void ModelRunner::set_scalpel(const std::optional<std::array<Eigen::Vector3d, 2>>& blade, bool cutting_enabled) {
  std::lock_guard lock(mutex_);
  scalpel_ = blade;
  cutting_enabled_ = cutting_enabled;
}

void ModelRunner::enable_grasper(const GrasperRole& role) {
  if (cut_) throw std::invalid_argument("a grasper cannot be coupled to a cutting model yet (host/cut has no attachment removal)");
  grasp_ = std::make_unique<GraspCoupling>(role, scene_);
}

void ModelRunner::set_grasper(const GraspCommand& cmd) {
  std::lock_guard lock(mutex_);
  grasp_cmd_ = cmd;
}

GraspStatus ModelRunner::grasp_status() const {
  std::lock_guard lock(mutex_);
  return grasp_status_;
}

std::shared_ptr<const ModelSnapshot> ModelRunner::snapshot_at(std::int64_t device_time_us) const {
  std::lock_guard lock(mutex_);
  if (!grasp_ || recent_.empty()) return snapshot_;
  for (auto it = recent_.rbegin(); it != recent_.rend(); ++it)
    if ((*it)->grasper_device_time_us <= device_time_us) return *it;
  return recent_.front();
}

std::vector<ModelCutEvent> ModelRunner::events(std::size_t from) const {
  std::lock_guard lock(mutex_);
  return from < events_.size() ? std::vector<ModelCutEvent>(events_.begin() + static_cast<std::ptrdiff_t>(from), events_.end())
                               : std::vector<ModelCutEvent>{};
}

std::vector<CutStepRecord> ModelRunner::cut_steps(std::size_t from) const {
  std::lock_guard lock(mutex_);
  return from < cut_steps_.size() ? std::vector<CutStepRecord>(cut_steps_.begin() + static_cast<std::ptrdiff_t>(from), cut_steps_.end())
                                  : std::vector<CutStepRecord>{};
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
  std::vector<ModelCutEvent> new_events;
  std::optional<CutStepRecord> cut_record;
  if (now_us >= 0) {
    const auto t0 = std::chrono::steady_clock::now();
    StepSummary s;
    if (cut_) {
      std::optional<std::array<Eigen::Vector3d, 2>> blade;
      bool enabled = false;
      {
        std::lock_guard lock(mutex_);
        blade = scalpel_;
        enabled = cutting_enabled_;
      }
      if (blade) {
        const bool cuts = enabled && !blade_gap_;
        const cut::CutFrameReport cr = cut_->apply_blade(cut::BladeSegment{(*blade)[0], (*blade)[1]}, cuts);
        if (cuts && previous_blade_) {
          cut::SweptSurface sweep;
          sweep.from = {(*previous_blade_)[0], (*previous_blade_)[1]};
          sweep.to = {(*blade)[0], (*blade)[1]};
          sweep.strips = 8;
          if (!sweep.degenerate(1e-6)) {
            Sweep sw;
            sw.tris = sweep.triangles();
            for (const auto& t : sw.tris) {
              sw.box.extend(t.a);
              sw.box.extend(t.b);
              sw.box.extend(t.c);
            }
            sweeps_.push_back(std::move(sw));
            if (sweeps_.size() > static_cast<std::size_t>(600 * rate_hz_)) sweeps_.pop_front();
          }
        }
        previous_blade_ = blade;
        blade_gap_ = false;
        for (const auto& e : cr.events) new_events.push_back({0, now_us, e});
        if (cr.cut.vertices_snapped > 0) cut_marks_changed_ = true;
        if (cr.cut.topology_changed) {
          cut_record = CutStepRecord{};
          cut_record->cutter_path_error_mm = cr.cut.max_path_deviation_mm;
          cut_record->update_ms = cr.cut.update_ms;
          cut_record->rebuild_ms = cr.rebuild_ms;
          cut_record->tets_cut = cr.cut.tets_cut;
        }
      } else {
        blade_gap_ = true;
        previous_blade_.reset();
      }
      s = cut_->step(1.0 / rate_hz_);
    } else {
      if (grasp_) {
        GraspCommand cmd;
        {
          std::lock_guard lock(mutex_);
          cmd = grasp_cmd_;
        }
        grasp_->apply(*model_, cmd, now_us);
        grasper_device_time_us_ = cmd.device_time_us;
        std::lock_guard lock(mutex_);
        grasp_status_ = grasp_->status();
      }
      s = model_->step(1.0 / rate_hz_);
    }
    snap->step_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    snap->healthy = s.healthy;
    snap->warning = s.warning;
  }
  if (cut_) {
    // The cut volume: its boundary (cut faces included) is the organ drawn; the tumours and
    // vessels are carried through the cuts by the cut session.
    const Eigen::Matrix3Xd x = cut_->positions_World_mm();
    const TetMesh& mesh = cut_->mesh();
    const auto& surface = cut_->surface_tris();
    snap->cutting = true;
    snap->organ.tris = surface;
    snap->organ.positions_World_mm = x;
    if (cut_->surface_version() != cut_surface_version_ || cut_marks_changed_) {
      // The boundary changed: its cut faces (all three vertices on a cut), the path error of
      // the vertices new on them, and the rim (cut-face edges shared with an uncut face).
      cut_surface_version_ = cut_->surface_version();
      cut_marks_changed_ = false;
      const auto& c = cut_->cutter();
      cut_face_tris_.clear();
      for (const auto& f : surface)
        if (c.on_cut(f[0]) && c.on_cut(f[1]) && c.on_cut(f[2])) cut_face_tris_.push_back(f);
      on_cut_face_.resize(static_cast<std::size_t>(x.cols()), 0);
      double worst = -1.0;
      int fresh = 0;
      for (const auto& f : cut_face_tris_)
        for (int v : f) {
          if (on_cut_face_[static_cast<std::size_t>(v)]) continue;
          on_cut_face_[static_cast<std::size_t>(v)] = 1;
          ++fresh;
          double best = 1e300;
          const Eigen::Vector3d p = x.col(v);
          for (auto it = sweeps_.rbegin(); it != sweeps_.rend(); ++it) {
            if (it->box.exteriorDistance(p) >= best) continue;  // newest first: the bound tightens fast
            for (const auto& t : it->tris) best = std::min(best, cut::point_triangle_distance(p, t));
          }
          if (best < 1e299) worst = std::max(worst, best);
        }
      if (fresh > 0 && worst >= 0.0) {
        if (!cut_record) cut_record = CutStepRecord{};
        cut_record->path_error_mm = worst;
        cut_record->new_cut_vertices = fresh;
      }
      cut_rim_.clear();
      if (!cut_face_tris_.empty()) {
        std::set<std::pair<int, int>> outer;
        const auto key = [](int a, int b) { return std::make_pair(std::min(a, b), std::max(a, b)); };
        for (const auto& f : surface)
          if (!(c.on_cut(f[0]) && c.on_cut(f[1]) && c.on_cut(f[2])))
            for (int e = 0; e < 3; ++e) outer.insert(key(f[e], f[(e + 1) % 3]));
        std::set<std::pair<int, int>> rim;
        for (const auto& f : cut_face_tris_)
          for (int e = 0; e < 3; ++e)
            if (const auto k = key(f[e], f[(e + 1) % 3]); outer.count(k)) rim.insert(k);
        cut_rim_.assign(rim.begin(), rim.end());
      }
    }
    TriMesh cut_faces;
    cut_faces.positions_World_mm = x;
    cut_faces.tris = cut_face_tris_;
    double area2 = 0.0;
    for (const auto& f : cut_faces.tris) area2 += (x.col(f[1]) - x.col(f[0])).cross(x.col(f[2]) - x.col(f[0])).norm();
    for (const auto& [a, b] : cut_rim_) snap->cut_rim_mm.push_back({x.col(a), x.col(b)});
    snap->cut_faces = static_cast<int>(cut_faces.tris.size());
    snap->cut_area_mm2 = 0.25 * area2;  // half of each face's |cross|, half of the faces (two sides)
    if (!cut_faces.tris.empty()) snap->cut_surface = std::move(cut_faces);
    for (std::size_t i = 0; i < cut_->tumours().size(); ++i) {
      TriMesh t;
      t.tris = scene_.tumours[i].rest.tris;
      t.positions_World_mm = cut_->tumours()[i].embedding.apply(mesh, x);
      snap->margins.push_back(overlay::offset_surface(t, margin_mm_));
      snap->tumour_centroids_mm.push_back(closed_centroid(t));
      snap->tumours.push_back(std::move(t));
    }
    if (scene_.vessels && cut_->vessels()) {
      VesselTree v = scene_.vessels->rest;
      v.nodes_World_mm = cut_->vessels()->embedding.apply(mesh, x);
      snap->vessels = std::move(v);
    }
    snap->volume_positions_mm = x;
  } else {
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
  }
  snap->step_done_mono_us = now_us;
  std::lock_guard lock(mutex_);
  snap->step = steps_.load() + (now_us >= 0 ? 1 : 0);
  for (auto& e : new_events) {
    e.step = snap->step;
    events_.push_back(std::move(e));
  }
  if (cut_record) {
    cut_record->step = snap->step;
    cut_steps_.push_back(*cut_record);
  }
  snap->events_total = static_cast<std::int64_t>(events_.size());
  snap->cut_steps_total = static_cast<std::int64_t>(cut_steps_.size());
  if (now_us >= 0) {
    ++steps_;
    step_ms_.push_back(snap->step_ms);
  }
  if (grasp_) {
    snap->grasper_device_time_us = grasper_device_time_us_;
    recent_.push_back(snap);
    while (recent_.size() > static_cast<std::size_t>(rate_hz_) + 1) recent_.pop_front();
  }
  snapshot_ = std::move(snap);
}

}  // namespace arnav::host
