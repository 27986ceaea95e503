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

NonrigidResult register_nonrigid(const Scene& scene, const Eigen::Matrix3Xd& data, const std::vector<LandmarkPair>& landmarks,
                                 const NonrigidOptions& o) {
  const auto t0 = Clock::now();
  const TetMesh& mesh = scene.problem.mesh;
  const ModelConfig config = registration_config(scene, o.model_kind);  // a bad kind throws before anything runs
  NonrigidResult res;
  res.x_Model_mm = mesh.rest_positions_World_mm;
  {
    const SurfaceIndex rest_index(res.x_Model_mm, mesh.surface_tris);
    const Correspondences c0 = correspond(rest_index, data, o.keep_fraction, o.max_distance_mm);
    res.rigid_rms_mm = c0.rms;
    res.final_rms_mm = c0.rms;
    constexpr int kMinPoints = 20;
    if (c0.used < kMinPoints) {
      res.message = "data does not support a non-rigid fit: " + std::to_string(c0.used) + " usable points (of " +
                    std::to_string(data.cols()) + ") within " + std::to_string(std::max(o.max_distance_mm, 0.0)) +
                    " mm of the rigidly registered model; the rigid result is kept";
      res.wall_time_s = seconds_since(t0);
      return res;
    }
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
    if (c0.rms <= res.discrepancy_mm) {
      res.message = "the rigid fit already reaches the expected noise (" + std::to_string(c0.rms) + " mm RMS <= " +
                    std::to_string(res.discrepancy_mm) + " mm): no deformation needed; the rigid result is kept";
      res.wall_time_s = seconds_since(t0);
      return res;
    }
  }

  SimProblem problem = scene.problem;
  problem.gravity_World_mm_s2.setZero();  // the preoperative shape is the reference state; the data explain the change
  if (!o.scene_boundary) problem.fixed_vertices.clear();
  for (auto& m : problem.region_materials) {
    m.damping_mass_per_s = 0.0;  // velocities are zeroed after every step (quasi-static)
    m.damping_stiffness_s = 0.0;
  }
  const double dt = o.step_s > 0 ? o.step_s : (config.kind == "corotational_fem" ? 1.0 : scene.time_step_s);
  if (o.estimate_gravity_change && !problem.fixed_vertices.empty()) {
    const auto tg = Clock::now();
    const Eigen::Matrix3Xd& rest = mesh.rest_positions_World_mm;
    const Eigen::Matrix3Xd zero = Eigen::Matrix3Xd::Zero(3, rest.cols());
    const double g = scene.problem.gravity_World_mm_s2.norm() > 0 ? scene.problem.gravity_World_mm_s2.norm() : 9810.0;
    std::array<Eigen::Matrix3Xd, 3> U;  // displacement under a unit gravity (|g|) along each axis, boundary held
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) {
      SimProblem pa = problem;
      pa.gravity_World_mm_s2 = g * Eigen::Vector3d::Unit(a);
      std::unique_ptr<TissueModel> m = make_tissue_model(pa, config);
      for (int st = 0; st < o.gravity_relax_steps; ++st) {
        const Eigen::Matrix3Xd before = m->positions_World_mm();
        const StepSummary sum = m->step(dt);
        if (!sum.healthy || !m->positions_World_mm().allFinite()) {
          ok = false;
          break;
        }
        m->set_state(m->positions_World_mm(), zero);
        if ((m->positions_World_mm() - before).colwise().norm().maxCoeff() < 0.01) break;
      }
      U[static_cast<std::size_t>(a)] = m->positions_World_mm() - rest;
    }
    if (ok) {
      const SurfaceIndex rest_index(rest, mesh.surface_tris);
      const Correspondences c = correspond(rest_index, data, o.keep_fraction, o.max_distance_mm);
      std::vector<double> abs_r;
      for (std::size_t i = 0; i < c.keep.size(); ++i)
        if (c.keep[i]) abs_r.push_back(std::abs(c.plane[i]));
      const double huber = o.huber_sigmas * std::max(o.min_sigma_mm, 1.4826 * kth_value(abs_r, 0.5));
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
      problem.gravity_World_mm_s2 = g * s;
      res.gravity_change_mm_s2 = g * s;
    }
    res.gravity_time_s = seconds_since(tg);
  }
  std::unique_ptr<TissueModel> model = make_tissue_model(problem, config);
  res.model = config.kind + (config.integrator.empty() ? "" : "/" + config.integrator);

  const double e_ref = problem.region_materials.empty() ? 5.0 : problem.region_materials[0].youngs_modulus_kPa;
  const Eigen::Vector3d ext = mesh.rest_positions_World_mm.rowwise().maxCoeff() - mesh.rest_positions_World_mm.rowwise().minCoeff();
  const double k_unit = e_ref / ext.maxCoeff();  // mN/mm^3: stiffness per mm^2 of covered surface at weight 1

  std::vector<MaterialPoint> landmark_points;
  if (o.landmark_weight > 0 && !landmarks.empty()) {
    Eigen::Matrix3Xd p(3, static_cast<Eigen::Index>(landmarks.size()));
    for (std::size_t i = 0; i < landmarks.size(); ++i) p.col(static_cast<Eigen::Index>(i)) = landmarks[i].p_Model_mm;
    const Embedding e = embed_points(mesh, p, 5.0, "landmark (model position)");
    for (int i = 0; i < e.size(); ++i) landmark_points.push_back(e.material_point(mesh, i));
  }

  // The data term acts on the surface vertices: one attachment per vertex, made once;
  // each update sets its target and stiffness (the correspondences' springs lumped onto
  // the vertices of their triangles by the barycentric weights). A vertex no point pulls
  // keeps a negligible spring to where it is (the models need a positive stiffness).
  constexpr double kIdle_mN_per_mm = 1e-9;
  std::vector<int> surface_vertices;
  {
    std::vector<char> on(static_cast<std::size_t>(mesh.num_vertices()), 0);
    for (const auto& f : mesh.surface_tris)
      for (int v : f) on[static_cast<std::size_t>(v)] = 1;
    for (int v = 0; v < mesh.num_vertices(); ++v)
      if (on[static_cast<std::size_t>(v)]) surface_vertices.push_back(v);
  }
  std::vector<int> slot(static_cast<std::size_t>(mesh.num_vertices()), -1);
  std::vector<AttachmentId> vertex_attachment;
  for (std::size_t i = 0; i < surface_vertices.size(); ++i) {
    const int v = surface_vertices[i];
    slot[static_cast<std::size_t>(v)] = static_cast<int>(i);
    MaterialPoint mp;
    mp.vertices = {v};
    mp.weights = {1.0};
    vertex_attachment.push_back(model->add_attachment({mp, mesh.rest_positions_World_mm.col(v), kIdle_mN_per_mm}));
  }
  std::vector<AttachmentId> landmark_attachment;
  for (std::size_t i = 0; i < landmark_points.size(); ++i)
    landmark_attachment.push_back(model->add_attachment({landmark_points[i], landmarks[i].target_Model_mm, kIdle_mN_per_mm}));
  std::unique_ptr<SelfContactDetector> contact;
  if (o.self_contact) contact = std::make_unique<SelfContactDetector>(mesh.rest_positions_World_mm, mesh.surface_tris, o.contact_exclusion_mm);
  // Contacts are looked for every update, so a crossing is caught while shallow: the
  // search reaches a few margins behind a face (a short search keeps the term cheap).
  const double contact_depth_mm = contact ? std::max(3.0 * o.contact_margin_mm, 0.25 * contact->exclusion_mm()) : 0.0;
  Eigen::Matrix3Xd x = mesh.rest_positions_World_mm;
  const Eigen::Matrix3Xd zero_v = Eigen::Matrix3Xd::Zero(3, x.cols());
  double prev_rms = res.rigid_rms_mm;
  Eigen::Matrix3Xd best_x = x;
  bool stop = false;
  for (double weight : o.data_weight_schedule) {
    if (stop) break;
    if (o.time_budget_s > 0 && seconds_since(t0) > o.time_budget_s) {
      res.message = "time budget reached";
      break;
    }
    const auto tl = Clock::now();
    NonrigidLevel level;
    level.data_weight = weight;
    level.termination = "max_updates";
    double last_rms = prev_rms;
    for (int u = 0; u < o.max_updates_per_level; ++u) {
      const SurfaceIndex index(x, mesh.surface_tris);
      const Correspondences c = correspond(index, data, o.keep_fraction, o.max_distance_mm);
      if (c.used < 20) {
        level.termination = "too few points";
        stop = true;
        break;
      }
      std::vector<double> abs_r;
      std::set<int> tris;
      for (std::size_t i = 0; i < c.keep.size(); ++i)
        if (c.keep[i]) {
          abs_r.push_back(std::abs(c.plane[i]));
          tris.insert(c.hit[i].tri);
        }
      double covered_mm2 = 0.0;
      for (int t : tris) {
        const auto& f = mesh.surface_tris[static_cast<std::size_t>(t)];
        covered_mm2 += 0.5 * (x.col(f[1]) - x.col(f[0])).cross(x.col(f[2]) - x.col(f[0])).norm();
      }
      const double area_per_point = covered_mm2 / c.used;
      const double sigma = std::max(o.min_sigma_mm, 1.4826 * kth_value(abs_r, 0.5));
      const double huber = o.huber_sigmas * sigma;
      const auto tm = Clock::now();
      // Lump: vertex j gets K_j = sum_i k_i w_ij and the weighted mean of the pulls
      // d_i = r_i n_i (towards the data point's tangent plane).
      std::vector<double> K(surface_vertices.size(), 0.0);
      Eigen::Matrix3Xd pull = Eigen::Matrix3Xd::Zero(3, static_cast<Eigen::Index>(surface_vertices.size()));
      double k_sum = 0.0;
      for (std::size_t i = 0; i < c.keep.size(); ++i) {
        if (!c.keep[i]) continue;
        const SurfaceHit& h = c.hit[i];
        const auto& f = mesh.surface_tris[static_cast<std::size_t>(h.tri)];
        const double r = c.plane[i];
        const double w = std::abs(r) <= huber ? 1.0 : huber / std::abs(r);
        const double k = weight * k_unit * area_per_point * w;
        k_sum += k;
        for (int a = 0; a < 3; ++a) {
          const int j = slot[static_cast<std::size_t>(f[static_cast<std::size_t>(a)])];
          const double kw = k * h.barycentric[a];
          K[static_cast<std::size_t>(j)] += kw;
          pull.col(j) += kw * r * h.normal;
        }
      }
      if (contact) {
        // Self-contact: push a vertex that reached another part back to the margin and
        // that part's triangle the other way, stiffer than any data spring.
        const auto tc = Clock::now();
        const std::vector<SelfContact> cs = contact->find(x, o.contact_margin_mm, contact_depth_mm);
        res.contact_time_s += seconds_since(tc);
        const double k_c = o.contact_stiffness_factor * std::max(*std::max_element(K.begin(), K.end()), weight * k_unit * area_per_point);
        for (const SelfContact& sc : cs) {
          const double push = sc.wanted_mm - sc.signed_distance_mm;  // > 0
          const int j = slot[static_cast<std::size_t>(sc.vertex)];
          K[static_cast<std::size_t>(j)] += k_c;
          pull.col(j) += k_c * push * sc.normal;
          const auto& f = mesh.surface_tris[static_cast<std::size_t>(sc.tri)];
          for (int a = 0; a < 3; ++a) {
            const int jj = slot[static_cast<std::size_t>(f[static_cast<std::size_t>(a)])];
            const double kw = k_c * sc.barycentric[a];
            K[static_cast<std::size_t>(jj)] += kw;
            pull.col(jj) -= kw * push * sc.normal;
          }
        }
        level.contacts = static_cast<int>(cs.size());
      }
      for (std::size_t j = 0; j < surface_vertices.size(); ++j) {
        const Eigen::Vector3d xj = x.col(surface_vertices[j]);
        const bool pulled = K[j] > kIdle_mN_per_mm;
        model->set_attachment_target(vertex_attachment[j], pulled ? Eigen::Vector3d(xj + pull.col(static_cast<Eigen::Index>(j)) / K[j]) : xj);
        model->set_attachment_stiffness(vertex_attachment[j], pulled ? K[j] : kIdle_mN_per_mm);
      }
      for (AttachmentId id : landmark_attachment) model->set_attachment_stiffness(id, o.landmark_weight * weight);
      level.stiffness_per_point_mN_per_mm = k_sum / c.used;
      level.points_used = c.used;
      level.points_trimmed = static_cast<int>(data.cols()) - c.used;
      const Eigen::Matrix3Xd before = x;
      bool healthy = true;
      for (int s = 0; s < o.steps_per_update; ++s) {
        const StepSummary st = model->step(dt);
        ++level.model_steps;
        level.elastic_energy = st.elastic_energy;
        if (!st.healthy || !model->positions_World_mm().allFinite()) {
          healthy = false;
          res.message = "tissue model unhealthy at data weight " + std::to_string(weight) + ": " + st.warning;
          break;
        }
        model->set_state(model->positions_World_mm(), zero_v);
      }
      level.updates = u + 1;
      level.model_time_s += seconds_since(tm);
      if (!healthy) {
        level.termination = "model unhealthy";
        stop = true;
        break;
      }
      x = model->positions_World_mm();
      const double moved = (x - before).colwise().norm().maxCoeff();
      const double rms_now = c.rms;
      if (u > 0 && std::abs(last_rms - rms_now) < 0.01 * last_rms && moved < 0.05) {
        level.termination = "converged";
        break;
      }
      last_rms = rms_now;
    }
    // Level result at the relaxed state.
    const SurfaceIndex index(x, mesh.surface_tris);
    const Correspondences c = correspond(index, data, o.keep_fraction, o.max_distance_mm);
    level.rms_mm = c.rms;
    level.max_mm = c.max;
    double e_data = 0.0;
    for (std::size_t i = 0; i < c.keep.size(); ++i)
      if (c.keep[i]) e_data += 0.5 * level.stiffness_per_point_mN_per_mm * c.plane[i] * c.plane[i];
    level.data_energy = e_data;
    level.max_displacement_mm = (x - mesh.rest_positions_World_mm).colwise().norm().maxCoeff();
    level.wall_time_s = seconds_since(tl);
    res.levels.push_back(level);
    if (stop) break;
    if (c.rms >= prev_rms) {
      level.termination += "; no improvement";
      res.levels.back().termination = level.termination;
      break;
    }
    best_x = x;
    const bool small_gain = (prev_rms - c.rms) < o.min_improvement * prev_rms;
    prev_rms = c.rms;
    if (c.rms <= res.discrepancy_mm) {
      res.message = "reached the expected noise level";
      break;
    }
    if (small_gain) {
      res.message = "residual stopped improving";
      break;
    }
  }
  res.final_rms_mm = prev_rms;
  res.wall_time_s = seconds_since(t0);
  if (prev_rms < res.rigid_rms_mm * (1.0 - o.min_improvement)) {
    res.accepted = true;
    res.x_Model_mm = best_x;
    if (res.message.empty()) res.message = "schedule completed";
    model->set_state(best_x, zero_v);
    for (const auto& e : model->element_measures())
      if (e.volume_ratio <= 0) ++res.inverted_elements;
    const SelfContactDetector check(mesh.rest_positions_World_mm, mesh.surface_tris, o.contact_exclusion_mm);
    res.crossed_vertices = check.count_crossed(best_x, 0.5 * check.exclusion_mm());
  } else {
    res.message = "data does not support a non-rigid fit (surface residual " + std::to_string(res.rigid_rms_mm) + " mm rigid, " +
                  std::to_string(prev_rms) + " mm non-rigid" + (res.message.empty() ? "" : "; " + res.message) +
                  "); the rigid result is kept";
  }
  return res;
}

}  // namespace arnav::host
