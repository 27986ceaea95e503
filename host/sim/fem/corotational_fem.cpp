#include "host/sim/fem/corotational_fem.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "host/sim/model_setup.hpp"
#include "host/sim/element_measure.hpp"
#include "host/sim/fem/blas_threads.hpp"
#include "host/sim/fem/fem_mesh_change.hpp"
#include "host/sim/fem/rotation_extraction.hpp"
#include "host/sim/fem/stable_neo_hookean_fem.hpp"
#include "host/sim/tet_geometry.hpp"

namespace arnav::host {
namespace {

// Warm-started per step: 1-2 updates; the cap only matters after set_state or a violent step.
constexpr RotationExtraction kStepRotation{.max_iterations = 12, .tolerance_rad = 1e-9};

// Rotation of a tet (invertible FEM, Irving, Teran & Fedkiw 2004): for an inverted or
// nearly flat tet (det F below kFlatJ) the rotation is taken in closed form from the SVD,
// R = U diag(1, 1, det(U V^T)) V^T: the reflection goes into the smallest singular value,
// so R^T F = V diag(s1, s2, +-s3) V^T is symmetric and the co-rotated stress pushes the
// element back through its flat state along the shortest way. The warm-started iteration
// is kept for all other tets (it is the polar rotation there and cheaper): started from the
// previous rotation of a tet that flipped through, it can stop at a saddle of tr(R^T F)
// and push the tet further in. Both give the same R for det F > 0 (polar rotation).
constexpr double kFlatJ = 0.05;
inline Eigen::Quaterniond element_rotation(const Eigen::Matrix3d& F, double J, const Eigen::Quaterniond& q_warm) {
  if (J < kFlatJ) return rotation_by_svd(F);
  return extract_rotation(F, q_warm, kStepRotation);
}

Eigen::Map<Eigen::VectorXd> flat(Eigen::Matrix3Xd& m) { return {m.data(), m.size()}; }

double process_cpu_ms() { return 1000.0 * static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }
double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

// Adds the 3x3 block B into the pattern through its 9 map entries (-1: skipped).
inline void scatter(double* values, const int* map, const Eigen::Matrix3d& B) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (map[3 * r + c] >= 0) values[map[3 * r + c]] += B(r, c);
}

// A tet's 10 blocks in the lower-triangular compressed-column pattern, 3 indices per block
// instead of 9: the three rows of a vertex are consecutive in every column (3 DOF per
// vertex), so a block is three runs of consecutive entries. For the pair (a, b), a <= b:
//   a == b         run k starts at the diagonal entry of column 3v+k (rows k..2);
//   v[a] > v[b]    run k is column 3v[b]+k, rows 3v[a]+0..2: B(r, k) -> start + r;
//   v[a] < v[b]    run k is column 3v[a]+k, rows 3v[b]+0..2: B(k, c) -> start + c.
// Derived from and checked against the full 9-index map (throws if the layout differs).
void compact_block_map(const std::array<int, 4>& v, const std::vector<int>& full, int* out) {
  for (int a = 0, pair = 0; a < 4; ++a)
    for (int b = a; b < 4; ++b, ++pair) {
      const int* m = full.data() + 9 * pair;
      for (int k = 0; k < 3; ++k) {
        const int start = a == b ? m[3 * k + k] : (v[a] > v[b] ? m[k] : m[3 * k]);
        out[3 * pair + k] = start;
        for (int j = 0; j < 3; ++j) {
          const int expect = a == b ? (j >= k ? m[3 * j + k] : -1) : (v[a] > v[b] ? m[3 * j + k] : m[3 * k + j]);
          const int got = a == b ? (j >= k ? start + j - k : -1) : start + j;
          if (expect != got) throw std::logic_error("corotational_fem: unexpected sparsity layout of a tet block");
        }
      }
    }
}

// Tets in the order of a Morton (Z-order) curve through their centroids, 10 bits per
// axis: consecutive tets then share vertices, so the gathers of positions and the
// scatters of forces and stiffness blocks mostly hit the cache (bundled liver: assembly
// 9.1 -> 7.3 ms CPU on one core; TetGen's own order is its insertion order).
std::vector<int> spatial_order(const Eigen::Matrix3Xd& X, const std::vector<std::array<int, 4>>& tets) {
  const Eigen::Vector3d lo = X.rowwise().minCoeff(), extent = X.rowwise().maxCoeff() - lo;
  std::vector<std::pair<std::uint32_t, int>> key(tets.size());
  for (std::size_t t = 0; t < tets.size(); ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int v : tets[t]) c += 0.25 * X.col(v);
    std::uint32_t q[3], code = 0;
    for (int d = 0; d < 3; ++d)
      q[d] = static_cast<std::uint32_t>(std::clamp(1023.0 * (c[d] - lo[d]) / std::max(extent[d], 1e-12), 0.0, 1023.0));
    for (int bit = 9; bit >= 0; --bit)
      for (int d = 0; d < 3; ++d) code = (code << 1) | ((q[d] >> bit) & 1u);
    key[t] = {code, static_cast<int>(t)};
  }
  std::sort(key.begin(), key.end());
  std::vector<int> order(tets.size());
  for (std::size_t i = 0; i < key.size(); ++i) order[i] = key[i].second;
  return order;
}

}  // namespace

CorotationalFem::CorotationalFem(const SimProblem& problem, const ModelConfig& config, const FemOptions& options)
    : integrator_(config.integrator.empty() ? "implicit_euler" : config.integrator),
      options_(options),
      threads_(config.threads),
      substeps_(config.substeps),
      gravity_(problem.gravity_World_mm_s2),
      solver_(FemLinearSolver::parse(config.linear_solver.empty() ? "pcg" : config.linear_solver),
              config.refactor_every, config.iterations, config.tolerance) {
  if (integrator_ != "implicit_euler" && integrator_ != "quasi_static") {
    throw std::invalid_argument("corotational_fem: unknown integrator '" + integrator_ +
                                "' (use implicit_euler or quasi_static)");
  }
  if (threads_ < 1) throw std::invalid_argument("corotational_fem: threads must be >= 1");
  if (substeps_ < 1) throw std::invalid_argument("corotational_fem: substeps must be >= 1");
  const TetMesh& mesh = problem.mesh;
  if (mesh.num_tets() == 0) throw std::invalid_argument("corotational_fem: the mesh has no tetrahedra");
  if (!gravity_.allFinite()) throw std::invalid_argument("corotational_fem: gravity is not finite");
  X_ = mesh.rest_positions_World_mm;
  x_ = X_;
  v_ = Eigen::Matrix3Xd::Zero(3, X_.cols());
  mass_ = checked_masses_kg(problem, "corotational_fem");
  const int nv = mesh.num_vertices();
  mass_damped_ = mass_;
  tets_.resize(mesh.tets.size());
  tet_order_ = spatial_order(X_, mesh.tets);
  Eigen::VectorXd mass_alpha = Eigen::VectorXd::Zero(nv);
  quarter_mass_.resize(tets_.size());
  quarter_alpha_.resize(tets_.size());
  for (int i = 0; i < mesh.num_tets(); ++i) {
    const int t = tet_order_[i];  // mesh index of stored tet i
    tets_[i] = make_element(problem, t, quarter_mass_[i], quarter_alpha_[i]);
    for (int v : tets_[i].v) mass_alpha[v] += quarter_alpha_[i];
  }
  apply_embedding(problem, mass_alpha);
  mass_damped_ = mass_;
  mass_alpha_ = mass_alpha;
  q_.assign(tets_.size(), Eigen::Quaterniond::Identity());

  // Beams only when the scene declares vessels.
  if (problem.vessels && !problem.vessels->segments.empty()) {
    lame_from(problem.vessel_material);  // validates E and nu
    embedding_ = embed_vessels(mesh, *problem.vessels, problem.vessel_material, options_.beams);
    std::vector<int> stored(tet_order_.size());  // mesh tet -> stored index
    for (std::size_t i = 0; i < tet_order_.size(); ++i) stored[tet_order_[i]] = static_cast<int>(i);
    for (const EmbeddedBeam& b : embedding_->beams) {
      Beam beam;
      beam.v = b.vertices;
      beam.K = b.K_rest;
      beam.X.resize(3 * b.vertices.size());
      for (std::size_t k = 0; k < b.vertices.size(); ++k) beam.X.segment<3>(3 * k) = X_.col(b.vertices[k]);
      beam.tets = {stored[b.tets[0]], stored[b.tets[1]]};
      beam.beta = problem.vessel_material.damping_stiffness_s;
      beams_.push_back(std::move(beam));
    }
    R_beam_.assign(beams_.size(), Eigen::Matrix3d::Identity());
  }
  check_vertex_indices(problem.fixed_vertices, nv, "corotational_fem: fixed vertices");
  user_fixed_.assign(nv, 0);
  for (int v : problem.fixed_vertices) user_fixed_[v] = 1;
  merge_fixed_with_embedding();
  solver_.set_refresh_residual(options_.refresh_residual);
  solver_.set_background_refactor(config.refactor_in_background);
  if (options_.background_nice < 0 || options_.background_nice > 19)
    throw std::invalid_argument("corotational_fem: background_nice must be in [0, 19]");
  solver_.set_background_nice(options_.background_nice);
  set_cut_region_rings(options_.cut_region_rings);
  if (config.single_precision_preconditioner && solver_.kind() != FemLinearSolver::Kind::PcgFactor) {
    throw std::invalid_argument("corotational_fem: single_precision_preconditioner needs linear_solver pcg");
  }
  solver_.set_single_precision_preconditioner(config.single_precision_preconditioner);
  if (config.blas_threads < 0) throw std::invalid_argument("corotational_fem: blas_threads must be >= 0 (0 = leave the BLAS as set)");
  if (config.blas_threads > 0 && !set_blas_threads(config.blas_threads) && config.blas_threads > 1) {
    // Said once, in the first step's warning: the run is valid, only slower than asked.
    note_ = "blas_threads " + std::to_string(config.blas_threads) +
            " asked for, but the BLAS is not OpenBLAS (install libopenblas0-pthread): CHOLMOD runs on one thread";
  }
  build_pattern();
}

CorotationalFem::~CorotationalFem() = default;

void CorotationalFem::set_cut_region_rings(int rings) {
  if (rings < -1) throw std::invalid_argument("corotational_fem: cut_region_rings must be >= -1 (-1: no cut-region correction)");
  solver_.set_cut_region_rings(rings);
}

CorotationalFem::Tet CorotationalFem::make_element(const SimProblem& problem, int t, double& quarter_mass,
                                                   double& quarter_alpha) const {
  const fem::RestTet r = fem::rest_tet(problem, t, "corotational_fem");
  Tet e;
  e.v = r.v;
  e.Dm_inv = r.Dm_inv;
  e.g = r.g;
  e.volume = r.volume;
  e.mu = r.mu;
  e.lambda = r.lambda;
  e.beta = r.beta;
  e.passive = r.passive;  // below the quality bound: no elastic term
  quarter_mass = r.quarter_mass;
  quarter_alpha = r.quarter_alpha;
  return e;
}

std::optional<MeshChangeStats> CorotationalFem::apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed,
                                                                  const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  const TetMesh& mesh = problem.mesh;
  const int n_old = static_cast<int>(X_.cols()), n = mesh.num_vertices();
  const int nt_old = static_cast<int>(tets_.size());
  if (!fem::mesh_change_fits(problem, changed, n_old, nt_old, x, v)) return std::nullopt;
  if (stored_of_mesh_.size() != tet_order_.size()) {  // once: mesh tet -> stored tet
    stored_of_mesh_.assign(tet_order_.size(), -1);
    for (std::size_t i = 0; i < tet_order_.size(); ++i) stored_of_mesh_[static_cast<std::size_t>(tet_order_[i])] = static_cast<int>(i);
  }
  // New elements and masses, checked before anything changes.
  std::vector<Tet> fresh(changed.size());
  std::vector<fem::TetChange> changes(changed.size());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    fem::TetChange& c = changes[i];
    fresh[i] = make_element(problem, changed[i], c.mass_after, c.alpha_after);
    c.after = fresh[i].v;
    if (changed[i] < nt_old) {
      const auto s = static_cast<std::size_t>(stored_of_mesh_[static_cast<std::size_t>(changed[i])]);
      c.existed = true;
      c.before = tets_[s].v;
      c.mass_before = quarter_mass_[s];
      c.alpha_before = quarter_alpha_[s];
    }
  }
  // Vertices whose records change: those of the changed tets before and after, the appended ones.
  const std::vector<int> touched = fem::touched_vertices(changes, n_old, n);
  // Vessel beams are embedded in tets with the rest shape of their vertices: a cut through
  // them needs a new embedding (the caller rebuilds).
  const auto is_touched = [&](int w) { return std::binary_search(touched.begin(), touched.end(), w); };
  for (const Beam& b : beams_) {
    for (int w : b.v)
      if (is_touched(w)) return std::nullopt;
    for (int s : b.tets)
      if (std::binary_search(changed.begin(), changed.end(), tet_order_[static_cast<std::size_t>(s)])) return std::nullopt;
  }
  if (pair_tets_.empty())  // once, O(tets): the pairs the tets couple before the cut
    for (const Tet& t : tets_) pair_tets_.add(t.v);

  // Vertex records: rest position, masses, state, fixed flags and the embedding.
  MeshChangeStats stats;
  stats.vertices_updated = fem::update_vertex_records(problem, changes, touched, x, v, embedded_,
                                                      {X_, x_, v_, mass_, mass_alpha_, fixed_, user_fixed_}, "corotational_fem");
  mass_damped_.conservativeResize(n);
  for (int w = 0; w < n; ++w) mass_damped_[w] = last_dt_ > 0.0 ? mass_[w] + last_dt_ * mass_alpha_[w] : mass_[w];
  if (last_dx_.size() > 0) {
    last_dx_.conservativeResize(3 * static_cast<Eigen::Index>(n));
    last_dx_.tail(3 * static_cast<Eigen::Index>(n - n_old)).setZero();
  }

  // Element records: changed tets in their slots, appended ones at the end.
  std::vector<int> stored_changed(changed.size());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    const int t = changed[i];
    int s;
    if (t < nt_old) {
      s = stored_of_mesh_[static_cast<std::size_t>(t)];
    } else {
      s = static_cast<int>(tets_.size());
      tets_.emplace_back();
      q_.emplace_back();
      quarter_mass_.push_back(0.0);
      quarter_alpha_.push_back(0.0);
      tet_order_.push_back(t);
      stored_of_mesh_.push_back(s);  // changed is sorted: t == stored_of_mesh_.size() - 1
    }
    tets_[static_cast<std::size_t>(s)] = fresh[i];
    quarter_mass_[static_cast<std::size_t>(s)] = changes[i].mass_after;
    quarter_alpha_[static_cast<std::size_t>(s)] = changes[i].alpha_after;
    // Warm-start rotation from the current shape, in closed form (as set_state does).
    q_[static_cast<std::size_t>(s)] = rotation_by_svd(edge_matrix(x_, fresh[i].v) * fresh[i].Dm_inv);
    stored_changed[i] = s;
    ++stats.elements_updated;
  }
  // Passive flags of unchanged tets can change too (islands of good tets cut off by slivers).
  for (std::size_t i = 0; i < tets_.size(); ++i) tets_[i].passive = problem.embedded.is_passive(tet_order_[i]);
  grow_pattern(stored_changed, n_old, changes);
  fem::update_partition(partition_, stored_changed, nt_old, static_cast<int>(tets_.size()));
  inversions_.reset_episode();  // as for a model rebuilt on the cut mesh (set_state)
  return stats;
}

std::vector<int> CorotationalFem::preconditioner_aliases(const std::vector<int>& stored_changed, int n_old) const {
  const int n = static_cast<int>(X_.cols());
  std::vector<int> alias(static_cast<std::size_t>(n - n_old), -1);
  std::vector<double> best(alias.size(), 1e300);
  for (int round = 0; round < 4; ++round) {
    bool missing = false;
    for (int s : stored_changed) {
      const auto& tet = tets_[static_cast<std::size_t>(s)].v;
      for (int w : tet) {
        if (w < n_old || fixed_[static_cast<std::size_t>(w)] || (round > 0 && alias[static_cast<std::size_t>(w - n_old)] >= 0)) continue;
        for (int u : tet) {
          // Round 0: older free neighbours; later rounds: new neighbours aggregated already.
          const int target = u < n_old ? (round == 0 && !fixed_[static_cast<std::size_t>(u)] ? u : -1)
                                       : (round > 0 ? alias[static_cast<std::size_t>(u - n_old)] : -1);
          if (u == w || target < 0) continue;
          const double d = (X_.col(u) - X_.col(w)).squaredNorm();
          if (d < best[static_cast<std::size_t>(w - n_old)]) {
            best[static_cast<std::size_t>(w - n_old)] = d;
            alias[static_cast<std::size_t>(w - n_old)] = target;
          }
        }
        missing = missing || alias[static_cast<std::size_t>(w - n_old)] < 0;
      }
    }
    if (!missing) break;
  }
  return alias;
}

void CorotationalFem::grow_pattern(const std::vector<int>& stored_changed, int old_vertices,
                                   const std::vector<fem::TetChange>& changes) {
  const int n = static_cast<int>(X_.cols());
  std::vector<std::vector<int>> groups;
  groups.reserve(stored_changed.size());
  for (int s : stored_changed) groups.emplace_back(tets_[static_cast<std::size_t>(s)].v.begin(), tets_[static_cast<std::size_t>(s)].v.end());
  // Vertex pairs no tet couples any more leave the pattern (as in a model built on the cut
  // mesh), unless an attachment (removed ones keep their entries) or a beam couples them.
  std::vector<std::vector<int>> kept;
  attachments_.append_groups(kept);
  for (const Beam& b : beams_) kept.push_back(b.v);
  const std::vector<std::pair<int, int>> drop = pair_tets_.update(changes, kept);
  std::vector<std::vector<int>*> maps{&tet_map_};
  for (auto& map : beam_maps_) maps.push_back(&map);
  if (fem::grow_pattern(pattern_, n, groups, drop, maps)) {
    attachments_.map_into(*pattern_);
    A_ = pattern_->matrix();
  }
  tet_map_.resize(30 * tets_.size());
  for (std::size_t i = 0; i < stored_changed.size(); ++i) {
    const int s = stored_changed[i];
    const std::vector<int> full = pattern_->block_map(groups[i]);
    compact_block_map(tets_[static_cast<std::size_t>(s)].v, full, tet_map_.data() + 30 * static_cast<std::ptrdiff_t>(s));
  }
  update_fixed_entries();
  // As for the lagged refactorisation: with refactor_in_background, PCG on the old factor
  // (padded) while the new pattern is factorised on a worker; otherwise (deterministic) and
  // for the direct kinds, the new pattern is factorised (analysis included) at the next solve.
  if (solver_.background_refactor()) {
    solver_.pattern_extended(old_vertices, preconditioner_aliases(stored_changed, old_vertices),
                             fem::touched_vertices(changes, old_vertices, n));
  } else {
    solver_.pattern_changed();
  }
}

void CorotationalFem::apply_embedding(const SimProblem& problem, Eigen::VectorXd& mass_alpha) {
  std::vector<int> touched;
  embedded_.reset(problem.embedded, X_, x_, v_);
  embedded_.move_mass({&mass_, &mass_alpha}, touched, &problem.region_materials);
}

void CorotationalFem::merge_fixed_with_embedding() {
  fixed_.assign(user_fixed_.size(), 0);
  for (std::size_t i = 0; i < fixed_.size(); ++i) fixed_[i] = user_fixed_[i] || embedded_.held(static_cast<int>(i)) ? 1 : 0;
}

void CorotationalFem::build_pattern() {
  const int nv = static_cast<int>(X_.cols());
  std::vector<std::vector<int>> elements;
  elements.reserve(tets_.size() + beams_.size());
  for (const Tet& t : tets_) elements.emplace_back(t.v.begin(), t.v.end());
  for (const Beam& b : beams_) elements.push_back(b.v);
  std::vector<std::vector<int>> groups = elements;
  attachments_.append_groups(groups);
  pattern_ = std::make_unique<SymmetricPattern>(nv, groups);
  tet_map_.resize(30 * tets_.size());
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const std::vector<int> full = pattern_->block_map(elements[t]);
    compact_block_map(tets_[t].v, full, tet_map_.data() + 30 * static_cast<std::ptrdiff_t>(t));
  }
  beam_maps_.clear();
  for (const Beam& b : beams_) beam_maps_.push_back(pattern_->block_map(b.v));
  attachments_.map_into(*pattern_);
  partition_ = partition_elements(X_, elements, threads_);
  A_ = pattern_->matrix();
  update_fixed_entries();
  solver_.pattern_changed();
}

void CorotationalFem::update_fixed_entries() {
  fixed_entries_.clear();
  for (int c = 0; c < A_.outerSize(); ++c)
    for (int k = A_.outerIndexPtr()[c]; k < A_.outerIndexPtr()[c + 1]; ++k) {
      const int r = A_.innerIndexPtr()[k];
      if (r != c && (fixed_[r / 3] || fixed_[c / 3])) fixed_entries_.push_back(k);
    }
}

CorotationalFem::AssemblyStats CorotationalFem::assemble(double dt_s, bool dynamic) {
  double* values = A_.valuePtr();
  std::fill(values, values + A_.nonZeros(), 0.0);
  f_.setZero(x_.size());
  f_ext_.setZero(x_.size());
  // Beams first: a beam co-rotates with the mean deformation of the two tets that hold
  // its ends (warm start: the rotation of its first tet from the last step).
  for (std::size_t b = 0; b < beams_.size(); ++b) {
    const Tet& t0 = tets_[beams_[b].tets[0]];
    const Tet& t1 = tets_[beams_[b].tets[1]];
    const Eigen::Matrix3d F = 0.5 * (edge_matrix(x_, t0.v) * t0.Dm_inv + edge_matrix(x_, t1.v) * t1.Dm_inv);
    R_beam_[b] = extract_rotation(F, q_[beams_[b].tets[0]], kStepRotation).toRotationMatrix();
  }
  double energy = 0.0, max_strain = 0.0;
  int n_inverted = 0;
  // Per element: rotation, forces and rotated stiffness in one pass over the element data;
  // parts are vertex-disjoint (no write conflicts), the interface elements follow
  // serially: one synchronisation per step.
  const int parts = static_cast<int>(partition_.parts.size());
#pragma omp parallel for schedule(static, 1) reduction(+ : energy, n_inverted) reduction(max : max_strain) \
    num_threads(threads_) if (threads_ > 1)
  for (int part = 0; part < parts; ++part)
    for (int id : partition_.parts[part]) assemble_element(id, dt_s, dynamic, energy, n_inverted, max_strain);
  for (int id : partition_.shared) assemble_element(id, dt_s, dynamic, energy, n_inverted, max_strain);
  // Attachments: zero-rest-length springs from material points to targets.
  const double s_att = dynamic ? dt_s * dt_s : 1.0;
  for (const auto& att : attachments_) {
    if (!att) continue;
    const MaterialPoint& p = att->spec.point;
    const double k = att->spec.stiffness_mN_per_mm;
    Eigen::Vector3d pos = Eigen::Vector3d::Zero();
    for (std::size_t a = 0; a < p.vertices.size(); ++a) pos += p.weights[a] * x_.col(p.vertices[a]);
    const Eigen::Vector3d pull = k * (att->spec.target_World_mm - pos);
    const int nb = static_cast<int>(p.vertices.size());
    for (int a = 0, pair = 0; a < nb; ++a) {
      f_ext_.segment<3>(3 * p.vertices[a]) += p.weights[a] * pull;
      for (int b = a; b < nb; ++b, ++pair)
        scatter(values, att->map.data() + 9 * pair,
                (s_att * k * p.weights[a] * p.weights[b]) * Eigen::Matrix3d::Identity());
    }
  }
  if (dynamic)
    for (int i = 0; i < static_cast<int>(X_.cols()); ++i)
      for (int d = 0; d < 3; ++d) values[pattern_->diagonal()[3 * i + d]] += mass_damped_[i];
  return {energy, n_inverted, max_strain};
}

void CorotationalFem::assemble_element(int id, double dt_s, bool dynamic, double& energy, int& n_inverted,
                                       double& max_strain) {
  double* values = A_.valuePtr();
  const int num_tets = static_cast<int>(tets_.size());
  if (id < num_tets) {
    const Tet& e = tets_[id];
    if (e.passive) return;  // below the quality bound: no elastic term (its block stays zero)
    Eigen::Matrix3d Ds;
    for (int k = 0; k < 3; ++k) Ds.col(k) = x_.col(e.v[k + 1]) - x_.col(e.v[0]);
    const Eigen::Matrix3d F = Ds * e.Dm_inv;
    const double J = F.determinant();
    q_[id] = element_rotation(F, J, q_[id]);
    const Eigen::Matrix3d R = q_[id].toRotationMatrix();
    if (J <= 0.0) ++n_inverted;
    const Eigen::Matrix3d S = R.transpose() * F;
    const Eigen::Matrix3d eps = 0.5 * (S + S.transpose()) - Eigen::Matrix3d::Identity();
    const double tr = eps.trace();
    max_strain = std::max(max_strain, eps.cwiseAbs().maxCoeff());
    const Eigen::Matrix3d sigma = e.lambda * tr * Eigen::Matrix3d::Identity() + 2.0 * e.mu * eps;
    energy += e.volume * (e.mu * eps.squaredNorm() + 0.5 * e.lambda * tr * tr);
    const Eigen::Matrix3d P = e.volume * R * sigma;
    std::array<Eigen::Vector3d, 4> h;
    for (int a = 0; a < 4; ++a) {
      f_.segment<3>(3 * e.v[a]) -= P * e.g[a];
      h[a] = R * e.g[a];
    }
    // R K_ab R^T = V (lambda h_a h_b^T + mu h_b h_a^T + mu (g_a . g_b) I), h = R g.
    const double s = dynamic ? dt_s * e.beta + dt_s * dt_s : 1.0;
    const double sv = s * e.volume;
    const int* map = tet_map_.data() + 30 * static_cast<std::ptrdiff_t>(id);
    for (int a = 0, pair = 0; a < 4; ++a)
      for (int b = a; b < 4; ++b, ++pair) {
        Eigen::Matrix3d B = sv * (e.lambda * h[a] * h[b].transpose() + e.mu * h[b] * h[a].transpose());
        B.diagonal().array() += sv * e.mu * e.g[a].dot(e.g[b]);
        const int* run = map + 3 * pair;  // compact_block_map
        if (a == b) {
          for (int k = 0; k < 3; ++k)
            for (int r = k; r < 3; ++r) values[run[k] + r - k] += B(r, k);
        } else if (e.v[a] > e.v[b]) {
          for (int k = 0; k < 3; ++k)
            for (int r = 0; r < 3; ++r) values[run[k] + r] += B(r, k);
        } else {
          for (int k = 0; k < 3; ++k)
            for (int c = 0; c < 3; ++c) values[run[k] + c] += B(k, c);
        }
      }
  } else {
    const int bi = id - num_tets;
    const Beam& bm = beams_[bi];
    const Eigen::Matrix3d& R = R_beam_[bi];
    const int nb = static_cast<int>(bm.v.size());
    Eigen::VectorXd u(3 * nb);
    for (int a = 0; a < nb; ++a) u.segment<3>(3 * a) = R.transpose() * x_.col(bm.v[a]) - bm.X.segment<3>(3 * a);
    const Eigen::VectorXd fl = bm.K * u;
    energy += 0.5 * u.dot(fl);
    for (int a = 0; a < nb; ++a) f_.segment<3>(3 * bm.v[a]) -= R * fl.segment<3>(3 * a);
    const double s = dynamic ? dt_s * bm.beta + dt_s * dt_s : 1.0;
    const int* map = beam_maps_[bi].data();
    for (int a = 0, pair = 0; a < nb; ++a)
      for (int b = a; b < nb; ++b, ++pair)
        scatter(values, map + 9 * pair, s * R * bm.K.block<3, 3>(3 * a, 3 * b) * R.transpose());
  }
}

double CorotationalFem::external_potential(const Eigen::Matrix3Xd& x) const {
  double e = 0.0;
  for (Eigen::Index i = 0; i < x.cols(); ++i) e -= mass_[i] * gravity_.dot(x.col(i));
  return e + attachments_.energy(x);
}

double CorotationalFem::potential_energy(const Eigen::Matrix3Xd& x) {
  const int num_tets = static_cast<int>(tets_.size());
  double energy = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : energy) num_threads(threads_) if (threads_ > 1)
  for (int t = 0; t < num_tets; ++t) {
    const Tet& e = tets_[t];
    const Eigen::Matrix3d F = edge_matrix(x, e.v) * e.Dm_inv;
    q_[t] = element_rotation(F, F.determinant(), q_[t]);
    const Eigen::Matrix3d S = q_[t].toRotationMatrix().transpose() * F;
    const Eigen::Matrix3d eps = 0.5 * (S + S.transpose()) - Eigen::Matrix3d::Identity();
    const double tr = eps.trace();
    energy += e.volume * (e.mu * eps.squaredNorm() + 0.5 * e.lambda * tr * tr);
  }
  for (const Beam& bm : beams_) {
    const Eigen::Matrix3d F = 0.5 * (edge_matrix(x, tets_[bm.tets[0]].v) * tets_[bm.tets[0]].Dm_inv +
                                     edge_matrix(x, tets_[bm.tets[1]].v) * tets_[bm.tets[1]].Dm_inv);
    const Eigen::Matrix3d R = extract_rotation(F, q_[bm.tets[0]], kStepRotation).toRotationMatrix();
    Eigen::VectorXd u(bm.X.size());
    for (std::size_t a = 0; a < bm.v.size(); ++a) u.segment<3>(3 * a) = R.transpose() * x.col(bm.v[a]) - bm.X.segment<3>(3 * a);
    energy += 0.5 * u.dot(bm.K * u);
  }
  return energy + external_potential(x);
}

StepSummary CorotationalFem::step(double dt_s) {
  check_dt(dt_s);
  const auto start = std::chrono::steady_clock::now();
  // Step control (step_control.hpp, issue 29): an unhealthy step (solve failed, vertex speed
  // beyond the limit, collapse) is redone from the saved state with 2-8x the sub-steps.
  StepSummary s = control_.run(
      [&] {
        x_saved_ = x_;
        v_saved_ = v_;
        q_saved_ = q_;
        R_beam_saved_ = R_beam_;
        last_dx_saved_ = last_dx_;
        inversions_saved_ = inversions_;
      },
      [&] {
        x_ = x_saved_;
        v_ = v_saved_;
        q_ = q_saved_;
        R_beam_ = R_beam_saved_;
        last_dx_ = last_dx_saved_;
        inversions_ = inversions_saved_;
      },
      [&](int factor) { return run_substeps(substeps_ * factor, dt_s, [this](double h) { return substep(h); }); },
      SubstepControl::budget_factor(dt_s));
  embedded_.drive(x_, v_, dt_s, gravity_);  // embedded vertices follow their drivers / rigid groups
  s.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return s;
}

StepSummary CorotationalFem::substep(double dt_s) {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = process_cpu_ms();
  const double thread0 = thread_cpu_ms();
  StepSummary summary;
  auto finish = [&]() {
    summary.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return summary;
  };
  const bool dynamic = integrator_ == "implicit_euler";
  const bool any_attachment = attachments_.any();
  if (!dynamic && !any_attachment && std::none_of(fixed_.begin(), fixed_.end(), [](char f) { return f != 0; })) {
    summary.healthy = false;
    summary.termination = "not_run";
    summary.warning = "quasi_static needs fixed vertices or attachments: rigid motions make K singular";
    return finish();
  }
  if (dt_s != last_dt_) {
    // The system matrix depends on dt (implicit Euler): a lagged factor from another dt is stale.
    mass_damped_ = mass_ + dt_s * mass_alpha_;
    if (dynamic) solver_.force_refactor();
    last_dt_ = dt_s;
  }
  const AssemblyStats stats = assemble(dt_s, dynamic);
  summary.elastic_energy = stats.energy;
  const int inverted = stats.inverted;
  const auto t_assembled = std::chrono::steady_clock::now();
  timing_.assemble_ms = std::chrono::duration<double, std::milli>(t_assembled - t0).count();
  timing_.assemble_cpu_ms = process_cpu_ms() - cpu0;
  timing_.assemble_thread_cpu_ms = thread_cpu_ms() - thread0;
  const int nv = static_cast<int>(X_.cols());
  for (int i = 0; i < nv; ++i) f_ext_.segment<3>(3 * i) += mass_[i] * gravity_;
  f_ += f_ext_;

  const Eigen::VectorXd x_flat = flat(x_);
  if (dynamic) {
    rhs_.resize(f_.size());
    for (int i = 0; i < nv; ++i) rhs_.segment<3>(3 * i) = mass_[i] * v_.col(i) + dt_s * f_.segment<3>(3 * i);
    sol_ = flat(v_);  // warm start: the velocity changes little per step
  } else {
    rhs_ = f_;
    if (last_dx_.size() != rhs_.size()) last_dx_.setZero(rhs_.size());
    sol_ = last_dx_;  // warm start: equilibrium moves as in the last step
  }
  // Dirichlet: fixed DOFs become identity rows with zero right-hand side (v = 0, dx = 0).
  double* values = A_.valuePtr();
  for (int k : fixed_entries_) values[k] = 0.0;
  for (int i = 0; i < nv; ++i)
    if (fixed_[i])
      for (int d = 0; d < 3; ++d) {
        values[pattern_->diagonal()[3 * i + d]] = 1.0;
        rhs_[3 * i + d] = 0.0;
        sol_[3 * i + d] = 0.0;
      }

  // Residual scale: the right-hand side without elastic forces (the load of this step).
  double load_scale = 0.0;
  for (int i = 0; i < nv; ++i)
    if (!fixed_[i]) {
      const Eigen::Vector3d l = dynamic ? Eigen::Vector3d(mass_[i] * v_.col(i) + dt_s * f_ext_.segment<3>(3 * i))
                                        : Eigen::Vector3d(f_ext_.segment<3>(3 * i));
      load_scale += l.squaredNorm();
    }
  const auto t_solve = std::chrono::steady_clock::now();
  const double cpu_solve = process_cpu_ms();
  const double thread_solve = thread_cpu_ms();
  last_solve_ = solver_.solve(A_, rhs_, sol_, std::sqrt(load_scale));
  timing_.solve_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t_solve).count();
  timing_.solve_cpu_ms = process_cpu_ms() - cpu_solve;
  timing_.solve_thread_cpu_ms = thread_cpu_ms() - thread_solve;
  const LinearSolveSummary& ls = last_solve_;
  summary.iterations = ls.iterations;
  summary.initial_residual = ls.initial_residual;
  summary.final_residual = ls.final_residual;
  summary.termination = ls.termination;
  std::vector<std::string> warnings;
  if (!ls.ok) {
    summary.healthy = false;
    summary.warning = "linear solve failed: " + ls.message + "; state kept";
    return finish();
  }
  if (!sol_.allFinite()) {
    summary.healthy = false;
    summary.warning = "non-finite solution (NaN/Inf); state kept";
    return finish();
  }
  // Velocities the step would produce; reject the step when they are not physical.
  const Eigen::VectorXd v_new = dynamic ? Eigen::VectorXd(sol_) : Eigen::VectorXd(sol_ / dt_s);
  double max_speed = 0.0;
  for (int i = 0; i < nv; ++i) max_speed = std::max(max_speed, v_new.segment<3>(3 * i).norm());
  if (dynamic && max_speed > options_.max_speed_mm_s) {
    summary.healthy = false;
    summary.warning = "unstable: vertex speed " + std::to_string(max_speed) + " mm/s exceeds " +
                      std::to_string(options_.max_speed_mm_s) + " mm/s; state kept";
    return finish();
  }
  if (dynamic) {
    flat(v_) = v_new;
    flat(x_) = x_flat + dt_s * v_new;
  } else {
    // The warped stiffness is not the exact Hessian: under large deformation a full
    // Newton-like step can overshoot, and repeated steps then cycle instead of converging
    // (seen on the hanging liver: 130 mm back and forth). Backtrack on the total potential
    // energy, whose gradient is exactly -f (R is the polar rotation).
    const double slope = -f_.dot(sol_);    // dPi/dalpha at alpha = 0 (< 0: K is SPD)
    const double pi0 = summary.elastic_energy + external_potential(x_);
    double alpha = 1.0;
    Eigen::Matrix3Xd trial = x_;
    bool accepted = false;
    for (int k = 0; k < 12 && !accepted; ++k, alpha *= 0.5) {
      flat(trial) = x_flat + alpha * sol_;
      accepted = potential_energy(trial) <= pi0 + 1e-4 * alpha * slope;
    }
    if (!accepted) {
      if (-slope <= 1e-10 * (std::abs(pi0) + 1.0)) {
        // The predicted decrease is below the round-off of the energy: at equilibrium.
        v_.setZero();
        last_dx_.setZero(sol_.size());
        summary.termination = "at_equilibrium";
        return finish();
      }
      summary.healthy = false;
      summary.warning = "quasi_static: no energy decrease along the update (not converging); state kept";
      return finish();
    }
    alpha *= 2.0;  // undo the last halving
    if (alpha < 1.0) warnings.push_back("quasi_static step shortened to " + std::to_string(alpha) + " (line search)");
    x_ = trial;
    sol_ *= alpha;
    flat(v_) = sol_ / dt_s;
    last_dx_ = sol_;
  }
  if (ls.termination == "max_iterations") {
    warnings.push_back("linear solve stopped at " + std::to_string(ls.iterations) + " iterations, residual " +
                       std::to_string(ls.final_residual));
  }
  if (stats.max_strain > options_.strain_warning) {
    warnings.push_back("strain " + std::to_string(stats.max_strain) + " beyond the linear range (" +
                       std::to_string(options_.strain_warning) + "): stresses are approximate");
  }
  if (!note_.empty()) {
    warnings.push_back(note_);
    note_.clear();
  }
  for (std::size_t k = 0; k < warnings.size(); ++k) summary.warning += (k ? "; " : "") + warnings[k];
  // Inverted tets (counted at assembly, i.e. in the state the step started from): a
  // counted warning, unhealthy only for a collapse (step_health.hpp, docs/sim.md).
  inversions_.update(inverted, static_cast<int>(tets_.size()), dt_s, summary);
  double ke = 0.0;
  for (int i = 0; i < nv; ++i) ke += 0.5 * mass_[i] * v_.col(i).squaredNorm();
  summary.kinetic_energy = ke;
  return finish();
}

AttachmentId CorotationalFem::add_attachment(const AttachmentSpec& spec) {
  bool needs_new_pattern = false;
  const AttachmentId id = attachments_.add(spec, static_cast<int>(X_.cols()), *pattern_, needs_new_pattern);
  if (needs_new_pattern) build_pattern();
  solver_.force_refactor();
  return id;
}

void CorotationalFem::set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  attachments_.set_target(id, target_World_mm);
}

void CorotationalFem::set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  attachments_.set_stiffness(id, stiffness_mN_per_mm);
  solver_.force_refactor();
}

void CorotationalFem::remove_attachment(AttachmentId id) {
  attachments_.remove(id);
  solver_.force_refactor();  // the pattern keeps its entries (zeros): no new analysis
}

void CorotationalFem::set_fixed_vertices(const std::vector<int>& vertices) {
  const int nv = static_cast<int>(X_.cols());
  check_vertex_indices(vertices, nv, "corotational_fem: set_fixed_vertices");
  user_fixed_.assign(nv, 0);
  for (int v : vertices) user_fixed_[v] = 1;
  merge_fixed_with_embedding();
  for (int i = 0; i < nv; ++i)
    if (fixed_[i]) v_.col(i).setZero();
  update_fixed_entries();
  solver_.force_refactor();
}

void CorotationalFem::set_state(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  check_state_shape(x, v, static_cast<int>(X_.cols()));
  x_ = x;
  v_ = v;
  embedded_.restart(x_, v_);  // rigid groups start from the given state
  last_dx_.setZero(x_.size());
  inversions_.reset_episode();
  // The warm-start rotations belong to the old state: restart them in closed form.
  for (std::size_t t = 0; t < tets_.size(); ++t) q_[t] = rotation_by_svd(edge_matrix(x_, tets_[t].v) * tets_[t].Dm_inv);
}

std::vector<ElementMeasure> CorotationalFem::element_measures() const {
  std::vector<ElementMeasure> out(tets_.size());
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const Tet& e = tets_[t];
    const Eigen::Matrix3d F = edge_matrix(x_, e.v) * e.Dm_inv;
    const Eigen::Matrix3d R = element_rotation(F, F.determinant(), q_[t]).toRotationMatrix();
    const Eigen::Matrix3d S = R.transpose() * F;
    const Eigen::Matrix3d eps = 0.5 * (S + S.transpose()) - Eigen::Matrix3d::Identity();
    const Eigen::Matrix3d sigma = e.lambda * eps.trace() * Eigen::Matrix3d::Identity() + 2.0 * e.mu * eps;
    out[tet_order_[t]] = element_measure_from(F, sigma);  // in mesh order
  }
  return out;
}

std::unique_ptr<TissueModel> make_corotational_fem(const SimProblem& problem, const ModelConfig& config) {
  if (config.material_model == "stable_neo_hookean") return std::make_unique<StableNeoHookeanFem>(problem, config);
  if (!config.material_model.empty() && config.material_model != "corotational_linear")
    throw std::invalid_argument("corotational_fem: unknown material_model '" + config.material_model +
                                "' (use corotational_linear or stable_neo_hookean)");
  return std::make_unique<CorotationalFem>(problem, config);
}

}  // namespace arnav::host
