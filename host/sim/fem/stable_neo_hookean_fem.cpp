#include "host/sim/fem/stable_neo_hookean_fem.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "host/sim/element_measure.hpp"
#include "host/sim/fem/fem_mesh_change.hpp"
#include "host/sim/model_setup.hpp"
#include "host/sim/tet_geometry.hpp"

namespace arnav::host {

namespace stable_neo_hookean {
namespace {
Eigen::Matrix3d cofactor(const Eigen::Matrix3d& F) {
  Eigen::Matrix3d C;
  C.col(0) = F.col(1).cross(F.col(2));
  C.col(1) = F.col(2).cross(F.col(0));
  C.col(2) = F.col(0).cross(F.col(1));
  return C;
}
Eigen::Matrix3d skew(const Eigen::Vector3d& a) {
  Eigen::Matrix3d S;
  S << 0, -a.z(), a.y(), a.z(), 0, -a.x(), -a.y(), a.x(), 0;
  return S;
}
}  // namespace

double energy_density(const Eigen::Matrix3d& F, double mu, double lambda) {
  const double lp = lambda + mu;
  const double J = F.determinant();
  return 0.5 * mu * (F.squaredNorm() - 3.0) - mu * (J - 1.0) + 0.5 * lp * (J - 1.0) * (J - 1.0);
}

Eigen::Matrix3d first_piola(const Eigen::Matrix3d& F, double mu, double lambda) {
  const double lp = lambda + mu;
  const double J = F.determinant();
  return mu * F + (lp * (J - 1.0) - mu) * cofactor(F);
}

Matrix9d hessian(const Eigen::Matrix3d& F, double mu, double lambda, bool project, bool* projected) {
  const double lp = lambda + mu;
  const double J = F.determinant();
  const Eigen::Matrix3d C = cofactor(F);
  const Eigen::Map<const Eigen::Matrix<double, 9, 1>> g(C.data());
  Matrix9d H = mu * Matrix9d::Identity() + lp * g * g.transpose();
  // d2J/dF2: block (i, j) = d(cof column i)/d(column j) of F.
  const double s = lp * (J - 1.0) - mu;
  const Eigen::Matrix3d S0 = s * skew(F.col(0)), S1 = s * skew(F.col(1)), S2 = s * skew(F.col(2));
  H.block<3, 3>(0, 3) -= S2;
  H.block<3, 3>(0, 6) += S1;
  H.block<3, 3>(3, 0) += S2;
  H.block<3, 3>(3, 6) -= S0;
  H.block<3, 3>(6, 0) -= S1;
  H.block<3, 3>(6, 3) += S0;
  if (projected) *projected = false;
  if (!project) return H;
  // Most elements are (numerically) semi-definite already: the infinitesimal rotations have
  // zero stiffness, hence the small shift in the test.
  const Eigen::LLT<Matrix9d> llt(H + (1e-9 * mu) * Matrix9d::Identity());
  if (llt.info() == Eigen::Success) return H;
  if (projected) *projected = true;
  // Analytic eigensystem (Smith, de Goes & Kim 2019) in the rotation-variant SVD
  // F = U diag(s) V^T (U, V rotations, s2 may be negative): with r = lambda' (J - 1) - mu,
  //   twist  U (e_i e_j^T - e_j e_i^T) V^T / sqrt2:  mu + r s_k
  //   flip   U (e_i e_j^T + e_j e_i^T) V^T / sqrt2:  mu - r s_k      ({i, j, k} = {0, 1, 2})
  //   scaling U diag(w) V^T, w an eigenvector of mu I + lambda' c c^T + r [s_k off the diagonal],
  //   c_i = prod_{j != i} s_j.
  // The negative modes are removed from H: H + sum_{l < 0} (-l) q q^T.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU(), V = svd.matrixV();
  Eigen::Vector3d sv = svd.singularValues();
  if (U.determinant() < 0) {
    U.col(2) *= -1.0;
    sv[2] *= -1.0;
  }
  if (V.determinant() < 0) {
    V.col(2) *= -1.0;
    sv[2] *= -1.0;
  }
  auto add_mode = [&](const Eigen::Matrix3d& D, double eigenvalue) {
    if (eigenvalue >= 0.0) return;
    const Eigen::Matrix3d Q = U * D * V.transpose();
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> q(Q.data());
    H.noalias() -= eigenvalue * q * q.transpose();
  };
  const double inv_sqrt2 = 1.0 / std::sqrt(2.0);
  for (int k = 0; k < 3; ++k) {
    const int i = (k + 1) % 3, j = (k + 2) % 3;
    Eigen::Matrix3d T = Eigen::Matrix3d::Zero();
    T(i, j) = inv_sqrt2;
    T(j, i) = -inv_sqrt2;
    add_mode(T, mu + s * sv[k]);
    T(j, i) = inv_sqrt2;
    add_mode(T, mu - s * sv[k]);
  }
  const Eigen::Vector3d c(sv[1] * sv[2], sv[0] * sv[2], sv[0] * sv[1]);
  Eigen::Matrix3d A = mu * Eigen::Matrix3d::Identity() + lp * c * c.transpose();
  A(0, 1) += s * sv[2];
  A(1, 0) += s * sv[2];
  A(0, 2) += s * sv[1];
  A(2, 0) += s * sv[1];
  A(1, 2) += s * sv[0];
  A(2, 1) += s * sv[0];
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  for (int m = 0; m < 3; ++m) add_mode(Eigen::Matrix3d(eig.eigenvectors().col(m).asDiagonal()), eig.eigenvalues()[m]);
  return H;
}

Matrix9d project_numerically(const Matrix9d& H) {
  const Eigen::SelfAdjointEigenSolver<Matrix9d> eig(H);
  const Eigen::Matrix<double, 9, 1> d = eig.eigenvalues().cwiseMax(0.0);
  return eig.eigenvectors() * d.asDiagonal() * eig.eigenvectors().transpose();
}
}  // namespace stable_neo_hookean

namespace {
constexpr const char* kWho = "corotational_fem (material_model stable_neo_hookean)";
Eigen::Map<Eigen::VectorXd> flat(Eigen::Matrix3Xd& m) { return {m.data(), m.size()}; }
Eigen::Map<const Eigen::VectorXd> flat(const Eigen::Matrix3Xd& m) { return {m.data(), m.size()}; }

inline void scatter(double* values, const int* map, const Eigen::Matrix3d& B) {
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      if (map[3 * r + c] >= 0) values[map[3 * r + c]] += B(r, c);
}
}  // namespace

StableNeoHookeanFem::StableNeoHookeanFem(const SimProblem& problem, const ModelConfig& config, const FemOptions& options)
    : integrator_(config.integrator.empty() ? "implicit_euler" : config.integrator),
      options_(options),
      threads_(config.threads),
      substeps_(config.substeps),
      newton_iterations_(config.iterations),
      tolerance_(config.tolerance),
      gravity_(problem.gravity_World_mm_s2),
      solver_(FemLinearSolver::parse(config.linear_solver.empty() ? "cholmod" : config.linear_solver),
              config.refactor_every, 100, 1e-4) {
  const std::string who = "corotational_fem (material_model stable_neo_hookean)";
  if (integrator_ != "implicit_euler" && integrator_ != "quasi_static")
    throw std::invalid_argument(who + ": unknown integrator '" + integrator_ + "' (use implicit_euler or quasi_static)");
  if (threads_ < 1 || substeps_ < 1 || newton_iterations_ < 1)
    throw std::invalid_argument(who + ": threads, substeps and iterations (Newton) must be >= 1");
  if (!(tolerance_ >= 0.0)) throw std::invalid_argument(who + ": tolerance must be >= 0");
  if (config.single_precision_preconditioner || config.refactor_in_background)
    throw std::invalid_argument(who + ": single_precision_preconditioner and refactor_in_background are options of the "
                                      "co-rotational material only (remove them)");
  const TetMesh& mesh = problem.mesh;
  if (mesh.num_tets() == 0) throw std::invalid_argument(who + ": the mesh has no tetrahedra");
  if (!gravity_.allFinite()) throw std::invalid_argument(who + ": gravity is not finite");
  X_ = mesh.rest_positions_World_mm;
  x_ = X_;
  v_ = Eigen::Matrix3Xd::Zero(3, X_.cols());
  mass_ = checked_masses_kg(problem, "corotational_fem");
  const int nv = mesh.num_vertices();
  mass_alpha_ = Eigen::VectorXd::Zero(nv);
  tets_.resize(mesh.tets.size());
  quarter_mass_.resize(tets_.size());
  quarter_alpha_.resize(tets_.size());
  for (int t = 0; t < mesh.num_tets(); ++t) {
    tets_[t] = make_element(problem, t, quarter_mass_[t], quarter_alpha_[t]);
    for (int v : tets_[t].v) mass_alpha_[v] += quarter_alpha_[t];
  }
  if (problem.vessels && !problem.vessels->segments.empty())
    note_ = "vessel tree ignored: the stable_neo_hookean material has no beam coupling (use material_model corotational_linear)";
  check_vertex_indices(problem.fixed_vertices, nv, "corotational_fem: fixed vertices");
  {
    std::vector<int> touched;
    embedded_.reset(problem.embedded, X_, x_, v_);
    embedded_.move_mass({&mass_, &mass_alpha_}, touched, &problem.region_materials);
  }
  user_fixed_.assign(nv, 0);
  for (int v : problem.fixed_vertices) user_fixed_[v] = 1;
  merge_fixed_with_embedding();
  solver_.set_refresh_residual(options_.refresh_residual);
  build_pattern();
}

StableNeoHookeanFem::~StableNeoHookeanFem() = default;

StableNeoHookeanFem::Tet StableNeoHookeanFem::make_element(const SimProblem& problem, int t, double& quarter_mass,
                                                           double& quarter_alpha) const {
  const fem::RestTet r = fem::rest_tet(problem, t, kWho);
  Tet e;
  e.v = r.v;
  e.Dm_inv = r.Dm_inv;
  e.volume = r.volume;
  e.passive = r.passive;  // below the quality bound: Psi = 0
  e.mu = r.passive ? 0.0 : r.mu;
  e.lambda = r.passive ? 0.0 : r.lambda;
  e.beta = r.passive ? 0.0 : r.beta;
  e.dFdx.setZero();
  for (int a = 0; a < 4; ++a)
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) e.dFdx(i + 3 * j, 3 * a + i) = r.g[static_cast<std::size_t>(a)][j];
  quarter_mass = r.quarter_mass;
  quarter_alpha = r.quarter_alpha;
  return e;
}

std::optional<MeshChangeStats> StableNeoHookeanFem::apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed,
                                                                      const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  const TetMesh& mesh = problem.mesh;
  const int n_old = static_cast<int>(X_.cols()), n = mesh.num_vertices();
  const int nt_old = static_cast<int>(tets_.size()), nt = mesh.num_tets();
  if (!fem::mesh_change_fits(problem, changed, n_old, nt_old, x, v)) return std::nullopt;
  // New elements and masses, checked before anything changes.
  std::vector<Tet> fresh(changed.size());
  std::vector<fem::TetChange> changes(changed.size());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    fem::TetChange& c = changes[i];
    const auto t = static_cast<std::size_t>(changed[i]);
    fresh[i] = make_element(problem, changed[i], c.mass_after, c.alpha_after);
    c.after = fresh[i].v;
    if (changed[i] < nt_old) {
      c.existed = true;
      c.before = tets_[t].v;
      c.mass_before = quarter_mass_[t];
      c.alpha_before = quarter_alpha_[t];
    }
  }
  const std::vector<int> touched = fem::touched_vertices(changes, n_old, n);
  if (pair_tets_.empty())  // once, O(tets): the pairs the tets couple before the cut
    for (const Tet& t : tets_) pair_tets_.add(t.v);

  // Vertex records: rest position, masses, state, fixed flags and the embedding.
  MeshChangeStats stats;
  stats.vertices_updated =
      fem::update_vertex_records(problem, changes, touched, x, v, embedded_, {X_, x_, v_, mass_, mass_alpha_, fixed_, user_fixed_}, kWho);

  // Element records (stored in mesh order): changed tets in their slots, appended ones at the end.
  tets_.resize(static_cast<std::size_t>(nt));
  quarter_mass_.resize(tets_.size());
  quarter_alpha_.resize(tets_.size());
  std::vector<std::vector<int>> groups;
  groups.reserve(changed.size());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    const auto t = static_cast<std::size_t>(changed[i]);
    tets_[t] = fresh[i];
    quarter_mass_[t] = changes[i].mass_after;
    quarter_alpha_[t] = changes[i].alpha_after;
    groups.emplace_back(fresh[i].v.begin(), fresh[i].v.end());
    ++stats.elements_updated;
  }
  // Passive flags of unchanged tets can change too (islands of good tets cut off by
  // slivers): an O(tets) byte pass, the few that flip made again.
  for (int t = 0; t < nt; ++t)
    if (tets_[static_cast<std::size_t>(t)].passive != problem.embedded.is_passive(t)) {
      double qm = 0, qa = 0;
      tets_[static_cast<std::size_t>(t)] = make_element(problem, t, qm, qa);
      ++stats.elements_updated;
    }

  // Pattern: the changed tets' pairs in, the pairs no tet or attachment couples any more
  // out, in one merge pass; the unchanged tets' maps remapped, the changed ones' made again.
  std::vector<std::vector<int>> kept;
  attachments_.append_groups(kept);
  const std::vector<std::pair<int, int>> drop = pair_tets_.update(changes, kept);
  if (fem::grow_pattern(pattern_, n, groups, drop, {&tet_map_})) {
    attachments_.map_into(*pattern_);
    A_ = pattern_->matrix();
    K_ = A_;
    D_ = A_;
  }
  tet_map_.resize(90 * tets_.size());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    const std::vector<int> m = pattern_->block_map(groups[i]);
    std::copy(m.begin(), m.end(), tet_map_.begin() + 90 * static_cast<std::ptrdiff_t>(changed[i]));
  }
  fem::update_partition(partition_, changed, nt_old, nt);
  solver_.pattern_changed();  // analysed and factorised at the next solve
  inversions_.reset_episode();  // as for a model rebuilt on the cut mesh (set_state)
  return stats;
}

void StableNeoHookeanFem::build_pattern() {
  std::vector<std::vector<int>> elements;
  for (const Tet& t : tets_) elements.emplace_back(t.v.begin(), t.v.end());
  std::vector<std::vector<int>> groups = elements;
  attachments_.append_groups(groups);
  pattern_ = std::make_unique<SymmetricPattern>(static_cast<int>(X_.cols()), groups);
  tet_map_.resize(90 * tets_.size());
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const std::vector<int> m = pattern_->block_map(elements[t]);
    std::copy(m.begin(), m.end(), tet_map_.begin() + 90 * static_cast<std::ptrdiff_t>(t));
  }
  attachments_.map_into(*pattern_);
  partition_ = partition_elements(X_, elements, threads_);
  A_ = pattern_->matrix();
  K_ = A_;
  D_ = A_;
  solver_.pattern_changed();
}

double StableNeoHookeanFem::assemble_elastic(const Eigen::Matrix3Xd& x, bool damping_matrix) {
  double* k_values = K_.valuePtr();
  double* d_values = D_.valuePtr();
  std::fill(k_values, k_values + K_.nonZeros(), 0.0);
  if (damping_matrix) std::fill(d_values, d_values + D_.nonZeros(), 0.0);
  f_el_.setZero(x.size());
  double energy = 0.0;
  int projected = 0;
  auto element = [&](int id, double& e_sum, int& n_proj) {
    const Tet& e = tets_[id];
    const Eigen::Matrix3d F = edge_matrix(x, e.v) * e.Dm_inv;
    e_sum += e.volume * stable_neo_hookean::energy_density(F, e.mu, e.lambda);
    const Eigen::Matrix3d P = stable_neo_hookean::first_piola(F, e.mu, e.lambda);
    const Eigen::Map<const Eigen::Matrix<double, 9, 1>> vecP(P.data());
    const Eigen::Matrix<double, 12, 1> grad = e.volume * e.dFdx.transpose() * vecP;
    for (int a = 0; a < 4; ++a) f_el_.segment<3>(3 * e.v[a]) -= grad.segment<3>(3 * a);
    bool proj = false;
    const stable_neo_hookean::Matrix9d H = stable_neo_hookean::hessian(F, e.mu, e.lambda, true, &proj);
    if (proj) ++n_proj;
    const Eigen::Matrix<double, 12, 12> K = e.volume * e.dFdx.transpose() * H * e.dFdx;
    const int* map = tet_map_.data() + 90 * static_cast<std::ptrdiff_t>(id);
    for (int a = 0, pair = 0; a < 4; ++a)
      for (int b = a; b < 4; ++b, ++pair) {
        const Eigen::Matrix3d B = K.block<3, 3>(3 * a, 3 * b);
        scatter(k_values, map + 9 * pair, B);
        if (damping_matrix && e.beta != 0.0) scatter(d_values, map + 9 * pair, e.beta * B);
      }
  };
  const int parts = static_cast<int>(partition_.parts.size());
#pragma omp parallel for schedule(static, 1) reduction(+ : energy, projected) num_threads(threads_) if (threads_ > 1)
  for (int part = 0; part < parts; ++part)
    for (int id : partition_.parts[part]) element(id, energy, projected);
  for (int id : partition_.shared) element(id, energy, projected);
  last_projected_ = projected;
  return energy;
}

double StableNeoHookeanFem::elastic_energy_of(const Eigen::Matrix3Xd& x) const {
  const int n = static_cast<int>(tets_.size());
  double energy = 0.0;
#pragma omp parallel for schedule(static) reduction(+ : energy) num_threads(threads_) if (threads_ > 1)
  for (int t = 0; t < n; ++t) {
    const Tet& e = tets_[t];
    energy += e.volume * stable_neo_hookean::energy_density(edge_matrix(x, e.v) * e.Dm_inv, e.mu, e.lambda);
  }
  return energy;
}

double StableNeoHookeanFem::elastic_energy() const { return elastic_energy_of(x_); }

double StableNeoHookeanFem::attachment_energy(const Eigen::Matrix3Xd& x) const {
  return attachments_.energy(x);
}

StepSummary StableNeoHookeanFem::step(double dt_s) {
  check_dt(dt_s);
  const auto start = std::chrono::steady_clock::now();
  // Step control (step_control.hpp, issue 29): an unhealthy step (Newton without decrease,
  // solve failed, vertex speed beyond the limit, collapse) is redone from the saved state
  // with 2-8x the sub-steps, each with the configured Newton iterations.
  StepSummary s = control_.run(
      [&] {
        x_saved_ = x_;
        v_saved_ = v_;
        inversions_saved_ = inversions_;
      },
      [&] {
        x_ = x_saved_;
        v_ = v_saved_;
        inversions_ = inversions_saved_;
      },
      [&](int factor) { return run_substeps(substeps_ * factor, dt_s, [this](double h) { return substep(h); }); },
      SubstepControl::budget_factor(dt_s));
  embedded_.drive(x_, v_, dt_s, gravity_);  // embedded vertices follow their drivers / rigid groups
  s.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return s;
}

void StableNeoHookeanFem::merge_fixed_with_embedding() {
  fixed_.assign(user_fixed_.size(), 0);
  for (std::size_t i = 0; i < fixed_.size(); ++i) fixed_[i] = user_fixed_[i] || embedded_.held(static_cast<int>(i)) ? 1 : 0;
}

StepSummary StableNeoHookeanFem::substep(double h) {
  const auto t0 = std::chrono::steady_clock::now();
  StepSummary summary;
  auto finish = [&]() {
    summary.wall_time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return summary;
  };
  const bool dynamic = integrator_ == "implicit_euler";
  const int nv = static_cast<int>(X_.cols());
  const bool any_attachment = attachments_.any();
  if (!dynamic && !any_attachment && std::none_of(fixed_.begin(), fixed_.end(), [](char f) { return f != 0; })) {
    summary.healthy = false;
    summary.termination = "not_run";
    summary.warning = "quasi_static needs fixed vertices or attachments: rigid motions make K singular";
    return finish();
  }
  if (h != last_dt_) {
    if (dynamic) solver_.force_refactor();
    last_dt_ = h;
  }
  bool any_beta = false;
  for (const Tet& e : tets_) any_beta = any_beta || e.beta != 0.0;

  const Eigen::Matrix3Xd x_n = x_;
  Eigen::Matrix3Xd x_hat = x_n + h * v_;
  for (int i = 0; i < nv; ++i)
    if (fixed_[i]) x_hat.col(i) = x_n.col(i);
  Eigen::Matrix3Xd x = x_n;
  const double hh = dynamic ? h * h : 1.0;  // weight of the potential in the objective

  auto external = [&](const Eigen::Matrix3Xd& y, Eigen::VectorXd* f_ext) {
    double u = 0.0;
    for (int i = 0; i < nv; ++i) u -= mass_[i] * gravity_.dot(y.col(i));
    u += attachment_energy(y);
    if (f_ext) {
      f_ext->setZero(y.size());
      for (int i = 0; i < nv; ++i) f_ext->segment<3>(3 * i) = mass_[i] * gravity_;
      for (const auto& att : attachments_) {
        if (!att) continue;
        const MaterialPoint& p = att->spec.point;
        Eigen::Vector3d pos = Eigen::Vector3d::Zero();
        for (std::size_t a = 0; a < p.vertices.size(); ++a) pos += p.weights[a] * y.col(p.vertices[a]);
        const Eigen::Vector3d pull = att->spec.stiffness_mN_per_mm * (att->spec.target_World_mm - pos);
        for (std::size_t a = 0; a < p.vertices.size(); ++a) f_ext->segment<3>(3 * p.vertices[a]) += p.weights[a] * pull;
      }
    }
    return u;
  };
  // Objective (implicit Euler: the incremental potential scaled by h^2; quasi-static: the
  // total potential) at y with elastic energy psi.
  auto objective = [&](const Eigen::Matrix3Xd& y, double psi) {
    double e = hh * (psi + external(y, nullptr));
    if (dynamic) {
      for (int i = 0; i < nv; ++i) {
        e += 0.5 * mass_[i] * (y.col(i) - x_hat.col(i)).squaredNorm();
        e += 0.5 * h * mass_alpha_[i] * (y.col(i) - x_n.col(i)).squaredNorm();
      }
      if (any_beta) {
        const Eigen::VectorXd u = flat(y) - flat(x_n);
        const Eigen::VectorXd Du = D_.selfadjointView<Eigen::Lower>() * u;
        e += 0.5 * h * u.dot(Du);
      }
    }
    return e;
  };

  Eigen::VectorXd f_ext, grad;
  double load_scale = 0.0, gnorm0 = 0.0, gnorm = 0.0;
  int it = 0;
  std::string termination = "max_iterations";
  timing_ = {};
  auto ms_since = [](std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
  };
  for (; it < newton_iterations_; ++it) {
    const auto t_assemble = std::chrono::steady_clock::now();
    const double psi = assemble_elastic(x, dynamic && it == 0 && any_beta);
    external(x, &f_ext);
    grad = -hh * (f_el_ + f_ext);
    if (dynamic) {
      for (int i = 0; i < nv; ++i)
        grad.segment<3>(3 * i) += mass_[i] * (x.col(i) - x_hat.col(i)) + h * mass_alpha_[i] * (x.col(i) - x_n.col(i));
      if (any_beta) {
        const Eigen::VectorXd u = flat(x) - flat(x_n);
        const Eigen::VectorXd Du = D_.selfadjointView<Eigen::Lower>() * u;
        grad += h * Du;
      }
    }
    for (int i = 0; i < nv; ++i)
      if (fixed_[i]) grad.segment<3>(3 * i).setZero();
    gnorm = grad.norm();
    if (it == 0) {
      // The load of this step: momentum and external forces (what the residual is relative to).
      for (int i = 0; i < nv; ++i)
        if (!fixed_[i]) {
          const Eigen::Vector3d l = hh * f_ext.segment<3>(3 * i) + (dynamic ? Eigen::Vector3d(h * mass_[i] * v_.col(i)) : Eigen::Vector3d::Zero());
          load_scale += l.squaredNorm();
        }
      load_scale = std::sqrt(load_scale);
      gnorm0 = gnorm;
      if (it == 0 && !std::isfinite(gnorm)) {
        summary.healthy = false;
        summary.warning = "non-finite forces (NaN/Inf); state kept";
        return finish();
      }
    }
    if (gnorm <= tolerance_ * std::max(load_scale, 1e-300)) {
      termination = "converged";
      break;
    }
    // System: M (1 + alpha h) + h D + h^2 (K + K_att)  (quasi-static: K + K_att).
    const double* kv = K_.valuePtr();
    const double* dv = D_.valuePtr();
    double* av = A_.valuePtr();
    const Eigen::Index nnz = A_.nonZeros();
    for (Eigen::Index k = 0; k < nnz; ++k) av[k] = hh * kv[k] + (dynamic && any_beta ? h * dv[k] : 0.0);
    for (const auto& att : attachments_) {
      if (!att) continue;
      const MaterialPoint& p = att->spec.point;
      const int nb = static_cast<int>(p.vertices.size());
      for (int a = 0, pair = 0; a < nb; ++a)
        for (int b = a; b < nb; ++b, ++pair)
          scatter(av, att->map.data() + 9 * pair,
                  (hh * att->spec.stiffness_mN_per_mm * p.weights[a] * p.weights[b]) * Eigen::Matrix3d::Identity());
    }
    if (dynamic)
      for (int i = 0; i < nv; ++i)
        for (int d = 0; d < 3; ++d) av[pattern_->diagonal()[3 * i + d]] += mass_[i] + h * mass_alpha_[i];
    // Dirichlet: identity rows and columns for the fixed DOFs.
    for (int c = 0; c < A_.outerSize(); ++c)
      for (int k = A_.outerIndexPtr()[c]; k < A_.outerIndexPtr()[c + 1]; ++k) {
        const int r = A_.innerIndexPtr()[k];
        if (fixed_[r / 3] || fixed_[c / 3]) av[k] = r == c ? 1.0 : 0.0;
      }
    const Eigen::VectorXd rhs = -grad;
    sol_.setZero(rhs.size());
    const auto t_solve = std::chrono::steady_clock::now();
    timing_.assemble_ms += std::chrono::duration<double, std::milli>(t_solve - t_assemble).count();
    const LinearSolveSummary ls = solver_.solve(A_, rhs, sol_, gnorm0);
    timing_.solve_ms += ms_since(t_solve);
    timing_.linear_iterations += ls.iterations;
    timing_.factorizations += ls.factorized ? 1 : 0;
    const auto t_line = std::chrono::steady_clock::now();
    if (!ls.ok || !sol_.allFinite()) {
      summary.healthy = false;
      summary.warning = "Newton: linear solve failed (" + (ls.ok ? std::string("non-finite solution") : ls.message) + "); state kept";
      return finish();
    }
    // Backtracking (Armijo) line search on the objective: the direction is a descent
    // direction because the projected system is positive definite.
    const double slope = grad.dot(sol_);
    const double e0 = objective(x, psi);
    Eigen::Matrix3Xd trial = x;
    double alpha = 1.0;
    bool accepted = false;
    for (int k = 0; k < 30 && !accepted; ++k) {
      flat(trial) = flat(x) + alpha * sol_;
      const double e1 = objective(trial, elastic_energy_of(trial));
      accepted = std::isfinite(e1) && e1 <= e0 + 1e-4 * alpha * slope;
      if (!accepted) alpha *= 0.5;
    }
    timing_.line_search_ms += ms_since(t_line);
    if (!accepted) {
      if (-slope <= 1e-12 * (std::abs(e0) + 1.0)) {
        termination = "at_equilibrium";  // the predicted decrease is below the round-off of E
        break;
      }
      summary.healthy = false;
      summary.warning = "Newton: no decrease of the incremental potential along the update (not converging); state kept";
      return finish();
    }
    x = trial;
  }
  last_newton_ = it;
  summary.iterations = it;
  summary.termination = termination;
  summary.initial_residual = gnorm0 / std::max(load_scale, 1e-300);
  summary.final_residual = gnorm / std::max(load_scale, 1e-300);
  Eigen::Matrix3Xd v_new = (x - x_n) / h;
  double max_speed = 0.0;
  for (int i = 0; i < nv; ++i) max_speed = std::max(max_speed, v_new.col(i).norm());
  if (!x.allFinite() || (dynamic && max_speed > options_.max_speed_mm_s)) {
    summary.healthy = false;
    summary.warning = "unstable: vertex speed " + std::to_string(max_speed) + " mm/s exceeds " +
                      std::to_string(options_.max_speed_mm_s) + " mm/s; state kept";
    return finish();
  }
  x_ = x;
  v_ = v_new;
  if (termination == "max_iterations" && newton_iterations_ > 1)
    report(summary, "Newton stopped at " + std::to_string(it) + " iterations, relative gradient " + std::to_string(summary.final_residual), false);
  if (!note_.empty()) {
    report(summary, note_, false);
    note_.clear();
  }
  int inverted = 0;
  for (const Tet& e : tets_)
    if (!e.passive && (edge_matrix(x_, e.v) * e.Dm_inv).determinant() <= 0.0) ++inverted;
  inversions_.update(inverted, static_cast<int>(tets_.size()), h, summary);
  summary.elastic_energy = elastic_energy_of(x_);
  summary.kinetic_energy = kinetic_energy(mass_, v_);
  return finish();
}

AttachmentId StableNeoHookeanFem::add_attachment(const AttachmentSpec& spec) {
  bool needs_new_pattern = false;
  const AttachmentId id = attachments_.add(spec, static_cast<int>(X_.cols()), *pattern_, needs_new_pattern);
  if (needs_new_pattern) build_pattern();
  solver_.force_refactor();
  return id;
}

void StableNeoHookeanFem::set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) {
  attachments_.set_target(id, target_World_mm);
}

void StableNeoHookeanFem::set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) {
  attachments_.set_stiffness(id, stiffness_mN_per_mm);
  solver_.force_refactor();
}

void StableNeoHookeanFem::remove_attachment(AttachmentId id) {
  attachments_.remove(id);
  solver_.force_refactor();
}

void StableNeoHookeanFem::set_fixed_vertices(const std::vector<int>& vertices) {
  const int nv = static_cast<int>(X_.cols());
  check_vertex_indices(vertices, nv, "corotational_fem: set_fixed_vertices");
  user_fixed_.assign(nv, 0);
  for (int v : vertices) user_fixed_[v] = 1;
  merge_fixed_with_embedding();
  for (int i = 0; i < nv; ++i)
    if (fixed_[i]) v_.col(i).setZero();
  solver_.force_refactor();
}

void StableNeoHookeanFem::set_state(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v) {
  check_state_shape(x, v, static_cast<int>(X_.cols()));
  x_ = x;
  v_ = v;
  embedded_.restart(x_, v_);  // rigid groups start from the given state
  inversions_.reset_episode();
}

std::vector<ElementMeasure> StableNeoHookeanFem::element_measures() const {
  std::vector<ElementMeasure> out(tets_.size());
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const Tet& e = tets_[t];
    const Eigen::Matrix3d F = edge_matrix(x_, e.v) * e.Dm_inv;
    // Cauchy stress P F^T / J; for nearly flat and inverted tets J is floored at 0.05 (the
    // display shows a bounded stress there, the volume ratio tells the state).
    const double J = F.determinant();
    const Eigen::Matrix3d sigma = stable_neo_hookean::first_piola(F, e.mu, e.lambda) * F.transpose() / std::max(J, 0.05);
    out[t] = element_measure_from(F, sigma);
  }
  return out;
}

}  // namespace arnav::host
