#include "host/register/tracking.hpp"

#include <chrono>

#include "host/register/surface_index.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {
constexpr double kIdle_mN_per_mm = 1e-9;
using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }
}  // namespace

SurfaceTracker::SurfaceTracker(const Scene& scene, const Eigen::Matrix3Xd& x_Model_mm, const Eigen::Isometry3d& X_IntraopModel,
                               const TrackingOptions& options)
    : scene_(scene), X_IntraopModel_(X_IntraopModel), options_(options) {
  SimProblem p = scene.problem;
  p.gravity_World_mm_s2.setZero();  // the registered shape is the state the features are pulling from
  if (!options.scene_boundary) p.fixed_vertices.clear();
  ModelConfig config = scene.model;
  if (options.realtime_model) {
    config = recommended_model_config(scene.model.kind);
    config.threads = scene.model.threads;
  }
  model_ = make_tissue_model(p, config);
  model_->set_state(x_Model_mm, Eigen::Matrix3Xd::Zero(3, x_Model_mm.cols()));
}

TrackingFrame SurfaceTracker::update(const Eigen::Matrix3Xd& points_Intraop_mm, const std::vector<long long>& ids, double dt_s) {
  const auto t0 = Clock::now();
  TrackingFrame f;
  if (static_cast<std::size_t>(points_Intraop_mm.cols()) != ids.size())
    throw std::invalid_argument("tracking: " + std::to_string(points_Intraop_mm.cols()) + " points but " + std::to_string(ids.size()) + " ids");
  const Eigen::Isometry3d X_ModelIntraop = X_IntraopModel_.inverse();
  std::map<long long, bool> seen;
  std::unique_ptr<SurfaceIndex> index;  // built only when a new ID needs binding
  for (int i = 0; i < points_Intraop_mm.cols(); ++i) {
    const long long id = ids[static_cast<std::size_t>(i)];
    if (!points_Intraop_mm.col(i).allFinite() || rejected_.count(id)) continue;
    const Eigen::Vector3d q = X_ModelIntraop * points_Intraop_mm.col(i);
    auto it = bound_.find(id);
    if (it == bound_.end()) {
      if (!index) index = std::make_unique<SurfaceIndex>(model_->positions_World_mm(), scene_.problem.mesh.surface_tris);
      const SurfaceHit h = index->closest(q, options_.bind_distance_mm);
      if (h.tri < 0) {
        rejected_[id] = true;
        ++f.rejected;
        continue;
      }
      const auto& t = scene_.problem.mesh.surface_tris[static_cast<std::size_t>(h.tri)];
      AttachmentSpec spec;
      spec.point.vertices = {t[0], t[1], t[2]};
      spec.point.weights = {h.barycentric[0], h.barycentric[1], h.barycentric[2]};
      spec.target_World_mm = q;
      spec.stiffness_mN_per_mm = options_.stiffness_per_point_mN_per_mm;
      bound_[id] = model_->add_attachment(spec);
      ++f.bound;
    } else {
      model_->set_attachment_target(it->second, q);
      model_->set_attachment_stiffness(it->second, options_.stiffness_per_point_mN_per_mm);
    }
    seen[id] = true;
    ++f.tracked;
  }
  for (const auto& [id, att] : bound_)
    if (!seen.count(id)) model_->set_attachment_stiffness(att, kIdle_mN_per_mm);  // lost this frame: let go
  const auto tm = Clock::now();
  f.bind_ms = ms_since(t0);
  const StepSummary st = model_->step(dt_s);
  f.model_ms = ms_since(tm);
  f.healthy = st.healthy;
  f.warning = st.warning;
  f.frame_ms = ms_since(t0);
  return f;
}

}  // namespace arnav::host
