#include "host/app/model_runner.hpp"

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstring>
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
                         std::optional<cut::CutSessionSettings> cutting, const ModelClockSettings& clock)
    : scene_(scene),
      rate_hz_(rate_hz),
      margin_mm_(margin_mm),
      nice_(nice),
      clock_(rate_hz, clock.input_wait_ms, clock.catch_up_ms, clock.tool_gap_ms, clock.cut_catch_up_ms),
      blade_stale_us_(std::llround(clock.blade_stale_ms * 1e3)),
      blade_bridge_us_(std::llround(std::max(clock.blade_stale_ms, clock.input_wait_ms) * 1e3)),
      path_meter_(static_cast<int>(120 * rate_hz)) {  // two minutes of cutting at one sweep a step
  if (cutting) {
    Scene copy = scene;
    if (!gravity) copy.problem.gravity_World_mm_s2.setZero();
    cut_ = cut::make_cut_session(copy, scene.model, *cutting);
  } else {
    SimProblem problem = scene.problem;
    if (!gravity) problem.gravity_World_mm_s2.setZero();
    model_ = make_tissue_model(problem, scene.model);
  }
  step_once(nullptr, -1);  // the rest state, before the first step
  steps_ = 0;
  step_ms_.clear();
}

ModelRunner::~ModelRunner() { stop(); }

void ModelRunner::start() {
  stop_ = false;
  thread_ = std::thread([this] {
    // The overlay's latency matters more than the model's rate: on a machine with few
    // cores the model thread (and the solver threads it starts) yields to rendering, unless
    // the session cuts (then it runs above other work: session_config.hpp, kCuttingModelNice).
    // A negative level (above the rest of the machine) needs CAP_SYS_NICE; refused, the
    // thread keeps the process's level and the summary says so.
    if (nice_ != 0 && setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), nice_) != 0) {
      const std::string e = std::strerror(errno);
      std::lock_guard lock(mutex_);
      nice_error_ = "nice " + std::to_string(nice_) + " refused (" + e + "): the model thread runs at the process's level";
    }
    // A core of its own (cpu_partition): the solver's workers started from here inherit it.
    if (!cpus_.empty()) {
      const std::string e = pin_current_thread(cpus_);  // refused (cgroup): the scheduler places it, reported in the summary
      std::lock_guard lock(mutex_);
      pin_error_ = e;
    }
    // Steps when the clock says a step is due (its inputs arrived, or waited for long
    // enough); between steps it sleeps until the next push or the step's deadline.
    std::unique_lock lock(mutex_);
    while (!stop_.load()) {
      const std::int64_t now = monotonic_us();
      if (const std::optional<std::int64_t> t = clock_.due(now)) {
        const ModelStepInputs in = clock_.take(*t, now);
        lock.unlock();
        step_once(&in, now);
        lock.lock();
        continue;
      }
      const auto wait_us = std::max<std::int64_t>(0, clock_.deadline_host_us(now) - now);
      cv_.wait_for(lock, std::chrono::microseconds(wait_us));
    }
  });
}

void ModelRunner::stop() {
  stop_ = true;
  cv_.notify_all();
  if (thread_.joinable()) thread_.join();
}

int ModelRunner::advance_to(std::int64_t now_us, int max_steps) {
  int done = 0;
  while (done < max_steps) {
    ModelStepInputs in;
    {
      std::lock_guard lock(mutex_);
      const std::optional<std::int64_t> t = clock_.due(now_us);
      if (!t) break;
      in = clock_.take(*t, now_us);
    }
    step_once(&in, now_us);
    ++done;
  }
  return done;
}

void ModelRunner::expect_blade() {
  std::lock_guard lock(mutex_);
  clock_.require_blade();
}

void ModelRunner::push_blade(const BladeSample& sample, std::int64_t now_us) {
  {
    std::lock_guard lock(mutex_);
    clock_.push_blade(sample, now_us);
  }
  cv_.notify_all();
}

void ModelRunner::push_grasp(const GraspSample& sample, std::int64_t now_us) {
  {
    std::lock_guard lock(mutex_);
    clock_.push_grasp(sample, now_us);
  }
  cv_.notify_all();
}

void ModelRunner::tracker_at(std::int64_t device_time_us, std::int64_t now_us) {
  {
    std::lock_guard lock(mutex_);
    clock_.tracker_at(device_time_us, now_us);
  }
  cv_.notify_all();
}

bool ModelRunner::has_inputs() const {
  std::lock_guard lock(mutex_);
  return clock_.has_inputs();
}

ModelClockCounters ModelRunner::clock_counters() const {
  std::lock_guard lock(mutex_);
  return clock_.counters();
}

void ModelRunner::enable_grasper(const GrasperRole& role) {
  grasp_ = std::make_unique<GraspCoupling>(role, scene_);
  std::lock_guard lock(mutex_);
  clock_.require_grasp();
}

GraspStatus ModelRunner::grasp_status() const {
  std::lock_guard lock(mutex_);
  return grasp_status_;
}

std::shared_ptr<const ModelSnapshot> ModelRunner::snapshot_at(std::int64_t device_time_us) const {
  std::lock_guard lock(mutex_);
  if (!clock_.has_inputs() || recent_.empty()) return snapshot_;
  for (auto it = recent_.rbegin(); it != recent_.rend(); ++it)
    if ((*it)->step_device_time_us <= device_time_us) return *it;
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

std::vector<ModelRunner::CutVertex> ModelRunner::cut_vertices() const {
  std::vector<CutVertex> out;
  if (!cut_) return out;
  const cut::TetCutter& cutter = cut_->cutter();
  const Eigen::Matrix3Xd& rest = cutter.mesh().rest_positions_World_mm;
  const Eigen::Matrix3Xd x = cut_->positions_World_mm();
  for (Eigen::Index v = 0; v < rest.cols(); ++v)
    if (cutter.on_cut(static_cast<int>(v))) out.push_back({static_cast<int>(v), rest.col(v), x.col(v)});
  return out;
}

std::string ModelRunner::nice_error() const {
  std::lock_guard lock(mutex_);
  return nice_error_;
}

std::string ModelRunner::pin_error() const {
  std::lock_guard lock(mutex_);
  return pin_error_;
}

std::vector<double> ModelRunner::step_times_ms() const {
  std::lock_guard lock(mutex_);
  return step_ms_;
}

void ModelRunner::apply_grasp(GraspBody& body, const ModelStepInputs& in) {
  if (in.grasp) grasp_cmd_ = *in.grasp;
  // The grasper pose's age is judged on the device clock, at the step's time.
  grasp_->apply(body, grasp_cmd_, in.device_time_us);
  grasper_device_time_us_ = grasp_cmd_.device_time_us;
  std::lock_guard lock(mutex_);
  grasp_status_ = grasp_->status();
}

bool ModelRunner::gap_ends_stroke(const BladeSample& b) const {
  if (!last_blade_) return true;
  const std::int64_t gap_us = b.device_time_us - last_blade_->device_time_us;
  if (gap_us > blade_bridge_us_) return true;
  if (!b.blade_Model_mm || gap_us <= blade_stale_us_) return false;
  // Bridged only where the straight sweep is a fair guess of the path: a blade back more than
  // kMaxBridgeMm from where it was (lifted out and put in elsewhere while the tracker missed
  // it) starts a new stroke instead of cutting a chord through tissue it never went through.
  constexpr double kMaxBridgeMm = 10.0;  // a 10 mm chord of a 21 mm ring: 0.6 mm from the arc
  return std::max(((*b.blade_Model_mm)[0] - (*last_blade_->blade_Model_mm)[0]).norm(),
                  ((*b.blade_Model_mm)[1] - (*last_blade_->blade_Model_mm)[1]).norm()) > kMaxBridgeMm;
}

void ModelRunner::apply_blade_sample(const BladeSample& b, std::vector<ModelCutEvent>& events, std::optional<CutStepRecord>& record) {
  // A gap in the blade's samples (the tracker missed the scalpel's markers, replies were lost
  // or late) does not end the stroke: the blade coming back within the longer of the
  // scalpel's stale_after_ms and model.input_wait_ms (the time the model waits for a late
  // stream before it counts it lost) goes on cutting from where it was; the sweep starts from
  // the last blade carried with the tissue (a 20 mm/s ring: a 4 mm chord after 200 ms, 0.1 mm
  // from the arc). Only a longer gap ends the stroke (the stroke's end completes the tets the
  // blade crossed; the next sample then only places itself). Issue 20: a 150 ms tracker
  // timeout on a loaded machine ended the ring's stroke mid-way, and its completions put cut
  // vertices up to 18 mm from the blade's path in the material.
  if (gap_ends_stroke(b)) blade_gap_ = true;
  if (!b.blade_Model_mm) return;
  const bool cuts = b.cutting && !blade_gap_;
  const cut::CutFrameReport cr = cut_->apply_blade(cut::BladeSegment{(*b.blade_Model_mm)[0], (*b.blade_Model_mm)[1]}, cuts);
  blade_gap_ = false;
  // Cut-path fidelity, in the material: the surface this sample's blade swept (as the
  // cutter used it), pulled back into the rest configuration at this instant; every vertex
  // put on the cut is compared with those surfaces at its rest position.
  if (cuts && cut_->last_sweep()) path_meter_.record_sweep(cut_->cutter(), cut_->positions_World_mm(), *cut_->last_sweep());
  for (const auto& e : cr.events) events.push_back({0, 0, e});
  if (cr.cut.vertices_snapped > 0) cut_marks_changed_ = true;
  const auto ensure = [&record]() -> CutStepRecord& {
    if (!record) record = CutStepRecord{};
    return *record;
  };
  if (cr.cut.topology_changed) {
    CutStepRecord& r = ensure();
    r.cutter_path_error_mm = std::max(r.cutter_path_error_mm, cr.cut.max_path_deviation_mm);
    r.update_ms += cr.cut.update_ms;
    r.rebuild_ms += cr.rebuild_ms;
    r.tets_cut += cr.cut.tets_cut;
  }
  if (cr.cut.topology_changed || cr.cut.vertices_snapped > 0) {
    double worst = -1.0;
    if (const int fresh = path_meter_.measure_new_cut_vertices(cut_->cutter(), worst); fresh > 0) {
      CutStepRecord& r = ensure();
      r.new_cut_vertices += fresh;
      r.path_error_mm = std::max(r.path_error_mm, worst);
    }
  }
}

void ModelRunner::apply_blades(const ModelStepInputs& in, std::vector<ModelCutEvent>& events, std::optional<CutStepRecord>& record) {
  bool blade_seen = false;
  for (const BladeSample& b : in.blades) {
    apply_blade_sample(b, events, record);
    if (b.blade_Model_mm) {
      last_blade_ = b;
      blade_seen = true;
    }
  }
  if (blade_seen) return;
  // No new sample with the blade: the blade stays where it was while it is fresh (the tissue
  // may move across it); older, it is not held, and past the bridge the scalpel is lost (the
  // stroke ends at the next sample, which only places itself).
  if (!last_blade_) {
    blade_gap_ = true;
    return;
  }
  const std::int64_t age_us = in.device_time_us - last_blade_->device_time_us;
  if (age_us <= blade_stale_us_)
    apply_blade_sample(*last_blade_, events, record);
  else if (age_us > blade_bridge_us_)
    blade_gap_ = true;
}

void ModelRunner::step_once(const ModelStepInputs* in, std::int64_t now_us) {
  auto snap = std::make_shared<ModelSnapshot>();
  std::vector<ModelCutEvent> new_events;
  std::optional<CutStepRecord> cut_record;
  if (in) {
    const auto t0 = std::chrono::steady_clock::now();
    StepSummary s;
    if (cut_) {
      apply_blades(*in, new_events, cut_record);
      if (grasp_) {  // after the blade: the grasp holds the tissue as the cut left it
        CutSessionBody body(*cut_);
        apply_grasp(body, *in);
      }
      s = cut_->step(1.0 / rate_hz_);
    } else {
      if (grasp_) {
        TissueModelBody body(*model_);
        apply_grasp(body, *in);
      }
      s = model_->step(1.0 / rate_hz_);
    }
    snap->step_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    snap->healthy = s.healthy;
    snap->warning = s.warning;
    if (s.warning.find("step control") != std::string::npos) ++step_control_steps_;
    snap->step_device_time_us = in->device_time_us;
    for (auto& e : new_events) e.step_done_mono_us = now_us;
  }
  fill_snapshot(*snap);
  snap->step_done_mono_us = now_us;
  std::lock_guard lock(mutex_);
  snap->step = steps_.load() + (in ? 1 : 0);
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
  snap->clock = clock_.counters();
  if (in) {
    ++steps_;
    step_ms_.push_back(snap->step_ms);
  }
  if (clock_.has_inputs()) {
    snap->grasper_device_time_us = grasper_device_time_us_;
    recent_.push_back(snap);
    while (recent_.size() > static_cast<std::size_t>(rate_hz_) + 1) recent_.pop_front();
  }
  snapshot_ = std::move(snap);
}

// What the overlay draws, from the model's state now.
void ModelRunner::fill_snapshot(ModelSnapshot& snap) {
  if (cut_) {
    // The cut volume: its boundary (cut faces included) is the organ drawn; the tumours and
    // vessels are carried through the cuts by the cut session.
    const Eigen::Matrix3Xd x = cut_->positions_World_mm();
    const TetMesh& mesh = cut_->mesh();
    const auto& surface = cut_->surface_tris();
    snap.cutting = true;
    snap.organ.tris = surface;
    snap.organ.positions_World_mm = x;
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
    for (const auto& [a, b] : cut_rim_) snap.cut_rim_mm.push_back({x.col(a), x.col(b)});
    snap.cut_faces = static_cast<int>(cut_faces.tris.size());
    snap.cut_area_mm2 = 0.25 * area2;  // half of each face's |cross|, half of the faces (two sides)
    if (!cut_faces.tris.empty()) snap.cut_surface = std::move(cut_faces);
    for (std::size_t i = 0; i < cut_->tumours().size(); ++i) {
      TriMesh t;
      t.tris = cut_->tumour_tris()[i];  // split along the cut (closed again)
      t.positions_World_mm = cut_->tumours()[i].embedding.apply(mesh, x);
      snap.margins.push_back(overlay::offset_surface(t, margin_mm_));
      snap.tumour_centroids_mm.push_back(closed_centroid(t));
      snap.tumours.push_back(std::move(t));
    }
    if (scene_.vessels && cut_->vessels()) {
      VesselTree v;  // split along the cut: new nodes take the radius of the node they came from
      v.nodes_World_mm = cut_->vessels()->embedding.apply(mesh, x);
      v.segments = cut_->vessel_segments();
      for (int src : cut_->vessel_node_source()) v.radius_mm.push_back(scene_.vessels->rest.radius_mm[static_cast<std::size_t>(src)]);
      snap.vessels = std::move(v);
    }
    snap.volume_positions_World_mm = x;
  } else {
    const Eigen::Matrix3Xd& x = model_->positions_World_mm();
    const TetMesh& mesh = scene_.problem.mesh;
    snap.organ.tris = scene_.organ_surface.tris;
    snap.organ.positions_World_mm = scene_.organ_embedding.apply(mesh, x);
    for (std::size_t i = 0; i < scene_.tumours.size(); ++i) {
      TriMesh t;
      t.tris = scene_.tumours[i].rest.tris;
      t.positions_World_mm = scene_.tumours[i].embedding.apply(mesh, x);
      snap.margins.push_back(overlay::offset_surface(t, margin_mm_));
      snap.tumours.push_back(std::move(t));
      snap.tumour_centroids_mm.push_back(tumour_centroid_World_mm(scene_, static_cast<int>(i), x));
    }
    if (scene_.vessels) {
      VesselTree v = scene_.vessels->rest;
      v.nodes_World_mm = scene_.vessels->embedding.apply(mesh, x);
      snap.vessels = std::move(v);
    }
    snap.volume_positions_World_mm = x;
  }
}

}  // namespace arnav::host
