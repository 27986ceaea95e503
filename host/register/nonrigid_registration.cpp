#include "host/register/nonrigid_registration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>

#include "host/register/robust_stats.hpp"
#include "host/register/self_contact.hpp"
#include "host/register/surface_index.hpp"
#include "host/scene/embedding.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Correspondences {
  std::vector<SurfaceHit> hit;
  std::vector<double> distance;
  std::vector<double> plane;   // signed point-to-plane residual n . (q - p)
  std::vector<char> keep;
  int used = 0;
  double rms = 0.0, max = 0.0;
};

Correspondences correspond(const SurfaceIndex& index, const Eigen::Matrix3Xd& q, double keep_fraction, double max_distance_mm) {
  Correspondences c;
  const int n = static_cast<int>(q.cols());
  c.hit.resize(static_cast<std::size_t>(n));
  c.distance.resize(static_cast<std::size_t>(n));
  c.plane.resize(static_cast<std::size_t>(n));
  c.keep.assign(static_cast<std::size_t>(n), 0);
  if (n == 0) return c;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const SurfaceHit h = index.closest(q.col(i), max_distance_mm);
    c.hit[static_cast<std::size_t>(i)] = h;
    c.distance[static_cast<std::size_t>(i)] = h.distance_mm;
    c.plane[static_cast<std::size_t>(i)] = h.tri >= 0 ? h.normal.dot(q.col(i) - h.point) : 0.0;
  }
  const double d_keep = kth_value(c.distance, keep_fraction);
  const double d_max = max_distance_mm;  // after the rigid stage a point further away is an outlier
  double ss = 0.0;
  for (int i = 0; i < n; ++i) {
    const double d = c.distance[static_cast<std::size_t>(i)];
    if (d <= d_keep && d <= d_max && c.hit[static_cast<std::size_t>(i)].tri >= 0) {
      c.keep[static_cast<std::size_t>(i)] = 1;
      ++c.used;
      ss += d * d;
      c.max = std::max(c.max, d);
    }
  }
  c.rms = c.used > 0 ? std::sqrt(ss / c.used) : 0.0;
  return c;
}

ModelConfig registration_config(const Scene& scene, const std::string& kind) {
  ModelConfig c = scene.model;
  if (!kind.empty() && kind != c.kind) {
    bool found = false;
    for (const ModelVariant& v : model_variants())
      if (v.config.kind == kind && !found) {
        c = v.config;
        c.threads = scene.model.threads;
        found = true;
      }
    if (!found) {
      std::string known;
      for (const auto& k : available_model_kinds()) known += (known.empty() ? "" : ", ") + k;
      throw std::invalid_argument("unknown or unavailable tissue model '" + kind + "' (this build has: " + known + ")");
    }
  }
  if (c.kind == "mass_spring" && c.integrator == "explicit") {
    // Explicit steps would need tiny substeps; the semi-implicit (CG) integrator takes the
    // scene's frame. (local_global refactors its matrix whenever attachments change:
    // every correspondence update, far too slow here.)
    c.integrator = "semi_implicit";
  }
  if (c.kind == "corotational_fem") {
    // Quasi-static relaxation with large steps: exact solves (a lagged factor would need
    // many PCG iterations once the attachments change the matrix).
    c.integrator = "implicit_euler";
    c.linear_solver = "cholmod";
    c.refactor_every = 1;
    c.refactor_in_background = false;
  }
  return c;
}

}  // namespace

double surface_rms_mm(const TetMesh& mesh, const Eigen::Matrix3Xd& x_mm, const Eigen::Matrix3Xd& points_mm, double keep_fraction,
                      double max_distance_mm, std::vector<double>* distances) {
  const SurfaceIndex index(x_mm, mesh.surface_tris);
  const Correspondences c = correspond(index, points_mm, keep_fraction, max_distance_mm);
  if (distances) *distances = c.distance;
  return c.rms;
}

namespace {

constexpr int kMinPoints = 20;  // fewer usable points than this cannot support a deformation

// Plane residuals beyond huber_sigmas robust sigmas (1.4826 x the median |r| of the kept
// points, at least min_sigma_mm) are down-weighted.
double huber_threshold_mm(const Correspondences& c, const NonrigidOptions& o) {
  std::vector<double> abs_r;
  for (std::size_t i = 0; i < c.keep.size(); ++i)
    if (c.keep[i]) abs_r.push_back(std::abs(c.plane[i]));
  return o.huber_sigmas * std::max(o.min_sigma_mm, 1.4826 * kth_value(abs_r, 0.5));
}

// Fills the rigid fit's residual and the discrepancy the schedule stops at (the expected
// noise, with the model's own surface error when asked). Returns why the rigid result is
// kept when the data do not call for a deformation; empty otherwise.
std::string rigid_fit_suffices(const Scene& scene, const Eigen::Matrix3Xd& data, const NonrigidOptions& o, NonrigidResult& res) {
  const TetMesh& mesh = scene.problem.mesh;
  const SurfaceIndex rest_index(res.x_Model_mm, mesh.surface_tris);
  const Correspondences c0 = correspond(rest_index, data, o.keep_fraction, o.max_distance_mm);
  res.rigid_rms_mm = c0.rms;
  res.final_rms_mm = c0.rms;
  if (c0.used < kMinPoints)
    return "data does not support a non-rigid fit: " + std::to_string(c0.used) + " usable points (of " + std::to_string(data.cols()) +
           ") within " + std::to_string(std::max(o.max_distance_mm, 0.0)) + " mm of the rigidly registered model; the rigid result is kept";
  res.discrepancy_mm = o.noise_mm;
  if (o.include_model_error && scene.organ_surface.positions_World_mm.cols() > 0) {
    double ss = 0.0;
    const Eigen::Matrix3Xd& s = scene.organ_surface.positions_World_mm;
    for (int i = 0; i < s.cols(); ++i) {
      const double d = rest_index.closest(s.col(i)).distance_mm;
      ss += d * d;
    }
    res.model_surface_error_mm = std::sqrt(ss / static_cast<double>(s.cols()));
    res.discrepancy_mm = std::hypot(o.noise_mm, res.model_surface_error_mm);
  }
  if (c0.rms <= res.discrepancy_mm)
    return "the rigid fit already reaches the expected noise (" + std::to_string(c0.rms) + " mm RMS <= " + std::to_string(res.discrepancy_mm) +
           " mm): no deformation needed; the rigid result is kept";
  return {};
}

// The problem the fit deforms: the preoperative shape is the reference state and the data
// explain the change (no gravity); velocities are zeroed after every step (quasi-static: no
// damping); the scene's supports only when asked.
SimProblem fit_problem(const Scene& scene, const NonrigidOptions& o) {
  SimProblem problem = scene.problem;
  problem.gravity_World_mm_s2.setZero();
  if (!o.scene_boundary) problem.fixed_vertices.clear();
  for (auto& m : problem.region_materials) {
    m.damping_mass_per_s = 0.0;
    m.damping_stiffness_s = 0.0;
  }
  return problem;
}

// Displacement of every vertex under a gravity of g along each axis, the boundary held,
// relaxed quasi-statically; false when the model fails.
bool unit_gravity_displacements(const SimProblem& problem, const ModelConfig& config, double dt, double g, int relax_steps,
                                std::array<Eigen::Matrix3Xd, 3>& U) {
  const Eigen::Matrix3Xd& rest = problem.mesh.rest_positions_World_mm;
  const Eigen::Matrix3Xd zero = Eigen::Matrix3Xd::Zero(3, rest.cols());
  for (int a = 0; a < 3; ++a) {
    SimProblem pa = problem;
    pa.gravity_World_mm_s2 = g * Eigen::Vector3d::Unit(a);
    std::unique_ptr<TissueModel> m = make_tissue_model(pa, config);
    for (int st = 0; st < relax_steps; ++st) {
      const Eigen::Matrix3Xd before = m->positions_World_mm();
      const StepSummary sum = m->step(dt);
      if (!sum.healthy || !m->positions_World_mm().allFinite()) return false;
      m->set_state(m->positions_World_mm(), zero);
      if ((m->positions_World_mm() - before).colwise().norm().maxCoeff() < 0.01) break;
    }
    U[static_cast<std::size_t>(a)] = m->positions_World_mm() - rest;
  }
  return true;
}

// The gravity change, as a fraction of g per axis, that best explains the data's plane
// residuals at rest (Huber-weighted linear least squares over the unit responses U), at
// most gravity_max_fraction long.
Eigen::Vector3d fit_gravity_fraction(const TetMesh& mesh, const Eigen::Matrix3Xd& data, const std::array<Eigen::Matrix3Xd, 3>& U,
                                     const NonrigidOptions& o) {
  const SurfaceIndex rest_index(mesh.rest_positions_World_mm, mesh.surface_tris);
  const Correspondences c = correspond(rest_index, data, o.keep_fraction, o.max_distance_mm);
  const double huber = huber_threshold_mm(c, o);
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < c.keep.size(); ++i) {
    if (!c.keep[i]) continue;
    const SurfaceHit& h = c.hit[i];
    const auto& f = mesh.surface_tris[static_cast<std::size_t>(h.tri)];
    Eigen::Vector3d j;
    for (int a = 0; a < 3; ++a) {
      Eigen::Vector3d u = Eigen::Vector3d::Zero();
      for (int k = 0; k < 3; ++k) u += h.barycentric[k] * U[static_cast<std::size_t>(a)].col(f[static_cast<std::size_t>(k)]);
      j[a] = h.normal.dot(u);
    }
    const double r = c.plane[i];
    const double w = std::abs(r) <= huber ? 1.0 : huber / std::abs(r);
    A += w * j * j.transpose();
    rhs += w * j * r;
  }
  A += 1e-3 * std::max(A.trace() / 3.0, 1e-12) * Eigen::Matrix3d::Identity();
  Eigen::Vector3d s = A.ldlt().solve(rhs);
  if (!s.allFinite()) s.setZero();
  if (s.norm() > o.gravity_max_fraction) s *= o.gravity_max_fraction / s.norm();
  return s;
}

// Sets problem's gravity to the change the data show (only with a held boundary: a free
// organ only translates under it).
void estimate_gravity_change(const Scene& scene, const Eigen::Matrix3Xd& data, const ModelConfig& config, double dt,
                             const NonrigidOptions& o, SimProblem& problem, NonrigidResult& res) {
  const auto tg = Clock::now();
  const double g = scene.problem.gravity_World_mm_s2.norm() > 0 ? scene.problem.gravity_World_mm_s2.norm() : 9810.0;
  std::array<Eigen::Matrix3Xd, 3> U;
  if (unit_gravity_displacements(problem, config, dt, g, o.gravity_relax_steps, U)) {
    const Eigen::Vector3d s = fit_gravity_fraction(problem.mesh, data, U, o);
    problem.gravity_World_mm_s2 = g * s;
    res.gravity_change_mm_s2 = g * s;
  }
  res.gravity_time_s = seconds_since(tg);
}

std::vector<MaterialPoint> landmark_material_points(const TetMesh& mesh, const std::vector<LandmarkPair>& landmarks,
                                                    const NonrigidOptions& o) {
  std::vector<MaterialPoint> points;
  if (o.landmark_weight <= 0 || landmarks.empty()) return points;
  Eigen::Matrix3Xd p(3, static_cast<Eigen::Index>(landmarks.size()));
  for (std::size_t i = 0; i < landmarks.size(); ++i) p.col(static_cast<Eigen::Index>(i)) = landmarks[i].p_Model_mm;
  const Embedding e = embed_points(mesh, p, 5.0, "landmark (model position)");
  for (int i = 0; i < e.size(); ++i) points.push_back(e.material_point(mesh, i));
  return points;
}

std::vector<int> surface_vertex_ids(const TetMesh& mesh) {
  std::vector<char> on(static_cast<std::size_t>(mesh.num_vertices()), 0);
  for (const auto& f : mesh.surface_tris)
    for (int v : f) on[static_cast<std::size_t>(v)] = 1;
  std::vector<int> ids;
  for (int v = 0; v < mesh.num_vertices(); ++v)
    if (on[static_cast<std::size_t>(v)]) ids.push_back(v);
  return ids;
}

// The deformation fit: the model with one attachment per surface vertex (the data term)
// and per landmark, run level by level of the data weight schedule.
class NonrigidFit {
 public:
  NonrigidFit(const TetMesh& mesh, std::unique_ptr<TissueModel> model, const std::vector<LandmarkPair>& landmarks, double k_unit,
              double dt, const NonrigidOptions& o)
      : mesh_(mesh), model_(std::move(model)), o_(o), k_unit_(k_unit), dt_(dt), surface_vertices_(surface_vertex_ids(mesh)),
        slot_(static_cast<std::size_t>(mesh.num_vertices()), -1), x_(mesh.rest_positions_World_mm),
        zero_v_(Eigen::Matrix3Xd::Zero(3, mesh.num_vertices())) {
    // The data term acts on the surface vertices: one attachment per vertex, made once;
    // each update sets its target and stiffness (the correspondences' springs lumped onto
    // the vertices of their triangles by the barycentric weights). A vertex no point pulls
    // keeps a negligible spring to where it is (the models need a positive stiffness).
    const std::vector<MaterialPoint> landmark_points = landmark_material_points(mesh, landmarks, o);
    for (std::size_t i = 0; i < surface_vertices_.size(); ++i) {
      const int v = surface_vertices_[i];
      slot_[static_cast<std::size_t>(v)] = static_cast<int>(i);
      MaterialPoint mp;
      mp.vertices = {v};
      mp.weights = {1.0};
      vertex_attachment_.push_back(model_->add_attachment({mp, mesh.rest_positions_World_mm.col(v), kIdle_mN_per_mm}));
    }
    for (std::size_t i = 0; i < landmark_points.size(); ++i)
      landmark_attachment_.push_back(model_->add_attachment({landmark_points[i], landmarks[i].target_Model_mm, kIdle_mN_per_mm}));
    if (o.self_contact) contact_ = std::make_unique<SelfContactDetector>(mesh.rest_positions_World_mm, mesh.surface_tris, o.contact_exclusion_mm);
    // Contacts are looked for every update, so a crossing is caught while shallow: the
    // search reaches a few margins behind a face (a short search keeps the term cheap).
    contact_depth_mm_ = contact_ ? std::max(3.0 * o.contact_margin_mm, 0.25 * contact_->exclusion_mm()) : 0.0;
  }

  const Eigen::Matrix3Xd& x() const { return x_; }
  TissueModel& model() { return *model_; }
  void set_state(const Eigen::Matrix3Xd& x) { model_->set_state(x, zero_v_); }

  // One level of the schedule: correspondence updates until the residual settles, then the
  // level's figures at the relaxed state. `stop` when the fit cannot go on (too few points,
  // an unhealthy model; res.message says why).
  NonrigidLevel run_level(double weight, const Eigen::Matrix3Xd& data, double start_rms, NonrigidResult& res, bool& stop) {
    const auto tl = Clock::now();
    NonrigidLevel level;
    level.data_weight = weight;
    level.termination = "max_updates";
    double last_rms = start_rms;
    for (int u = 0; u < o_.max_updates_per_level; ++u) {
      const SurfaceIndex index(x_, mesh_.surface_tris);
      const Correspondences c = correspond(index, data, o_.keep_fraction, o_.max_distance_mm);
      if (c.used < kMinPoints) {
        level.termination = "too few points";
        stop = true;
        break;
      }
      const Eigen::Matrix3Xd before = x_;
      if (!update(weight, c, static_cast<int>(data.cols()), level, res)) {
        level.updates = u + 1;
        level.termination = "model unhealthy";
        stop = true;
        break;
      }
      level.updates = u + 1;
      x_ = model_->positions_World_mm();
      const double moved = (x_ - before).colwise().norm().maxCoeff();
      if (u > 0 && std::abs(last_rms - c.rms) < 0.01 * last_rms && moved < 0.05) {
        level.termination = "converged";
        break;
      }
      last_rms = c.rms;
    }
    measure_level(data, level);
    level.wall_time_s = seconds_since(tl);
    return level;
  }

 private:
  static constexpr double kIdle_mN_per_mm = 1e-9;

  // Springs lumped onto the surface vertices (by slot): stiffness K_j and the sum of the
  // pulls, K_j times the displacement wanted.
  struct LumpedSprings {
    std::vector<double> K;
    Eigen::Matrix3Xd pull;
    double k_sum = 0.0;  // of the data springs
  };

  // One correspondence update: springs set from c, the model relaxed. False: unhealthy.
  bool update(double weight, const Correspondences& c, int data_points, NonrigidLevel& level, NonrigidResult& res) {
    const double area_per_point = covered_area_mm2(c) / c.used;
    const double huber = huber_threshold_mm(c, o_);
    const auto tm = Clock::now();
    LumpedSprings springs = data_springs(weight, c, area_per_point, huber);
    if (contact_) add_contact_springs(weight * k_unit_ * area_per_point, springs, level, res);
    set_attachments(weight, springs);
    level.stiffness_per_point_mN_per_mm = springs.k_sum / c.used;
    level.points_used = c.used;
    level.points_trimmed = data_points - c.used;
    bool healthy = true;
    for (int s = 0; s < o_.steps_per_update; ++s) {
      const StepSummary st = model_->step(dt_);
      ++level.model_steps;
      level.elastic_energy = st.elastic_energy;
      if (!st.healthy || !model_->positions_World_mm().allFinite()) {
        healthy = false;
        res.message = "tissue model unhealthy at data weight " + std::to_string(weight) + ": " + st.warning;
        break;
      }
      model_->set_state(model_->positions_World_mm(), zero_v_);
    }
    level.model_time_s += seconds_since(tm);
    return healthy;
  }

  // Area of the surface triangles the kept points land on, at x.
  double covered_area_mm2(const Correspondences& c) const {
    std::set<int> tris;
    for (std::size_t i = 0; i < c.keep.size(); ++i)
      if (c.keep[i]) tris.insert(c.hit[i].tri);
    double covered_mm2 = 0.0;
    for (int t : tris) {
      const auto& f = mesh_.surface_tris[static_cast<std::size_t>(t)];
      covered_mm2 += 0.5 * (x_.col(f[1]) - x_.col(f[0])).cross(x_.col(f[2]) - x_.col(f[0])).norm();
    }
    return covered_mm2;
  }

  // The data term: point i pulls its triangle towards the point's tangent plane
  // (d_i = r_i n_i) with k_i = weight * k_unit * area per point * Huber weight; vertex j
  // gets K_j = sum_i k_i w_ij and the weighted pulls.
  LumpedSprings data_springs(double weight, const Correspondences& c, double area_per_point, double huber) const {
    LumpedSprings s{std::vector<double>(surface_vertices_.size(), 0.0),
                    Eigen::Matrix3Xd::Zero(3, static_cast<Eigen::Index>(surface_vertices_.size())), 0.0};
    for (std::size_t i = 0; i < c.keep.size(); ++i) {
      if (!c.keep[i]) continue;
      const SurfaceHit& h = c.hit[i];
      const auto& f = mesh_.surface_tris[static_cast<std::size_t>(h.tri)];
      const double r = c.plane[i];
      const double w = std::abs(r) <= huber ? 1.0 : huber / std::abs(r);
      const double k = weight * k_unit_ * area_per_point * w;
      s.k_sum += k;
      for (int a = 0; a < 3; ++a) {
        const int j = slot_[static_cast<std::size_t>(f[static_cast<std::size_t>(a)])];
        const double kw = k * h.barycentric[a];
        s.K[static_cast<std::size_t>(j)] += kw;
        s.pull.col(j) += kw * r * h.normal;
      }
    }
    return s;
  }

  // Self-contact: a vertex that reached another part is pushed back to the margin and that
  // part's triangle the other way, stiffer than any data spring.
  void add_contact_springs(double k_point, LumpedSprings& s, NonrigidLevel& level, NonrigidResult& res) const {
    const auto tc = Clock::now();
    const std::vector<SelfContact> cs = contact_->find(x_, o_.contact_margin_mm, contact_depth_mm_);
    res.contact_time_s += seconds_since(tc);
    const double k_c = o_.contact_stiffness_factor * std::max(*std::max_element(s.K.begin(), s.K.end()), k_point);
    for (const SelfContact& sc : cs) {
      const double push = sc.wanted_mm - sc.signed_distance_mm;  // > 0
      const int j = slot_[static_cast<std::size_t>(sc.vertex)];
      s.K[static_cast<std::size_t>(j)] += k_c;
      s.pull.col(j) += k_c * push * sc.normal;
      const auto& f = mesh_.surface_tris[static_cast<std::size_t>(sc.tri)];
      for (int a = 0; a < 3; ++a) {
        const int jj = slot_[static_cast<std::size_t>(f[static_cast<std::size_t>(a)])];
        const double kw = k_c * sc.barycentric[a];
        s.K[static_cast<std::size_t>(jj)] += kw;
        s.pull.col(jj) -= kw * push * sc.normal;
      }
    }
    level.contacts = static_cast<int>(cs.size());
  }

  void set_attachments(double weight, const LumpedSprings& s) {
    for (std::size_t j = 0; j < surface_vertices_.size(); ++j) {
      const Eigen::Vector3d xj = x_.col(surface_vertices_[j]);
      const bool pulled = s.K[j] > kIdle_mN_per_mm;
      model_->set_attachment_target(vertex_attachment_[j], pulled ? Eigen::Vector3d(xj + s.pull.col(static_cast<Eigen::Index>(j)) / s.K[j]) : xj);
      model_->set_attachment_stiffness(vertex_attachment_[j], pulled ? s.K[j] : kIdle_mN_per_mm);
    }
    for (AttachmentId id : landmark_attachment_) model_->set_attachment_stiffness(id, o_.landmark_weight * weight);
  }

  // The level's residual, data energy and displacement at the relaxed state.
  void measure_level(const Eigen::Matrix3Xd& data, NonrigidLevel& level) const {
    const SurfaceIndex index(x_, mesh_.surface_tris);
    const Correspondences c = correspond(index, data, o_.keep_fraction, o_.max_distance_mm);
    level.rms_mm = c.rms;
    level.max_mm = c.max;
    double e_data = 0.0;
    for (std::size_t i = 0; i < c.keep.size(); ++i)
      if (c.keep[i]) e_data += 0.5 * level.stiffness_per_point_mN_per_mm * c.plane[i] * c.plane[i];
    level.data_energy = e_data;
    level.max_displacement_mm = (x_ - mesh_.rest_positions_World_mm).colwise().norm().maxCoeff();
  }

  const TetMesh& mesh_;
  std::unique_ptr<TissueModel> model_;
  const NonrigidOptions& o_;
  double k_unit_, dt_;
  std::vector<int> surface_vertices_;
  std::vector<int> slot_;  // per vertex: its index in surface_vertices_ (-1: not on the surface)
  std::vector<AttachmentId> vertex_attachment_, landmark_attachment_;
  std::unique_ptr<SelfContactDetector> contact_;
  double contact_depth_mm_ = 0.0;
  Eigen::Matrix3Xd x_;
  Eigen::Matrix3Xd zero_v_;
};

// The schedule's result: accepted only when it lowers the rigid residual by min_improvement;
// then the inverted elements and crossed surface vertices of the accepted shape.
void conclude(const TetMesh& mesh, const NonrigidOptions& o, const Eigen::Matrix3Xd& best_x, double best_rms, NonrigidFit& fit,
              NonrigidResult& res) {
  res.final_rms_mm = best_rms;
  if (best_rms < res.rigid_rms_mm * (1.0 - o.min_improvement)) {
    res.accepted = true;
    res.x_Model_mm = best_x;
    if (res.message.empty()) res.message = "schedule completed";
    fit.set_state(best_x);
    for (const auto& e : fit.model().element_measures())
      if (e.volume_ratio <= 0) ++res.inverted_elements;
    const SelfContactDetector check(mesh.rest_positions_World_mm, mesh.surface_tris, o.contact_exclusion_mm);
    res.crossed_vertices = check.count_crossed(best_x, 0.5 * check.exclusion_mm());
  } else {
    res.message = "data does not support a non-rigid fit (surface residual " + std::to_string(res.rigid_rms_mm) + " mm rigid, " +
                  std::to_string(best_rms) + " mm non-rigid" + (res.message.empty() ? "" : "; " + res.message) +
                  "); the rigid result is kept";
  }
}

}  // namespace

NonrigidResult register_nonrigid(const Scene& scene, const Eigen::Matrix3Xd& data, const std::vector<LandmarkPair>& landmarks,
                                 const NonrigidOptions& o) {
  const auto t0 = Clock::now();
  const TetMesh& mesh = scene.problem.mesh;
  const ModelConfig config = registration_config(scene, o.model_kind);  // a bad kind throws before anything runs
  NonrigidResult res;
  res.x_Model_mm = mesh.rest_positions_World_mm;
  if (std::string why = rigid_fit_suffices(scene, data, o, res); !why.empty()) {
    res.message = std::move(why);
    res.wall_time_s = seconds_since(t0);
    return res;
  }
  SimProblem problem = fit_problem(scene, o);
  const double dt = o.step_s > 0 ? o.step_s : (config.kind == "corotational_fem" ? 1.0 : scene.time_step_s);
  if (o.estimate_gravity_change && !problem.fixed_vertices.empty()) estimate_gravity_change(scene, data, config, dt, o, problem, res);
  res.model = config.kind + (config.integrator.empty() ? "" : "/" + config.integrator);
  const double e_ref = problem.region_materials.empty() ? 5.0 : problem.region_materials[0].youngs_modulus_kPa;
  const Eigen::Vector3d ext = mesh.rest_positions_World_mm.rowwise().maxCoeff() - mesh.rest_positions_World_mm.rowwise().minCoeff();
  const double k_unit = e_ref / ext.maxCoeff();  // mN/mm^3: stiffness per mm^2 of covered surface at weight 1
  NonrigidFit fit(mesh, make_tissue_model(problem, config), landmarks, k_unit, dt, o);

  double prev_rms = res.rigid_rms_mm;
  Eigen::Matrix3Xd best_x = fit.x();
  for (double weight : o.data_weight_schedule) {
    if (o.time_budget_s > 0 && seconds_since(t0) > o.time_budget_s) {
      res.message = "time budget reached";
      break;
    }
    bool stop = false;
    res.levels.push_back(fit.run_level(weight, data, prev_rms, res, stop));
    NonrigidLevel& level = res.levels.back();
    if (stop) break;
    if (level.rms_mm >= prev_rms) {
      level.termination += "; no improvement";
      break;
    }
    best_x = fit.x();
    const bool small_gain = (prev_rms - level.rms_mm) < o.min_improvement * prev_rms;
    prev_rms = level.rms_mm;
    if (level.rms_mm <= res.discrepancy_mm) {
      res.message = "reached the expected noise level";
      break;
    }
    if (small_gain) {
      res.message = "residual stopped improving";
      break;
    }
  }
  res.wall_time_s = seconds_since(t0);
  conclude(mesh, o, best_x, prev_rms, fit, res);
  return res;
}

}  // namespace arnav::host
