#include "host/sim/mass_spring/mass_spring_model.hpp"

#include <omp.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "host/sim/model_setup.hpp"
#include "host/sim/element_measure.hpp"
#include "host/sim/step_health.hpp"

namespace arnav::host {

namespace {

// Spring kernels: out = sum over springs of the contribution fn(s) at end 0 and
// sign1 * fn(s) at end 1. With several threads each writes into its own buffer (no locks,
// no atomics) and a vertex pass sums the buffers; one thread writes into out directly.
template <class Fn>
void scatter(int threads, std::vector<Eigen::Matrix3Xd>& buffers, const std::vector<std::array<int, 2>>& ends,
             double sign1, Eigen::Matrix3Xd& out, Fn fn) {
  const int n = static_cast<int>(ends.size());
  // Element s adds its contribution c to its first vertex and sign1 * c to its second.
  auto add = [&](double* o, int s) {
    const Eigen::Vector3d c = fn(s);
    double* oi = o + 3 * ends[s][0];
    double* oj = o + 3 * ends[s][1];
    oi[0] += c.x(), oi[1] += c.y(), oi[2] += c.z();
    oj[0] += sign1 * c.x(), oj[1] += sign1 * c.y(), oj[2] += sign1 * c.z();
  };
  if (threads == 1) {
    out.setZero();
    for (int s = 0; s < n; ++s) add(out.data(), s);
    return;
  }
  const int nv = static_cast<int>(out.cols());
#pragma omp parallel num_threads(threads)
  {
    Eigen::Matrix3Xd& buf = buffers[static_cast<std::size_t>(omp_get_thread_num())];
    buf.setZero();
    double* o = buf.data();
#pragma omp for schedule(static)
    for (int s = 0; s < n; ++s) add(o, s);
#pragma omp for schedule(static)
    for (int i = 0; i < nv; ++i) {
      Eigen::Vector3d sum = buffers[0].col(i);
      for (std::size_t t = 1; t < buffers.size(); ++t) sum += buffers[t].col(i);
      out.col(i) = sum;
    }
  }
}

// Tet kernels: out += sum over tets of fn(t, c) (one contribution per tet vertex).
template <class Fn>
void scatter_tets_add(int threads, std::vector<Eigen::Matrix3Xd>& buffers, const std::vector<std::array<int, 4>>& tets,
                      Eigen::Matrix3Xd& out, Fn fn) {
  const int n = static_cast<int>(tets.size());
  if (threads == 1) {
    std::array<Eigen::Vector3d, 4> c;
    for (int t = 0; t < n; ++t) {
      if (!fn(t, c)) continue;
      for (int a = 0; a < 4; ++a) out.col(tets[t][a]) += c[a];
    }
    return;
  }
  const int nv = static_cast<int>(out.cols());
#pragma omp parallel num_threads(threads)
  {
    Eigen::Matrix3Xd& buf = buffers[static_cast<std::size_t>(omp_get_thread_num())];
    buf.setZero();
    std::array<Eigen::Vector3d, 4> c;
#pragma omp for schedule(static)
    for (int t = 0; t < n; ++t) {
      if (!fn(t, c)) continue;
      for (int a = 0; a < 4; ++a) buf.col(tets[t][a]) += c[a];
    }
#pragma omp for schedule(static)
    for (int i = 0; i < nv; ++i) {
      Eigen::Vector3d sum = buffers[0].col(i);
      for (std::size_t k = 1; k < buffers.size(); ++k) sum += buffers[k].col(i);
      out.col(i) += sum;
    }
  }
}

double dot(int threads, const Eigen::Matrix3Xd& a, const Eigen::Matrix3Xd& b) {
  const int n = static_cast<int>(a.size());
  const double* pa = a.data();
  const double* pb = b.data();
  double s = 0.0;
#pragma omp parallel for num_threads(threads) if (threads > 1) reduction(+ : s) schedule(static)
  for (int i = 0; i < n; ++i) s += pa[i] * pb[i];
  return s;
}

// Modulus of the volume term as a fraction of E (see the header).
constexpr double kVolumeModulusPerE = 0.5;
// Inversion barrier of the volume term. Below J = kBarrierJ the tet also stores
// kb/2 (kBarrierJ - J)^2, kb = kBarrierPerVolumeStiffness * kv, continued linearly more
// than kBarrierDepth below kBarrierJ (the restoring force is capped at kb * depth * |dJ/dx|).
// Why: springs keep an inverted tet in a local minimum (mirrored through a face it keeps
// its edge lengths, and the springs around it resist the way back through the flat state
// more than kv/2 (J - 1)^2 pushes). In the deform bench's lobe_pull 10 tets at the grasp
// stayed inverted with either implicit integrator; with the barrier 2 (tets held by
// competing attachments). The cap keeps the local/global integrator stable: its constant
// matrix does not bound the barrier, and uncapped forces from deeply inverted tets (a
// vertex pushed two cells through the mesh) made it diverge.
constexpr double kBarrierJ = 0.1;
constexpr double kBarrierPerVolumeStiffness = 10.0;
constexpr double kBarrierDepth = 0.5;

}  // namespace

double volume_energy(double J, double kv) {
  const double below = std::max(0.0, kBarrierJ - J);
  const double b = below <= kBarrierDepth ? 0.5 * below * below : kBarrierDepth * (below - 0.5 * kBarrierDepth);
  return kv * (0.5 * (J - 1.0) * (J - 1.0) + kBarrierPerVolumeStiffness * b);
}
double volume_slope(double J, double kv) {
  const double below = std::max(0.0, kBarrierJ - J);
  return kv * ((J - 1.0) - kBarrierPerVolumeStiffness * std::min(below, kBarrierDepth));
}
double volume_curvature(double J, double kv) {
  const double below = kBarrierJ - J;
  return kv * (1.0 + (below > 0.0 && below <= kBarrierDepth ? kBarrierPerVolumeStiffness : 0.0));
}

namespace {

// Relative CG residual above which a semi-implicit step is reported as not converged.
constexpr double kUnconvergedResidual = 0.01;

}  // namespace

MassSpringModel::MassSpringModel(const SimProblem& problem, Integrator integrator, const ModelConfig& config)
    : integrator_(integrator), config_(config), threads_(config.threads) {
  check_iterative_config(config, "mass_spring");  // iterations: CG iterations per substep
  if (config.linear_solver == "laplacian" && integrator == Integrator::kSemiImplicit) {
    laplacian_pc_ = true;
  } else if (!config.linear_solver.empty() && !(config.linear_solver == "jacobi" && integrator == Integrator::kSemiImplicit)) {
    throw std::invalid_argument("mass_spring: linear_solver '" + config.linear_solver +
                                "' is unknown for this integrator: semi_implicit takes jacobi (default) or laplacian; "
                                "explicit and local_global take none");
  }
  const TetMesh& mesh = problem.mesh;
  mass_ = checked_masses_kg(problem, "mass_spring");
  const int n = mesh.num_vertices();
  passive_ = problem.embedded.passive;
  passive_.resize(static_cast<std::size_t>(mesh.num_tets()), 0);
  springs_ = build_spring_network(mesh, problem.region_materials, passive_);
  gravity_ = problem.gravity_World_mm_s2;
  vessels_ignored_ = problem.vessels.has_value() && !problem.vessels->segments.empty();
  x_ = mesh.rest_positions_World_mm;
  v_ = Eigen::Matrix3Xd::Zero(3, n);

  mass_damping_ = Eigen::VectorXd::Zero(n);
  tets_ = mesh.tets;
  Dm_inv_.resize(tets_.size());
  tet_lame_.resize(tets_.size());
  volume_stiffness_.resize(tets_.size());
  inv_6v0_.resize(tets_.size());
  for (int t = 0; t < mesh.num_tets(); ++t) {
    const int region = mesh.tet_region.empty() ? 0 : mesh.tet_region[t];
    const Material& mat = problem.region_materials[region];
    Dm_inv_[t] = edge_matrix(x_, tets_[t]).inverse();
    tet_lame_[t] = lame_from(mat);
    // Volume term with a fixed modulus kVolumeModulusPerE * E: enough to stop compressed
    // tets from collapsing and inverting, small enough to keep the CG well conditioned.
    volume_stiffness_[t] = passive(t) ? 0.0 : kVolumeModulusPerE * mat.youngs_modulus_kPa * signed_volume_mm3(x_, tets_[t]);
    inv_6v0_[t] = 1.0 / (6.0 * signed_volume_mm3(x_, tets_[t]));
    const double quarter = 0.25 * signed_volume_mm3(x_, tets_[t]) * mat.density_kg_per_mm3;
    for (int v : tets_[t]) mass_damping_[v] += quarter * mat.damping_mass_per_s;
  }

  thread_buffers_.assign(static_cast<std::size_t>(threads_), Eigen::Matrix3Xd::Zero(3, n));
  for (Eigen::Matrix3Xd* m : {&f_, &rhs_, &dv_, &r_, &z_, &p_, &q_, &diag_}) *m = Eigen::Matrix3Xd::Zero(3, n);
  {  // semi-implicit buffers: also the fallback of the explicit and local/global integrators
    spring_dir_.resize(springs_.ends.size());
    spring_s1_.resize(springs_.ends.size());
    spring_s2_.resize(springs_.ends.size());
    vol_grad_.resize(tets_.size());
    vol_coef_.resize(tets_.size());
  }
  {  // embedded vertices: mass to their drivers / rigid groups, held by the solver
    std::vector<int> touched;
    embedded_.reset(problem.embedded, mesh.rest_positions_World_mm, x_, v_);
    embedded_.move_mass({&mass_, &mass_damping_}, touched, &problem.region_materials);
  }
  set_fixed_vertices(problem.fixed_vertices);
  ledger_.set_floor(energy_floor_mN_mm(problem));
  reset_ledger();
}

std::optional<MeshChangeStats> MassSpringModel::apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                                  const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  const auto& kEdges = kTetEdges;
  const TetMesh& mesh = problem.mesh;
  const int n_old = static_cast<int>(x_.cols()), n = mesh.num_vertices();
  const int nt_old = static_cast<int>(tets_.size()), nt = mesh.num_tets();
  if (n < n_old || nt < nt_old || x.cols() != n || (v.cols() != n && v.cols() != 0) || mesh.tet_region.size() != mesh.tets.size())
    return std::nullopt;
  MeshChangeStats stats;
  // The embedding's mass moves undone first (the lumped masses change below).
  std::vector<int> embedded_touched;
  embedded_.restore_mass({&mass_, &mass_damping_}, embedded_touched);
  const auto key = [](int a, int b) { return edge_key(a, b); };
  if (spring_tets_.empty()) {  // once: edge -> spring, tets per spring
    spring_of_edge_.reserve(static_cast<std::size_t>(springs_.size()) * 2);
    for (int sp = 0; sp < springs_.size(); ++sp) spring_of_edge_[key(springs_.ends[sp][0], springs_.ends[sp][1])] = sp;
    spring_tets_.assign(static_cast<std::size_t>(springs_.size()), 0);
    for (const auto& tet : tets_)
      for (const auto& e : kEdges) ++spring_tets_[static_cast<std::size_t>(spring_of_edge_[key(tet[e[0]], tet[e[1]])])];
  }
  // Vertices appended.
  x_.conservativeResize(Eigen::NoChange, n);
  v_.conservativeResize(Eigen::NoChange, n);
  mass_.conservativeResize(n);
  mass_damping_.conservativeResize(n);
  fixed_.resize(static_cast<std::size_t>(n), 0);
  user_fixed_.resize(static_cast<std::size_t>(n), 0);
  for (int i = n_old; i < n; ++i) {
    mass_[i] = 0.0;
    mass_damping_[i] = 0.0;
    x_.col(i) = x.col(i);
    v_.col(i).setZero();
  }
  for (auto it = problem.fixed_vertices.rbegin(); it != problem.fixed_vertices.rend() && *it >= n_old; ++it)
    user_fixed_[static_cast<std::size_t>(*it)] = 1;
  for (Eigen::Matrix3Xd* m : {&f_, &rhs_, &dv_, &r_, &z_, &p_, &q_, &diag_}) {
    m->conservativeResize(Eigen::NoChange, n);
    m->rightCols(n - n_old).setZero();
  }
  for (auto& buffer : thread_buffers_) {
    buffer.conservativeResize(Eigen::NoChange, n);
    buffer.rightCols(n - n_old).setZero();
  }
  std::vector<int> touched = embedded_touched;
  for (int i = n_old; i < n; ++i) touched.push_back(i);
  passive_.resize(static_cast<std::size_t>(nt), 0);
  // The changed tets' old contributions out.
  tets_.resize(static_cast<std::size_t>(nt));
  Dm_inv_.resize(static_cast<std::size_t>(nt));
  tet_lame_.resize(static_cast<std::size_t>(nt));
  volume_stiffness_.resize(static_cast<std::size_t>(nt));
  inv_6v0_.resize(static_cast<std::size_t>(nt));
  vol_grad_.resize(static_cast<std::size_t>(nt));  // semi-implicit, also the fallback of the others
  vol_coef_.resize(static_cast<std::size_t>(nt));
  for (int t : changed_tets) {
    if (t >= nt_old) continue;
    const Material& mat = problem.region_materials[static_cast<std::size_t>(mesh.tet_region[static_cast<std::size_t>(t)])];
    const auto& old = tets_[static_cast<std::size_t>(t)];
    const double V_old = 1.0 / (6.0 * inv_6v0_[static_cast<std::size_t>(t)]);
    const double E_old = passive(t) ? 0.0 : mat.youngs_modulus_kPa;  // a passive tet added no stiffness
    for (const auto& e : kEdges) {
      const int sp = spring_of_edge_.at(key(old[e[0]], old[e[1]]));
      const double L = springs_.rest_length_mm[static_cast<std::size_t>(sp)];
      const double k = E_old * V_old / (L * L);
      if (--spring_tets_[static_cast<std::size_t>(sp)] == 0) {
        springs_.stiffness_mN_per_mm[static_cast<std::size_t>(sp)] = 0.0;  // no tet left: no spring (no round-off residue)
        springs_.damping_mN_s_per_mm[static_cast<std::size_t>(sp)] = 0.0;
      } else {
        springs_.stiffness_mN_per_mm[static_cast<std::size_t>(sp)] -= k;
        springs_.damping_mN_s_per_mm[static_cast<std::size_t>(sp)] -= mat.damping_stiffness_s * k;
      }
      ++stats.elements_updated;
    }
    for (int w : old) {
      mass_[w] -= 0.25 * V_old * mat.density_kg_per_mm3;
      mass_damping_[w] -= 0.25 * V_old * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      touched.push_back(w);
    }
  }
  // The new ones in (springs of new edges appended; a spring whose tets all left takes the
  // new rest length: a vertex moved onto the cut).
  const auto& X = mesh.rest_positions_World_mm;
  for (int t : changed_tets) {
    const auto& tet = mesh.tets[static_cast<std::size_t>(t)];
    const Material& mat = problem.region_materials[static_cast<std::size_t>(mesh.tet_region[static_cast<std::size_t>(t)])];
    const double V = signed_volume_mm3(X, tet);
    if (!(V > 0.0)) throw std::invalid_argument("mass_spring: tet " + std::to_string(t) + " has non-positive rest volume after the cut");
    tets_[static_cast<std::size_t>(t)] = tet;
    passive_[static_cast<std::size_t>(t)] = problem.embedded.is_passive(t) ? 1 : 0;
    const double E = passive(t) ? 0.0 : mat.youngs_modulus_kPa;  // below the quality bound: no elastic term
    Dm_inv_[static_cast<std::size_t>(t)] = edge_matrix(X, tet).inverse();
    tet_lame_[static_cast<std::size_t>(t)] = lame_from(mat);
    volume_stiffness_[static_cast<std::size_t>(t)] = kVolumeModulusPerE * E * V;
    inv_6v0_[static_cast<std::size_t>(t)] = 1.0 / (6.0 * V);
    for (const auto& e : kEdges) {
      const int a = tet[e[0]], b = tet[e[1]];
      auto [it, inserted] = spring_of_edge_.emplace(key(a, b), springs_.size());
      const std::size_t sp = static_cast<std::size_t>(it->second);
      if (inserted) {
        springs_.ends.push_back({std::min(a, b), std::max(a, b)});
        springs_.rest_length_mm.push_back(0.0);
        springs_.stiffness_mN_per_mm.push_back(0.0);
        springs_.damping_mN_s_per_mm.push_back(0.0);
        spring_tets_.push_back(0);
      }
      if (spring_tets_[sp] == 0) springs_.rest_length_mm[sp] = (X.col(b) - X.col(a)).norm();
      const double L = springs_.rest_length_mm[sp];
      const double k = E * V / (L * L);
      springs_.stiffness_mN_per_mm[sp] += k;
      springs_.damping_mN_s_per_mm[sp] += mat.damping_stiffness_s * k;
      ++spring_tets_[sp];
      ++stats.elements_updated;
    }
    for (int w : tet) {
      mass_[w] += 0.25 * V * mat.density_kg_per_mm3;
      mass_damping_[w] += 0.25 * V * mat.density_kg_per_mm3 * mat.damping_mass_per_s;
      touched.push_back(w);
    }
  }
  spring_dir_.resize(springs_.ends.size());
  spring_s1_.resize(springs_.ends.size());
  spring_s2_.resize(springs_.ends.size());
  // The new embedding (driven vertices, rigid groups): mass moved, held in the solver.
  for (int w : touched)
    if (!(mass_[w] > 0.0)) throw std::invalid_argument("mass_spring: vertex " + std::to_string(w) + " lost its mass in the cut");
  embedded_.reset(problem.embedded, X, x, v);
  embedded_.move_mass({&mass_, &mass_damping_}, touched, &problem.region_materials);
  merge_fixed();
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  inv_mass_.conservativeResize(n);
  for (int w : touched) {
    x_.col(w) = x.col(w);
    v_.col(w) = v.cols() == n && !fixed_[static_cast<std::size_t>(w)] ? Eigen::Vector3d(v.col(w)) : Eigen::Vector3d::Zero();
    inv_mass_[w] = fixed_[static_cast<std::size_t>(w)] ? 0.0 : 1.0 / mass_[w];
    ++stats.vertices_updated;
  }
  if (integrator_ == Integrator::kExplicit) {
    update_omega_bound();  // the stability bound the small pieces lower
    bound_lowered_by_cut_ = true;
  }
  // As for a model rebuilt on the cut mesh (set_state): the energy balance restarts on the
  // cut mesh (the cut changed the energy function: a split spring's pieces take their own
  // rest lengths) and so does the inversion episode. O(mesh), one energy evaluation.
  inversions_.reset_episode();
  reset_ledger();
  if (integrator_ == Integrator::kLocalGlobal || laplacian_pc_) {
    // The prefactored system: new rows for the new free vertices (numbered after the old
    // ones, as a fresh numbering would), refactored in the background (local_global_step.cpp).
    ++mesh_version_;
    stale_ready_ = false;
    base_valid_ = false;
    if (static_cast<int>(free_index_.size()) == n_old) {
      const std::vector<int> old_free_index = free_index_;
      // Rows numbered as a fresh build would (the old rows keep theirs unless the embedding
      // now holds or frees one of their vertices).
      free_index_.assign(static_cast<std::size_t>(n), -1);
      free_count_ = 0;
      for (int i = 0; i < n; ++i) free_index_[static_cast<std::size_t>(i)] = fixed_[static_cast<std::size_t>(i)] ? -1 : free_count_++;
      lg_rhs_.resize(free_count_, 3);
      lg_dx_.resize(free_count_, 3);
      if (!system_dirty_ && system_.ready()) {
        if (!factor_stale_) {
          pc_free_index_ = old_free_index;  // the rows system_ was factored for
          pc_alias_.resize(static_cast<std::size_t>(n_old));
          std::iota(pc_alias_.begin(), pc_alias_.end(), 0);
        }
        // A vertex the cut made moves, in the preconditioner, with its nearest (rest)
        // neighbour in the changed tets that existed before (aggregation).
        pc_alias_.resize(static_cast<std::size_t>(n), -1);
        for (int round = 0; round < 4; ++round) {
          bool missing = false;
          for (int t : changed_tets) {
            const auto& tet = tets_[static_cast<std::size_t>(t)];
            for (int w : tet) {
              if (w < n_old || pc_alias_[static_cast<std::size_t>(w)] >= 0) continue;
              double best = 1e300;
              for (int u : tet)
                if (u != w && pc_alias_[static_cast<std::size_t>(u)] >= 0 && (u < n_old || round > 0)) {
                  const double d = (X.col(u) - X.col(w)).squaredNorm();
                  if (d < best) {
                    best = d;
                    pc_alias_[static_cast<std::size_t>(w)] = pc_alias_[static_cast<std::size_t>(u)];
                  }
                }
              missing = missing || pc_alias_[static_cast<std::size_t>(w)] < 0;
            }
          }
          if (!missing) break;
        }
        factor_stale_ = true;
        if (pending_factor_.valid()) {
          refactor_again_ = true;
        } else {
          launch_background_factor();
        }
      }
    } else {
      system_dirty_ = true;  // never factored: the next step builds it
    }
  }
  return stats;
}

std::string MassSpringModel::name() const {
  switch (integrator_) {
    case Integrator::kExplicit: return "mass_spring/explicit";
    case Integrator::kSemiImplicit: return "mass_spring/semi_implicit";
    case Integrator::kLocalGlobal: return "mass_spring/local_global";
  }
  return "mass_spring";
}

void MassSpringModel::set_fixed_vertices(const std::vector<int>& vertices) {
  check_vertex_indices(vertices, static_cast<int>(x_.cols()), "set_fixed_vertices");
  user_fixed_.assign(static_cast<std::size_t>(x_.cols()), 0);
  for (int v : vertices) user_fixed_[static_cast<std::size_t>(v)] = 1;
  merge_fixed();
  inv_mass_ = mass_.cwiseInverse();
  for (int v : vertices) v_.col(v).setZero();
  for (std::size_t i = 0; i < fixed_.size(); ++i)
    if (fixed_[i]) inv_mass_[static_cast<Eigen::Index>(i)] = 0.0;
  system_dirty_ = true;
  base_valid_ = false;
  update_omega_bound();
}

void MassSpringModel::merge_fixed() {
  fixed_.assign(user_fixed_.size(), 0);
  for (std::size_t i = 0; i < fixed_.size(); ++i) fixed_[i] = user_fixed_[i] || embedded_.held(static_cast<int>(i)) ? 1 : 0;
}

void MassSpringModel::update_omega_bound() {
  // Gershgorin: every eigenvalue of M^-1 K lies below max_i (|K_ii| + sum_j |K_ij|) / m_i,
  // and the spring tangent is bounded by k (the geometric part (1 - L/l) is below 1).
  const int n = static_cast<int>(x_.cols());
  Eigen::VectorXd row = Eigen::VectorXd::Zero(n), eta = Eigen::VectorXd::Zero(n);
  for (int s = 0; s < springs_.size(); ++s) {
    for (int end : springs_.ends[s]) {
      row[end] += 2.0 * springs_.stiffness_mN_per_mm[s];
      eta[end] += 2.0 * springs_.damping_mN_s_per_mm[s];
    }
  }
  for (int id : attachments_.active()) {
    const Attachment& a = attachments_[id];
    for (int i = 0; i < a.count; ++i) row[a.vertices[i]] += a.stiffness_mN_per_mm * std::abs(a.weights[i]);
  }
  // Volume term: kv g g^T with g_a = cof(F) b_a, bounded with its rest value g_a = b_a
  // (the energy ledger backs this up under large stretch).
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    if (volume_stiffness_[t] <= 0.0) continue;
    std::array<double, 4> gn;
    gn[1] = Dm_inv_[t].row(0).norm();
    gn[2] = Dm_inv_[t].row(1).norm();
    gn[3] = Dm_inv_[t].row(2).norm();
    gn[0] = Dm_inv_[t].colwise().sum().norm();
    const double sum = gn[0] + gn[1] + gn[2] + gn[3];
    for (int a = 0; a < 4; ++a) row[tets_[t][a]] += volume_stiffness_[t] * gn[a] * sum;
  }
  omega_max_ = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!fixed_[static_cast<std::size_t>(i)]) omega_max_ = std::max(omega_max_, std::sqrt(row[i] / mass_[i]));
  }
  // Damping ratio of the fastest mode: stiffness-proportional (Voigt dashpots) plus
  // mass-proportional; take the largest over vertices (damping shrinks the bound).
  zeta_ = 0.0;
  for (int i = 0; i < n && omega_max_ > 0.0; ++i) {
    if (fixed_[static_cast<std::size_t>(i)]) continue;
    const double beta = row[i] > 0.0 ? eta[i] / row[i] : 0.0;
    const double alpha = mass_damping_[i] / mass_[i];
    zeta_ = std::max(zeta_, 0.5 * beta * omega_max_ + 0.5 * alpha / omega_max_);
  }
}

double MassSpringModel::explicit_stable_substep_s() const {
  if (omega_max_ <= 0.0) return std::numeric_limits<double>::infinity();
  return 2.0 / omega_max_ * (std::sqrt(1.0 + zeta_ * zeta_) - zeta_);
}

int MassSpringModel::explicit_substeps_needed(double dt_s) const {
  const double h_max = explicit_stable_substep_s();
  return std::isfinite(h_max) ? std::max(1, static_cast<int>(std::ceil(dt_s / h_max))) : 1;
}

int MassSpringModel::explicit_substeps(double dt_s) const {
  const int configured = config_.substeps, needed = explicit_substeps_needed(dt_s);
  if (needed <= configured) return configured;
  // The margin after a cut and here: the bound is the rest network's, a guess at what the
  // deformed one needs (at 10 g on a patient liver the integrator still diverges at +10 % and
  // +25 %, and the semi-implicit fallback takes over: docs/benchmarks.md "Stress matrix again").
  constexpr double kMargin = 1.25;
  const int wanted = static_cast<int>(std::ceil(kMargin * dt_s / explicit_stable_substep_s()));
  if (bound_lowered_by_cut_) return std::max(configured, wanted);
  const int budget = SubstepControl::budget_substeps(configured, dt_s);
  if (needed > budget) return 0;
  return std::min(budget, wanted);
}

// The warning of an explicit step that took more substeps than configured: after a cut, as
// before; otherwise in the step control's words ("step control: Nx the substeps", N the
// power-of-two level it is counted at), which the session counts as a step under step control.
std::string MassSpringModel::explicit_substeps_warning(double dt_s, int substeps) const {
  const std::string bound = std::to_string(explicit_stable_substep_s()) + " s";
  if (bound_lowered_by_cut_)
    return "explicit mass-spring: " + std::to_string(substeps) + " substeps instead of " + std::to_string(config_.substeps) +
           " (a cut lowered the stability bound to " + bound + ")";
  int level = 1;
  while (level * config_.substeps < substeps) level *= 2;
  return "step control: " + std::to_string(level) + "x the substeps (explicit mass-spring: " + std::to_string(substeps) +
         " substeps instead of " + std::to_string(config_.substeps) + " for the stiffest springs' stability bound " + bound +
         "; model.substeps >= " + std::to_string(explicit_substeps_needed(dt_s)) + " needs none)";
}

AttachmentId MassSpringModel::add_attachment(const AttachmentSpec& spec) {
  double work = 0.0;
  const AttachmentId id = attachments_.add(spec, x_, work);
  ledger_.add_work(work);
  system_dirty_ = true;
  update_omega_bound();
  return id;
}
void MassSpringModel::set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  ledger_.add_work(attachments_.set_target(id, target_World_mm, x_));
}
void MassSpringModel::set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  ledger_.add_work(attachments_.set_stiffness(id, stiffness_mN_per_mm, x_));
  system_dirty_ = true;
  update_omega_bound();
}
void MassSpringModel::remove_attachment(AttachmentId id) {
  ledger_.add_work(attachments_.remove(id, x_));
  system_dirty_ = true;
  update_omega_bound();
}

void MassSpringModel::set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) {
  check_state_shape(positions_World_mm, velocities_World_mm_s, static_cast<int>(x_.cols()));
  x_ = positions_World_mm;
  v_ = velocities_World_mm_s;
  embedded_.restart(x_, v_);  // rigid groups start from the given state
  for (std::size_t i = 0; i < fixed_.size(); ++i)
    if (fixed_[i]) v_.col(static_cast<Eigen::Index>(i)).setZero();
  dv_.setZero();
  inversions_.reset_episode();
  reset_ledger();
}

void MassSpringModel::reset_ledger() {
  ledger_.reset(kinetic_energy(mass_, v_) + elastic_energy(), gravity_potential(mass_, x_, gravity_));
  control_.ledger_reset();
}

void MassSpringModel::assemble(double h) {
  const auto& ends = springs_.ends;
  const double* X = x_.data();
  const double* V = v_.data();
  const double* L = springs_.rest_length_mm.data();
  const double* K = springs_.stiffness_mN_per_mm.data();
  const double* ETA = springs_.damping_mN_s_per_mm.data();
  const bool implicit = h > 0.0;
  Eigen::Matrix3Xd& out = implicit ? rhs_ : f_;
  scatter(threads_, thread_buffers_, ends, -1.0, out, [&](int s) -> Eigen::Vector3d {
    const int i = ends[s][0], j = ends[s][1];
    const Eigen::Vector3d d(X[3 * j] - X[3 * i], X[3 * j + 1] - X[3 * i + 1], X[3 * j + 2] - X[3 * i + 2]);
    const Eigen::Vector3d dv(V[3 * j] - V[3 * i], V[3 * j + 1] - V[3 * i + 1], V[3 * j + 2] - V[3 * i + 2]);
    const double l = d.norm();
    if (!(l > 1e-12)) return Eigen::Vector3d::Zero();  // coincident ends: no direction
    const Eigen::Vector3d n = d / l;
    // Voigt element: elastic k (l - L) plus dashpot eta (v_j - v_i).n, both along n.
    const double ndv = n.dot(dv);
    Eigen::Vector3d f = (K[s] * (l - L[s]) + ETA[s] * ndv) * n;
    if (!implicit) return f;
    // Tangent K_e = k (n n^T + c (I - n n^T)), c = max(0, 1 - L/l) (compressive part dropped).
    const double c = std::max(0.0, 1.0 - L[s] / l);
    const double h2k = h * h * K[s];
    spring_dir_[s] = n;
    spring_s1_[s] = h * ETA[s] + h2k * (1.0 - c);
    spring_s2_[s] = h2k * c;
    // rhs at i: h f_i + h^2 (K v)_i, (K v)_i = -K_e (v_i - v_j) = K_e dv.
    return h * f + h2k * ((1.0 - c) * ndv * n + c * dv);
  });
  // Volume term E_V = kv/2 (J - 1)^2: f_a = -kv (J - 1) g_a, g_a = cof(F) b_a; its
  // Gauss-Newton tangent -kv g g^T enters the implicit system.
  scatter_tets_add(threads_, thread_buffers_, tets_, out, [&](int t, std::array<Eigen::Vector3d, 4>& c) {
    const double kv = volume_stiffness_[t];
    if (kv <= 0.0) return false;
    // J = V / V0 with 6 V = e1.(e2 x e3); dJ/dx_a = (cross product of the other two
    // edges) / (6 V0), the same as cof(F) b_a at a fraction of the cost.
    const auto& v = tets_[t];
    const Eigen::Vector3d x0 = x_.col(v[0]);
    const Eigen::Vector3d e1 = x_.col(v[1]) - x0, e2 = x_.col(v[2]) - x0, e3 = x_.col(v[3]) - x0;
    const double s6 = inv_6v0_[t];
    std::array<Eigen::Vector3d, 4> g;
    g[1] = s6 * e2.cross(e3);
    g[2] = s6 * e3.cross(e1);
    g[3] = s6 * e1.cross(e2);
    g[0] = -(g[1] + g[2] + g[3]);
    const double J = e1.dot(g[1]);
    const double f = -volume_slope(J, kv);
    if (!implicit) {
      for (int a = 0; a < 4; ++a) c[a] = f * g[a];
      return true;
    }
    double gv = 0.0;
    for (int a = 0; a < 4; ++a) gv += g[a].dot(v_.col(tets_[t][a]));
    const double curvature = volume_curvature(J, kv);
    vol_grad_[t] = g;
    vol_coef_[t] = h * h * curvature;
    for (int a = 0; a < 4; ++a) c[a] = (h * f - h * h * curvature * gv) * g[a];
    return true;
  });
  const int n = static_cast<int>(x_.cols());
  const double scale = implicit ? h : 1.0;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) schedule(static)
  for (int i = 0; i < n; ++i) out.col(i) += scale * (mass_[i] * gravity_ - mass_damping_[i] * v_.col(i));
  for (int id : attachments_.active()) {
    const Attachment& a = attachments_[id];
    const Eigen::Vector3d stretch = a.point(x_) - a.target_World_mm;
    const Eigen::Vector3d vel = a.point(v_);
    for (int k = 0; k < a.count; ++k) {
      const double kw = a.stiffness_mN_per_mm * a.weights[k];
      out.col(a.vertices[k]) -= scale * kw * stretch;
      if (implicit) out.col(a.vertices[k]) -= h * h * kw * vel;
    }
  }
}

void MassSpringModel::explicit_substep(double h) {
  assemble(0.0);
  const int n = static_cast<int>(x_.cols());
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) schedule(static)
  for (int i = 0; i < n; ++i) {
    if (fixed_[static_cast<std::size_t>(i)]) continue;
    v_.col(i) += h * inv_mass_[i] * f_.col(i);
    x_.col(i) += h * v_.col(i);
  }
}

double MassSpringModel::apply_system(const Eigen::Matrix3Xd& p, Eigen::Matrix3Xd& out) {
  // One fused pass (the CG spends most of its time here): springs and volume terms
  // scatter into per-thread buffers inside a single parallel region, then one vertex pass
  // sums the buffers, adds the mass term, zeroes fixed rows and accumulates p.out (the
  // CG's curvature), so the buffers are zeroed and read once per product, not twice.
  const auto& ends = springs_.ends;
  const int ns = static_cast<int>(ends.size());
  const int nt = static_cast<int>(tets_.size());
  const int n = static_cast<int>(x_.cols());
  const double h = current_h_;
  const double* P = p.data();
  const unsigned char* fixed = fixed_.data();
  auto spring_kernel = [&](double* o, int s) {
    const int i = ends[s][0], j = ends[s][1];
    const Eigen::Vector3d d(P[3 * i] - P[3 * j], P[3 * i + 1] - P[3 * j + 1], P[3 * i + 2] - P[3 * j + 2]);
    const Eigen::Vector3d& dir = spring_dir_[s];
    const Eigen::Vector3d c = spring_s1_[s] * dir.dot(d) * dir + spring_s2_[s] * d;
    double* oi = o + 3 * i;
    double* oj = o + 3 * j;
    oi[0] += c.x(), oi[1] += c.y(), oi[2] += c.z();
    oj[0] -= c.x(), oj[1] -= c.y(), oj[2] -= c.z();
  };
  auto tet_kernel = [&](double* o, int t) {
    if (volume_stiffness_[t] <= 0.0) return;
    const auto& g = vol_grad_[t];
    const auto& v = tets_[t];
    double gp = 0.0;
    for (int a = 0; a < 4; ++a) gp += g[a].x() * P[3 * v[a]] + g[a].y() * P[3 * v[a] + 1] + g[a].z() * P[3 * v[a] + 2];
    const double coef = vol_coef_[t] * gp;
    for (int a = 0; a < 4; ++a) {
      double* oa = o + 3 * v[a];
      oa[0] += coef * g[a].x(), oa[1] += coef * g[a].y(), oa[2] += coef * g[a].z();
    }
  };
  // Attachments (few) are added after the vertex pass; they never touch fixed rows.
  double pq = 0.0;
  if (threads_ == 1) {
    out.setZero();
    double* o = out.data();
    for (int s = 0; s < ns; ++s) spring_kernel(o, s);
    for (int t = 0; t < nt; ++t) tet_kernel(o, t);
    for (int i = 0; i < n; ++i) {
      if (fixed[i]) {
        out.col(i).setZero();
      } else {
        out.col(i) += (mass_[i] + h * mass_damping_[i]) * p.col(i);
      }
    }
  } else {
#pragma omp parallel num_threads(threads_)
    {
      Eigen::Matrix3Xd& buf = thread_buffers_[static_cast<std::size_t>(omp_get_thread_num())];
      buf.setZero();
      double* o = buf.data();
#pragma omp for schedule(static) nowait
      for (int s = 0; s < ns; ++s) spring_kernel(o, s);
#pragma omp for schedule(static)
      for (int t = 0; t < nt; ++t) tet_kernel(o, t);
#pragma omp for schedule(static)
      for (int i = 0; i < n; ++i) {
        if (fixed[i]) {
          out.col(i).setZero();
          continue;
        }
        Eigen::Vector3d sum = thread_buffers_[0].col(i);
        for (std::size_t k = 1; k < thread_buffers_.size(); ++k) sum += thread_buffers_[k].col(i);
        out.col(i) = sum + (mass_[i] + h * mass_damping_[i]) * p.col(i);
      }
    }
  }
  for (int id : attachments_.active()) {
    const Attachment& a = attachments_[id];
    const Eigen::Vector3d pp = a.point(p);
    for (int k = 0; k < a.count; ++k) {
      if (fixed[a.vertices[k]]) continue;
      out.col(a.vertices[k]) += h * h * a.stiffness_mN_per_mm * a.weights[k] * pp;
    }
  }
  pq = dot(threads_, p, out);
  return pq;
}

void MassSpringModel::precondition_with_laplacian(const Eigen::Matrix3Xd& r, Eigen::Matrix3Xd& z, double h) {
  // The CG matrix is M + hC + h^2 K (velocity form) and the local/global matrix A bounds
  // M/h^2 + C/h + K from above (docs/sim.md), so z = A^-1 r / h^2 (fixed rows zero).
  // After a cut, until the new factor is ready: the old factor and the diagonal instead.
  const int n = static_cast<int>(r.cols());
  for (int i = 0; i < n; ++i) {
    const int fi = free_index_[static_cast<std::size_t>(i)];
    if (fi >= 0) lg_rhs_.row(fi) = r.col(i).transpose();
  }
  if (factor_stale_) {
    prepare_stale_preconditioner(h);
    stale_precondition(lg_rhs_, lg_dx_);
  } else {
    system_.solve(lg_rhs_, lg_dx_, threads_);
  }
  const double inv_h2 = 1.0 / (h * h);
  for (int i = 0; i < n; ++i) {
    const int fi = free_index_[static_cast<std::size_t>(i)];
    if (fi >= 0) {
      z.col(i) = inv_h2 * lg_dx_.row(fi).transpose();
    } else {
      z.col(i).setZero();
    }
  }
}

StepSummary MassSpringModel::semi_implicit_substep(double h) {
  if (laplacian_pc_) poll_background_factor(h, false);
  if (laplacian_pc_ && (system_dirty_ || h != system_h_)) {
    std::string error;
    StepSummary failed;
    if (!build_local_global_system(h, error)) {
      failed.healthy = false;
      failed.termination = "factorization_failed";
      failed.warning = "semi_implicit (laplacian preconditioner): " + error;
      return failed;
    }
    ++refactorizations_;
  }
  current_h_ = h;
  assemble(h);
  const int n = static_cast<int>(x_.cols());
  // Jacobi preconditioner: diagonal of M + h C_mass + sum of spring blocks + attachments.
  const auto& ends = springs_.ends;
  scatter(threads_, thread_buffers_, ends, 1.0, diag_, [&](int s) -> Eigen::Vector3d {
    return spring_s1_[s] * spring_dir_[s].cwiseAbs2() + Eigen::Vector3d::Constant(spring_s2_[s]);
  });
  scatter_tets_add(threads_, thread_buffers_, tets_, diag_, [&](int t, std::array<Eigen::Vector3d, 4>& c) {
    if (volume_stiffness_[t] <= 0.0) return false;
    for (int a = 0; a < 4; ++a) c[a] = vol_coef_[t] * vol_grad_[t][a].cwiseAbs2();
    return true;
  });
  for (int i = 0; i < n; ++i) diag_.col(i).array() += mass_[i] + h * mass_damping_[i];
  for (int id : attachments_.active()) {
    const Attachment& a = attachments_[id];
    for (int k = 0; k < a.count; ++k)
      diag_.col(a.vertices[k]).array() += h * h * a.stiffness_mN_per_mm * a.weights[k] * a.weights[k];
  }
  for (int i = 0; i < n; ++i) {
    if (fixed_[static_cast<std::size_t>(i)]) {
      rhs_.col(i).setZero();
      dv_.col(i).setZero();
      diag_.col(i).setOnes();  // a held embedded vertex has no mass here: no 0/0 in the preconditioner
    }
  }
  // PCG warm-started from the previous velocity change.
  StepSummary s;
  const double b_norm = std::sqrt(dot(threads_, rhs_, rhs_));
  apply_system(dv_, q_);
  r_ = rhs_ - q_;
  double r_norm = std::sqrt(dot(threads_, r_, r_));
  if (r_norm > b_norm) {  // the previous velocity change is a worse start than none (a cut, a jolt)
    dv_.setZero();
    r_ = rhs_;
    r_norm = b_norm;
  }
  const double denom = b_norm > 0.0 ? b_norm : 1.0;
  s.initial_residual = r_norm / denom;
  s.termination = "max_iterations";
  if (r_norm <= config_.tolerance * denom) {
    s.termination = "converged";
  } else {
    if (laplacian_pc_) {
      precondition_with_laplacian(r_, z_, h);
    } else {
      z_ = r_.cwiseQuotient(diag_);
    }
    p_ = z_;
    double rz = dot(threads_, r_, z_);
    const int nc = static_cast<int>(r_.size());
    double* DV = dv_.data();
    double* R = r_.data();
    double* Z = z_.data();
    double* PP = p_.data();
    const double* Q = q_.data();
    const double* D = diag_.data();
    for (int it = 0; it < config_.iterations; ++it) {
      const double pq = apply_system(p_, q_);
      if (!(pq > 0.0)) {
        s.termination = "breakdown";
        break;
      }
      const double alpha = rz / pq;
      // One pass: update dv and r, precondition, and both dot products.
      double rr = 0.0, rz_new = 0.0;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) reduction(+ : rr, rz_new) schedule(static)
      for (int k = 0; k < nc; ++k) {
        DV[k] += alpha * PP[k];
        R[k] -= alpha * Q[k];
        Z[k] = R[k] / D[k];
        rr += R[k] * R[k];
        rz_new += R[k] * Z[k];
      }
      if (laplacian_pc_) {
        precondition_with_laplacian(r_, z_, h);
        rz_new = dot(threads_, r_, z_);
      }
      ++s.iterations;
      r_norm = std::sqrt(rr);
      if (r_norm <= config_.tolerance * denom) {
        s.termination = "converged";
        break;
      }
      const double beta = rz_new / rz;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) schedule(static)
      for (int k = 0; k < nc; ++k) PP[k] = Z[k] + beta * PP[k];
      rz = rz_new;
    }
  }
  s.final_residual = r_norm / denom;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) schedule(static)
  for (int i = 0; i < n; ++i) {
    if (fixed_[static_cast<std::size_t>(i)]) continue;
    v_.col(i) += dv_.col(i);
    x_.col(i) += h * v_.col(i);
  }
  return s;
}

StepSummary MassSpringModel::step(double dt_s) {
  StepSummary s = step_guarded(dt_s);
  embedded_.drive(x_, v_, dt_s, gravity_);  // embedded vertices follow their drivers / rigid groups
  return s;
}

StepSummary MassSpringModel::semi_implicit_guarded(double dt_s) {
  // Step control (docs/sim.md, step_control.hpp): one linearised backward-Euler step follows an
  // element only while its motion in the step is small against its size. Elements far below
  // the mesh's resolution (what a cut leaves between its sweeps) can move by their own size in
  // a frame; the step then creates energy or inverts them. Such a step is undone and redone
  // with 2, 4, ... times the substeps (up to the step's budget, SubstepControl::budget_factor), the factor that held kept until the
  // tissue calms; counted (retries(), step_control()) and named in the warning.
  InversionMonitor inversions0;
  const int substeps = config_.substeps;
  return control_.run(
      [&] {
        x_before_step_ = x_;
        v_before_step_ = v_;
        inversions0 = inversions_;
      },
      [&] {
        x_ = x_before_step_;
        v_ = v_before_step_;
        inversions_ = inversions0;
        dv_.setZero();
      },
      [&](int factor) {
        config_.substeps = substeps * factor;
        StepSummary s = step_unguarded(dt_s);
        config_.substeps = substeps;
        return s;
      },
      SubstepControl::budget_factor(dt_s));
}

StepSummary MassSpringModel::step_guarded(double dt_s) {
  check_dt(dt_s);
  if (integrator_ == Integrator::kSemiImplicit) return semi_implicit_guarded(dt_s);
  // Fallback (docs/sim.md): the explicit and local/global integrators diverge on extreme
  // boundaries (an organ hanging from a small patch: nearly every tet flips within
  // 0.1-0.6 s). A step that ends unhealthy (non-finite state, energy created, collapse) is
  // undone and redone with the semi-implicit integrator (unconditionally stable), which
  // then also takes the next kFallbackSpan_s of simulated time; named in the warning.
  constexpr double kFallbackSpan_s = 1.0;
  auto semi_implicit_step = [&]() {
    const Integrator integrator = integrator_;
    const ModelConfig config = config_;
    integrator_ = Integrator::kSemiImplicit;
    config_.substeps = 1;
    config_.iterations = 20;
    config_.tolerance = 1e-4;
    StepSummary s = semi_implicit_guarded(dt_s);
    integrator_ = integrator;
    config_ = config;
    return s;
  };
  if (fallback_left_s_ > 0.0) {
    StepSummary s = semi_implicit_step();
    fallback_left_s_ -= dt_s;
    if (s.healthy)
      report(s, "fallback: semi_implicit integrator for another " + std::to_string(std::max(fallback_left_s_, 0.0)) + " s", false);
    return s;
  }
  x_before_step_ = x_;
  v_before_step_ = v_;
  const InversionMonitor inversions0 = inversions_;
  StepSummary first = step_unguarded(dt_s);
  if (first.healthy && integrator_ == Integrator::kExplicit)  // the factor its stability bound took
    control_.count_step_at((first.iterations + config_.substeps - 1) / config_.substeps);
  if (first.healthy || first.termination == "refused_unstable_dt") return first;
  x_ = x_before_step_;  // restored before the redo saves its own start in the same buffers
  v_ = v_before_step_;
  inversions_ = inversions0;
  StepSummary s = semi_implicit_step();
  ++fallbacks_;
  if (s.healthy) {
    fallback_left_s_ = kFallbackSpan_s - dt_s;
    report(s, name() + " diverged (" + first.warning.substr(0, 160) + "): step undone and redone with the semi_implicit "
                        "integrator, which takes the next " + std::to_string(kFallbackSpan_s) + " s (fallback)", false);
  }
  return s;
}

StepSummary MassSpringModel::step_unguarded(double dt_s) {
  const auto start = std::chrono::steady_clock::now();
  StepSummary summary;
  double h = dt_s / config_.substeps;
  int substeps = config_.substeps;
  if (integrator_ == Integrator::kExplicit) {
    substeps = explicit_substeps(dt_s);
    if (substeps == 0) {
      report(summary,
             "explicit mass-spring: substep " + std::to_string(h) + " s exceeds the stability bound " +
                 std::to_string(explicit_stable_substep_s()) + " s (2/omega_max) even at the step control's budget of " +
                 std::to_string(SubstepControl::budget_substeps(config_.substeps, dt_s)) +
                 " substeps; step not taken: use substeps >= " +
                 std::to_string(explicit_substeps_needed(dt_s)) + " or integrator semi_implicit",
             true);
      summary.termination = "refused_unstable_dt";
    } else {
      if (substeps != config_.substeps) report(summary, explicit_substeps_warning(dt_s, substeps), false);
      h = dt_s / substeps;
      for (int k = 0; k < substeps; ++k) explicit_substep(h);
      summary.iterations = substeps;
      summary.termination = "explicit";
    }
  } else {
    for (int k = 0; k < config_.substeps; ++k) {
      const StepSummary sub = integrator_ == Integrator::kLocalGlobal ? local_global_substep(h) : semi_implicit_substep(h);
      if (!sub.healthy) {  // the system could not be factored: state untouched
        report(summary, sub.warning, true);
        summary.termination = sub.termination;
        break;
      }
      if (k == 0) summary.initial_residual = sub.initial_residual;
      summary.final_residual = sub.final_residual;
      summary.iterations += sub.iterations;
      summary.termination = sub.termination;
    }
  }
  if (integrator_ == Integrator::kLocalGlobal && config_.tolerance > 0.0 && summary.final_residual > config_.tolerance &&
      summary.healthy) {
    report(summary,
           "local_global not converged: relative residual " + std::to_string(summary.final_residual) +
               " before the last of " + std::to_string(config_.iterations) + " iterations (raise iterations)",
           false);
  }
  if (integrator_ == Integrator::kSemiImplicit && summary.final_residual > kUnconvergedResidual) {
    report(summary,
           "CG not converged: relative residual " + std::to_string(summary.final_residual) + " after " +
               std::to_string(config_.iterations) + " iterations (raise iterations)",
           false);
  }
  if (vessels_ignored_) {
    report(summary, "vessel tree ignored: this model has no beam coupling (model vessels as a stiff tet region, or use corotational_fem)", false);
  }
  check_state(x_, v_, summary);
  const StateMeasure measure = measure_state();
  const int inverted = measure.inverted_tets;
  // Springs have no orientation: inverted tets recover only if the volume term and their
  // neighbours push them back. A counted warning; unhealthy only for a collapse
  // (step_health.hpp, docs/sim.md).
  inversions_.update(inverted, static_cast<int>(tets_.size()), dt_s, summary);
  summary.kinetic_energy = kinetic_energy(mass_, v_);
  summary.elastic_energy = measure.elastic_energy;
  ledger_.check(summary.kinetic_energy + summary.elastic_energy, gravity_potential(mass_, x_, gravity_), summary);
  summary.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

MassSpringModel::StateMeasure MassSpringModel::measure_state() const {
  // One pass over springs and one over tets (parallel): stored energy and inverted tets.
  const auto& ends = springs_.ends;
  const int ns = springs_.size();
  const double* X = x_.data();
  double e = 0.0;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) reduction(+ : e) schedule(static)
  for (int s = 0; s < ns; ++s) {
    const int i = ends[s][0], j = ends[s][1];
    const double dx = X[3 * j] - X[3 * i], dy = X[3 * j + 1] - X[3 * i + 1], dz = X[3 * j + 2] - X[3 * i + 2];
    const double stretch = std::sqrt(dx * dx + dy * dy + dz * dz) - springs_.rest_length_mm[s];
    e += 0.5 * springs_.stiffness_mN_per_mm[s] * stretch * stretch;
  }
  const int nt = static_cast<int>(tets_.size());
  int inverted = 0;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) reduction(+ : e, inverted) schedule(static)
  for (int t = 0; t < nt; ++t) {
    const auto& v = tets_[t];
    const Eigen::Vector3d x0 = x_.col(v[0]);
    const double six_v = (x_.col(v[1]) - x0).dot((x_.col(v[2]) - x0).cross(x_.col(v[3]) - x0));
    if (!(six_v > 0.0) && !passive(t)) ++inverted;  // a passive tet (no elastic term) may flatten
    e += volume_energy(six_v * inv_6v0_[t], volume_stiffness_[t]);
  }
  return {e + attachments_.energy(x_), inverted};
}

double MassSpringModel::elastic_energy() const { return measure_state().elastic_energy; }

std::vector<ElementMeasure> MassSpringModel::element_measures() const {
  std::vector<ElementMeasure> out(tets_.size());
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const Eigen::Matrix3d F = deformation_gradient(x_, tets_[t], Dm_inv_[t]);
    out[t] = element_measure_from(F, corotated_linear_stress_kPa(F, tet_lame_[t]));
  }
  return out;
}

}  // namespace arnav::host
