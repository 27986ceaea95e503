#include "host/app/model_runner.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <stdexcept>

#include <sys/resource.h>
#include <unistd.h>

#include "host/app/cpu_partition.hpp"
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
    // A core of its own (cpu_partition): the solver's workers started from here inherit it.
    if (!cpus_.empty()) {
      const std::string e = pin_current_thread(cpus_);  // refused (cgroup): the scheduler places it, reported in the summary
      std::lock_guard lock(mutex_);
      pin_error_ = e;
    }
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

std::string ModelRunner::pin_error() const {
  std::lock_guard lock(mutex_);
  return pin_error_;
}

std::vector<double> ModelRunner::step_times_ms() const {
  std::lock_guard lock(mutex_);
  return step_ms_;
}

void ModelRunner::record_material_sweep(const cut::SweptSurface& sweep) {
  cut::TetCutter& cutter = cut_->cutter();
  const Eigen::Matrix3Xd x = cut_->positions_World_mm();
  const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
  // The pull-back is affine per tet; over a blade segment that spans tets of different
  // strain (the tissue the blade pushed before cutting, a grasp nearby) the segment's image
  // is curved: the lines are resampled every ~1 mm (at most 64 segments) so the chords stay on it.
  const int strips = sweep.strips;
  const double length = (sweep.to.heel_World_mm - sweep.to.tip_World_mm).norm();
  const int n = std::clamp(static_cast<int>(std::ceil(length / 1.0)), strips, 64);
  const bool carried = sweep.from_points.size() == static_cast<std::size_t>(strips + 1);
  // The blade's start (carried with the tissue) and end lines, tip first: 2 (n + 1) points.
  std::vector<Eigen::Vector3d> p(static_cast<std::size_t>(2 * (n + 1)));
  for (int i = 0; i <= n; ++i) {
    const double u = static_cast<double>(i) / n;
    if (carried) {
      const double f = u * strips;
      const int j = std::min(static_cast<int>(std::floor(f)), strips - 1);
      const double a = f - j;
      p[static_cast<std::size_t>(i)] = (1 - a) * sweep.from_points[static_cast<std::size_t>(j)] + a * sweep.from_points[static_cast<std::size_t>(j + 1)];
    } else {
      p[static_cast<std::size_t>(i)] = (1 - u) * sweep.from.tip_World_mm + u * sweep.from.heel_World_mm;
    }
    p[static_cast<std::size_t>(n + 1 + i)] = (1 - u) * sweep.to.tip_World_mm + u * sweep.to.heel_World_mm;
  }
  // Pull back: rest = the barycentric combination of the rest positions of the tet holding
  // the point now; a point outside the tissue (or in the opening of a cut) keeps the
  // displacement of the nearest mapped point of its line (the blade's part outside the
  // organ cuts nothing).
  std::vector<Eigen::Vector3d> r(p.size());
  std::vector<char> mapped(p.size(), 0);
  bool refit = true;
  for (std::size_t k = 0; k < p.size(); ++k) {
    Eigen::Vector4d w;
    const int t = cutter.locate(p[k], x, w, refit);
    refit = false;
    if (t < 0 || w.minCoeff() < -1e-6) continue;  // outside the tissue (or in a cut's opening)
    const auto& tet = cutter.mesh().tets[static_cast<std::size_t>(t)];
    r[k].setZero();
    for (int j = 0; j < 4; ++j) r[k] += w[j] * rest.col(tet[static_cast<std::size_t>(j)]);
    mapped[k] = 1;
  }
  for (int line = 0; line < 2; ++line) {
    const int base = line * (n + 1);
    for (int i = 0; i <= n; ++i) {
      const auto k = static_cast<std::size_t>(base + i);
      if (mapped[k]) continue;
      int nearest = -1;
      for (int j = 0; j <= n; ++j)
        if (mapped[static_cast<std::size_t>(base + j)] && (nearest < 0 || std::abs(j - i) < std::abs(nearest - i))) nearest = j;
      if (nearest < 0) return;  // a whole line outside the tissue: nothing swept in the material
      const auto m = static_cast<std::size_t>(base + nearest);
      r[k] = p[k] + (r[m] - p[m]);
    }
  }
  Sweep sw;
  for (int i = 0; i < n; ++i) {
    const auto f0 = static_cast<std::size_t>(i), f1 = f0 + 1, t0 = static_cast<std::size_t>(n + 1 + i), t1 = t0 + 1;
    sw.tris.push_back({r[f0], r[f1], r[t0]});
    sw.tris.push_back({r[f1], r[t1], r[t0]});
  }
  for (const auto& t : sw.tris) {
    sw.box.extend(t.a);
    sw.box.extend(t.b);
    sw.box.extend(t.c);
  }
  sweeps_.push_back(std::move(sw));
  if (sweeps_.size() > static_cast<std::size_t>(120 * rate_hz_)) sweeps_.pop_front();  // two minutes of cutting
}

int ModelRunner::measure_new_cut_vertices(double& worst_mm) {
  const cut::TetCutter& cutter = cut_->cutter();
  const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
  on_cut_seen_.resize(static_cast<std::size_t>(rest.cols()), 0);
  int fresh = 0;
  worst_mm = -1.0;
  for (Eigen::Index v = 0; v < rest.cols(); ++v) {
    if (on_cut_seen_[static_cast<std::size_t>(v)] || !cutter.on_cut(static_cast<int>(v))) continue;
    on_cut_seen_[static_cast<std::size_t>(v)] = 1;
    ++fresh;
    double best = 1e300;
    const Eigen::Vector3d p = rest.col(v);
    for (auto it = sweeps_.rbegin(); it != sweeps_.rend(); ++it) {
      if (it->box.exteriorDistance(p) >= best) continue;  // newest first: the bound tightens fast
      for (const auto& t : it->tris) best = std::min(best, cut::point_triangle_distance(p, t));
    }
    if (best < 1e299) worst_mm = std::max(worst_mm, best);
  }
  return fresh;
}

void ModelRunner::apply_grasp(GraspBody& body, std::int64_t now_us) {
  GraspCommand cmd;
  {
    std::lock_guard lock(mutex_);
    cmd = grasp_cmd_;
  }
  grasp_->apply(body, cmd, now_us);
  grasper_device_time_us_ = cmd.device_time_us;
  std::lock_guard lock(mutex_);
  grasp_status_ = grasp_->status();
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
        // Cut-path fidelity, in the material: the surface this frame's blade swept (as the
        // cutter used it), pulled back into the rest configuration at this instant; every
        // vertex put on the cut is compared with those surfaces at its rest position (below).
        if (cuts && cut_->last_sweep()) record_material_sweep(*cut_->last_sweep());
        if (cr.cut.topology_changed || cr.cut.vertices_snapped > 0) {
          double worst = -1.0;
          const int fresh = measure_new_cut_vertices(worst);
          if (fresh > 0) {
            cut_path_.emplace_back(fresh, worst);
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
        if (!cut_path_.empty()) {
          if (!cut_record) cut_record = CutStepRecord{};
          cut_record->new_cut_vertices = cut_path_.back().first;
          cut_record->path_error_mm = cut_path_.back().second;
          cut_path_.clear();
        }
      } else {
        blade_gap_ = true;
        previous_blade_.reset();
      }
      if (grasp_) {  // after the blade: the grasp holds the tissue as the cut left it
        cut::CutSession& session = *cut_;
        CutSessionBody body(session);
        apply_grasp(body, now_us);
      }
      s = cut_->step(1.0 / rate_hz_);
    } else {
      if (grasp_) {
        TissueModelBody body(*model_);
        apply_grasp(body, now_us);
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
      // The boundary changed (or vertices were put on the cut): its cut faces (all three
      // vertices on a cut) and the rim (cut-face edges shared with an uncut face), found
      // again only then, not every step.
      cut_surface_version_ = cut_->surface_version();
      cut_marks_changed_ = false;
      const auto& c = cut_->cutter();
      cut_face_tris_.clear();
      for (const auto& f : surface)
        if (c.on_cut(f[0]) && c.on_cut(f[1]) && c.on_cut(f[2])) cut_face_tris_.push_back(f);
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
      t.tris = cut_->tumour_tris()[i];  // split along the cut (closed again)
      t.positions_World_mm = cut_->tumours()[i].embedding.apply(mesh, x);
      snap->margins.push_back(overlay::offset_surface(t, margin_mm_));
      snap->tumour_centroids_mm.push_back(closed_centroid(t));
      snap->tumours.push_back(std::move(t));
    }
    if (scene_.vessels && cut_->vessels()) {
      VesselTree v;  // split along the cut: new nodes take the radius of the node they came from
      v.nodes_World_mm = cut_->vessels()->embedding.apply(mesh, x);
      v.segments = cut_->vessel_segments();
      for (int src : cut_->vessel_node_source()) v.radius_mm.push_back(scene_.vessels->rest.radius_mm[static_cast<std::size_t>(src)]);
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
