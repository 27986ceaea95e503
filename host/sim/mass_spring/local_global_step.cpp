// Local/global ("fast mass-spring", Liu et al. 2013; projective dynamics, Bouaziz et al.
// 2014) integrator of the mass-spring model: backward Euler solved by a few iterations
// with a constant, prefactored matrix. Frame World; units mm, kg, s, mN.
//
// Backward Euler for the positions x at the end of a substep h, with v = (x - x_n)/h and
// the inertial prediction y = x_n + h v_n:
//   r(x) = M (x - y)/h^2 - f(x, v(x)) = 0,
// f = springs + Voigt dashpots + volume term + attachments + gravity - alpha M v, all
// evaluated exactly (the dashpot along the current spring direction, as in paper 000).
// Each iteration solves A dx = -r(x) with the constant scalar matrix (same for x, y, z)
//   A = M/h^2 + alpha M/h + sum_springs (k + eta/h) l l^T + sum_tets w kv B^T B
//       + sum_attachments k w w^T,
// l the +1/-1 incidence vector of a spring, B the rest gradient operator of a tet.
// For springs A is the projective-dynamics Laplacian: k I bounds the spring Hessian
// k (n n^T + (1 - L/l)(I - n n^T)) from above, so a step minimises a quadratic upper
// bound of the incremental potential and cannot gain energy; the dashpot term eta/h I
// bounds the implicit dashpot (eta/h) n n^T the same way (its direction lagged to the
// iterate); w = kLocalGlobalVolumeWeight bounds the volume term near rest
// ((tr grad u)^2 <= 3 |grad u|^2). A converged iteration is the exact backward-Euler step;
// a truncated one (the real-time setting) is a damped approximation to it whose fixed
// point over frames is still the exact static equilibrium f(x) = 0. The Laplacian is
// stiffer than the network across the springs, so bending/shear modes converge slowly;
// from the third iteration on the iterates are Chebyshev-accelerated.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <future>

#include "host/sim/mass_spring/mass_spring_model.hpp"

namespace arnav::host {

namespace {
// Weight of the volume term in the constant matrix (see above): 3 bounds it at rest;
// smaller converges faster where the springs already carry the volume mode.
constexpr double kLocalGlobalVolumeWeight = 1.5;
// Chebyshev semi-iterative acceleration (Wang 2015) of iterations kChebyshevStart, ...
// (0-based): spectral radius estimate rho and under-relaxation gamma, tuned on the liver
// (45 frames of gravity sag, distance from the equilibrium: 4 iterations 0.18 -> 0.04 mm
// RMS, 1.8 -> 0.38 mm max; rho 0.99 diverged, starting at the second iteration diverged
// with 2 and 3 iterations). One and two iterations per step are not accelerated.
constexpr int kChebyshevStart = 2;
constexpr double kChebyshevRho = 0.9;
constexpr double kChebyshevGamma = 0.9;
}  // namespace

namespace {

// The constant matrix without attachments (lower triangle, free vertices only):
// M/h^2 + alpha M/h + sum_springs (k + eta/h) l l^T + sum_tets w kv B^T B.
PrefactoredSystem::Matrix assemble_base(const std::vector<int>& free_index, int nf, double h, const Eigen::VectorXd& mass,
                                        const Eigen::VectorXd& mass_damping, const SpringNetwork& springs,
                                        const std::vector<std::array<int, 4>>& tets, const std::vector<Eigen::Matrix3d>& Dm_inv,
                                        const std::vector<double>& volume_stiffness) {
  const int n = static_cast<int>(free_index.size());
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(static_cast<std::size_t>(nf) + 3 * springs.ends.size() + 10 * tets.size());
  auto add = [&](int a, int b, double w) {
    const int fa = free_index[static_cast<std::size_t>(a)], fb = free_index[static_cast<std::size_t>(b)];
    if (fa < 0 || fb < 0) return;
    trip.emplace_back(std::max(fa, fb), std::min(fa, fb), w);
  };
  for (int i = 0; i < n; ++i) add(i, i, mass[i] / (h * h) + mass_damping[i] / h);
  for (int s = 0; s < springs.size(); ++s) {
    const int i = springs.ends[s][0], j = springs.ends[s][1];
    const double w = springs.stiffness_mN_per_mm[s] + springs.damping_mN_s_per_mm[s] / h;
    add(i, i, w);
    add(j, j, w);
    add(i, j, -w);  // also keeps every spring pair in the pattern
  }
  for (std::size_t t = 0; t < tets.size(); ++t) {
    const double kv = kLocalGlobalVolumeWeight * volume_stiffness[t];
    if (kv <= 0.0) continue;
    std::array<Eigen::Vector3d, 4> b;
    for (int a = 1; a < 4; ++a) b[a] = Dm_inv[t].row(a - 1).transpose();
    b[0] = -(b[1] + b[2] + b[3]);
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c <= a; ++c) add(tets[t][a], tets[t][c], kv * b[a].dot(b[c]));
  }
  PrefactoredSystem::Matrix base(nf, nf);
  base.setFromTriplets(trip.begin(), trip.end());
  return base;
}

// The attachments' part of the matrix (lower triangle).
std::vector<Eigen::Triplet<double>> attachment_triplets(const AttachmentSet& attachments, const std::vector<int>& free_index) {
  std::vector<Eigen::Triplet<double>> trip;
  for (int id : attachments.active()) {
    const Attachment& at = attachments[id];
    for (int a = 0; a < at.count; ++a)
      for (int c = 0; c <= a; ++c) {
        const int fa = free_index[static_cast<std::size_t>(at.vertices[a])];
        const int fc = free_index[static_cast<std::size_t>(at.vertices[c])];
        if (fa < 0 || fc < 0) continue;
        // An off-diagonal pair on one vertex stands for both (a, c) and (c, a).
        const double twice = (c < a && fa == fc) ? 2.0 : 1.0;
        trip.emplace_back(std::max(fa, fc), std::min(fa, fc), twice * at.stiffness_mN_per_mm * at.weights[a] * at.weights[c]);
      }
  }
  return trip;
}

// Factors base + attachments into `system`.
bool factor_with_attachments(PrefactoredSystem& system, const PrefactoredSystem::Matrix& base, const std::vector<Eigen::Triplet<double>>& trip) {
  if (trip.empty()) return system.factorize(base);
  PrefactoredSystem::Matrix attached(base.rows(), base.cols());
  attached.setFromTriplets(trip.begin(), trip.end());
  const PrefactoredSystem::Matrix A = base + attached;
  return system.factorize(A);
}

}  // namespace

// A factorisation made on the worker thread after a cut.
struct MassSpringModel::PendingFactor {
  PrefactoredSystem system;
  PrefactoredSystem::Matrix base;
  std::vector<int> free_index;
  double h = 0.0;
  int version = 0;
  bool ok = false;
};

bool MassSpringModel::build_local_global_system(double h, std::string& error) {
  // The part from masses, springs and volume terms changes only with h, the fixed set and
  // cuts; attachments are added to it here (a grasp costs a sparse sum and a numeric
  // factorisation, not a new assembly).
  if (!base_valid_ || h != base_h_) {
    const int n = static_cast<int>(x_.cols());
    free_index_.assign(static_cast<std::size_t>(n), -1);
    int nf = 0;
    for (int i = 0; i < n; ++i)
      if (!fixed_[static_cast<std::size_t>(i)]) free_index_[static_cast<std::size_t>(i)] = nf++;
    free_count_ = nf;
    base_ = assemble_base(free_index_, nf, h, mass_, mass_damping_, springs_, tets_, Dm_inv_, volume_stiffness_);
    base_h_ = h;
    base_valid_ = true;
    lg_rhs_.resize(nf, 3);
    lg_dx_.resize(nf, 3);
  }
  const bool ok = factor_with_attachments(system_, base_, attachment_triplets(attachments_, free_index_));
  // Whatever a worker thread is factoring is older than this.
  ++mesh_version_;
  factor_stale_ = false;
  refactor_again_ = false;
  stale_ready_ = false;
  if (!ok) {
    error = system_.message();
    return false;
  }
  system_h_ = h;
  system_dirty_ = false;
  return true;
}

void MassSpringModel::launch_background_factor() {
  refactor_again_ = false;
  // Copies: the worker owns its inputs (the model keeps stepping and may be cut again).
  pending_factor_ = std::async(std::launch::async, [free_index = free_index_, nf = free_count_, h = system_h_, version = mesh_version_,
                                                    mass = mass_, mass_damping = mass_damping_, springs = springs_, tets = tets_,
                                                    Dm_inv = Dm_inv_, volume_stiffness = volume_stiffness_,
                                                    trip = attachment_triplets(attachments_, free_index_)]() {
    auto out = std::make_unique<PendingFactor>();
    out->base = assemble_base(free_index, nf, h, mass, mass_damping, springs, tets, Dm_inv, volume_stiffness);
    out->ok = factor_with_attachments(out->system, out->base, trip);
    out->free_index = free_index;
    out->h = h;
    out->version = version;
    return out;
  });
}

void MassSpringModel::poll_background_factor(double h, bool wait) {
  if (!pending_factor_.valid() || (hold_factor_ && !wait)) return;
  if (!wait && pending_factor_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
  std::unique_ptr<PendingFactor> done = pending_factor_.get();
  if (!factor_stale_ || system_dirty_) return;  // an inline factorisation replaced the stale one meanwhile
  if (!done->ok) {  // not positive definite: the inline build of this step reports it
    system_dirty_ = true;
    return;
  }
  ++background_factorizations_;
  if (done->version == mesh_version_ && done->h == h) {  // the current system: adopt it
    system_ = std::move(done->system);
    base_ = std::move(done->base);
    base_h_ = h;
    base_valid_ = true;
    system_h_ = h;
    factor_stale_ = false;
    stale_ready_ = false;
    return;
  }
  // Cut again meanwhile: a closer preconditioner until the next one is ready.
  system_ = std::move(done->system);
  pc_free_index_ = std::move(done->free_index);
  stale_ready_ = false;
  if (refactor_again_) launch_background_factor();
}

void MassSpringModel::wait_for_factor() {
  while (pending_factor_.valid()) poll_background_factor(system_h_, true);
}

void MassSpringModel::prepare_stale_preconditioner(double h) {
  if (stale_ready_) return;
  const int n = static_cast<int>(x_.cols());
  pc_row_.assign(static_cast<std::size_t>(free_count_), -1);
  pc_own_.assign(static_cast<std::size_t>(free_count_), 0);
  auto factor_row = [&](int i) { return i < static_cast<int>(pc_free_index_.size()) ? pc_free_index_[static_cast<std::size_t>(i)] : -1; };
  for (int i = 0; i < n; ++i) {
    const int fi = free_index_[static_cast<std::size_t>(i)];
    if (fi < 0) continue;
    if (factor_row(i) >= 0) {
      pc_row_[static_cast<std::size_t>(fi)] = factor_row(i);
      pc_own_[static_cast<std::size_t>(fi)] = 1;
    } else if (i < static_cast<int>(pc_alias_.size()) && pc_alias_[static_cast<std::size_t>(i)] >= 0) {
      pc_row_[static_cast<std::size_t>(fi)] = factor_row(pc_alias_[static_cast<std::size_t>(i)]);
    }
  }
  // Diagonal of the current matrix (rows the old factor does not know).
  pc_diag_.setZero(free_count_);
  auto diag = [&](int i, double w) {
    const int fi = free_index_[static_cast<std::size_t>(i)];
    if (fi >= 0) pc_diag_[fi] += w;
  };
  for (int i = 0; i < n; ++i) diag(i, mass_[i] / (h * h) + mass_damping_[i] / h);
  for (int s = 0; s < springs_.size(); ++s) {
    const double w = springs_.stiffness_mN_per_mm[static_cast<std::size_t>(s)] + springs_.damping_mN_s_per_mm[static_cast<std::size_t>(s)] / h;
    diag(springs_.ends[static_cast<std::size_t>(s)][0], w);
    diag(springs_.ends[static_cast<std::size_t>(s)][1], w);
  }
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const double kv = kLocalGlobalVolumeWeight * volume_stiffness_[t];
    if (kv <= 0.0) continue;
    std::array<Eigen::Vector3d, 4> b;
    for (int a = 1; a < 4; ++a) b[a] = Dm_inv_[t].row(a - 1).transpose();
    b[0] = -(b[1] + b[2] + b[3]);
    for (int a = 0; a < 4; ++a) diag(tets_[t][a], kv * b[a].squaredNorm());
  }
  for (int id : attachments_.active()) {
    const Attachment& at = attachments_[id];
    for (int a = 0; a < at.count; ++a)
      for (int c = 0; c < at.count; ++c)
        if (at.vertices[a] == at.vertices[c]) diag(at.vertices[a], at.stiffness_mN_per_mm * at.weights[a] * at.weights[c]);
  }
  int old_rows = 0;
  for (int r : pc_free_index_) old_rows = std::max(old_rows, r + 1);
  pc_rhs_.resize(old_rows, 3);
  stale_ready_ = true;
}

void MassSpringModel::stale_precondition(const Eigen::MatrixX3d& r, Eigen::MatrixX3d& z) {
  // z = R^T A_old^-1 R r + D^-1 r on the rows the old factor does not own: R sums each
  // row into the factor row it owns or is aliased to (additive aggregation; SPD).
  z.resize(r.rows(), 3);
  pc_rhs_.setZero();
  for (int fi = 0; fi < free_count_; ++fi) {
    const int old = pc_row_[static_cast<std::size_t>(fi)];
    if (old >= 0) pc_rhs_.row(old) += r.row(fi);
    z.row(fi) = pc_own_[static_cast<std::size_t>(fi)] ? Eigen::RowVector3d::Zero() : Eigen::RowVector3d(r.row(fi) / pc_diag_[fi]);
  }
  if (pc_rhs_.rows() > 0) system_.solve(pc_rhs_, pc_sol_, threads_);
  for (int fi = 0; fi < free_count_; ++fi) {
    const int old = pc_row_[static_cast<std::size_t>(fi)];
    if (old >= 0) z.row(fi) += pc_sol_.row(old);
  }
}

void MassSpringModel::apply_local_global_matrix(const Eigen::MatrixX3d& p_rows, Eigen::MatrixX3d& out_rows, double h) const {
  // The matrix of build_local_global_system, applied without forming it (fixed rows absent);
  // on 3 x rows copies (one column per row: contiguous per vertex).
  const int n = static_cast<int>(x_.cols());
  const Eigen::Matrix3Xd p = p_rows.transpose();
  Eigen::Matrix3Xd out = Eigen::Matrix3Xd::Zero(3, p.cols());
  const int* row = free_index_.data();
  for (int i = 0; i < n; ++i) {
    const int fi = row[i];
    if (fi >= 0) out.col(fi) = (mass_[i] / (h * h) + mass_damping_[i] / h) * p.col(fi);
  }
  for (int s = 0; s < springs_.size(); ++s) {
    const double w = springs_.stiffness_mN_per_mm[static_cast<std::size_t>(s)] + springs_.damping_mN_s_per_mm[static_cast<std::size_t>(s)] / h;
    if (w == 0.0) continue;
    const int fa = row[springs_.ends[static_cast<std::size_t>(s)][0]], fb = row[springs_.ends[static_cast<std::size_t>(s)][1]];
    Eigen::Vector3d d = Eigen::Vector3d::Zero();
    if (fa >= 0) d += p.col(fa);
    if (fb >= 0) d -= p.col(fb);
    d *= w;
    if (fa >= 0) out.col(fa) += d;
    if (fb >= 0) out.col(fb) -= d;
  }
  for (std::size_t t = 0; t < tets_.size(); ++t) {
    const double kv = kLocalGlobalVolumeWeight * volume_stiffness_[t];
    if (kv <= 0.0) continue;
    const Eigen::Matrix3d& Di = Dm_inv_[t];  // rows: b_1, b_2, b_3; b_0 = -(b_1 + b_2 + b_3)
    int f[4];
    Eigen::Matrix3d S = Eigen::Matrix3d::Zero();  // sum_c p_c b_c^T
    Eigen::Vector3d p0 = Eigen::Vector3d::Zero();
    for (int c = 0; c < 4; ++c) f[c] = row[tets_[t][static_cast<std::size_t>(c)]];
    if (f[0] >= 0) p0 = p.col(f[0]);
    for (int c = 1; c < 4; ++c) {
      const Eigen::Vector3d pc = f[c] >= 0 ? Eigen::Vector3d(p.col(f[c]) - p0) : Eigen::Vector3d(-p0);
      S += pc * Di.row(c - 1);
    }
    // out_a += kv sum_c (b_a . b_c) p_c = kv S b_a
    const Eigen::Matrix3d G = kv * S * Di.transpose();  // columns: kv S b_1, kv S b_2, kv S b_3
    if (f[0] >= 0) out.col(f[0]) -= G.rowwise().sum();
    for (int a = 1; a < 4; ++a)
      if (f[a] >= 0) out.col(f[a]) += G.col(a - 1);
  }
  for (int id : attachments_.active()) {
    const Attachment& at = attachments_[id];
    for (int a = 0; a < at.count; ++a) {
      const int fa = row[at.vertices[a]];
      if (fa < 0) continue;
      for (int c = 0; c < at.count; ++c) {
        const int fc = row[at.vertices[c]];
        if (fc >= 0) out.col(fa) += at.stiffness_mN_per_mm * at.weights[a] * at.weights[c] * p.col(fc);
      }
    }
  }
  out_rows = out.transpose();
}

int MassSpringModel::solve_with_stale_factor(const Eigen::MatrixX3d& b, Eigen::MatrixX3d& x, double h) {
  // Truncated PCG on the current matrix A, one recurrence per coordinate, preconditioned by
  // the old factor (stale_precondition). Every CG iterate lowers the quadratic model
  // q(dx) = dx^T A dx / 2 - b^T dx below 0, and A bounds the Hessian of the incremental
  // potential from above, so the plain local/global step still cannot gain energy when PCG stops
  // early; the frame's cost is what bounds the iterations (each one a back-substitution and
  // a product with A, against one back-substitution for a step with a current factor). The
  // old and new matrices differ only near the cut.
  const double kRelativeTolerance = stale_pcg_tolerance_;
  const int kMaxIterations = stale_pcg_limit_;
  prepare_stale_preconditioner(h);
  ++stale_solves_;
  x.setZero(b.rows(), 3);
  pcg_r_ = b;
  const Eigen::Array3d b_norm = b.colwise().norm().transpose().array();
  stale_precondition(pcg_r_, pcg_z_);
  pcg_p_ = pcg_z_;
  Eigen::Array3d rz = (pcg_r_.array() * pcg_z_.array()).colwise().sum().transpose();
  int it = 0;
  for (; it < kMaxIterations; ++it) {
    const Eigen::Array3d r_norm = pcg_r_.colwise().norm().transpose().array();
    if ((r_norm <= kRelativeTolerance * b_norm).all()) break;
    apply_local_global_matrix(pcg_p_, pcg_q_, h);
    const Eigen::Array3d pq = (pcg_p_.array() * pcg_q_.array()).colwise().sum().transpose();
    Eigen::Array3d alpha = Eigen::Array3d::Zero();
    for (int c = 0; c < 3; ++c)
      if (pq[c] > 0.0 && r_norm[c] > kRelativeTolerance * b_norm[c]) alpha[c] = rz[c] / pq[c];
    x += pcg_p_ * alpha.matrix().asDiagonal();
    pcg_r_ -= pcg_q_ * alpha.matrix().asDiagonal();
    stale_precondition(pcg_r_, pcg_z_);
    const Eigen::Array3d rz_new = (pcg_r_.array() * pcg_z_.array()).colwise().sum().transpose();
    Eigen::Array3d beta = Eigen::Array3d::Zero();
    for (int c = 0; c < 3; ++c)
      if (rz[c] > 0.0) beta[c] = rz_new[c] / rz[c];
    pcg_p_ = pcg_z_ + pcg_p_ * beta.matrix().asDiagonal();
    rz = rz_new;
  }
  stale_pcg_iterations_ += it;
  return it;
}

StepSummary MassSpringModel::local_global_substep(double h) {
  StepSummary s;
  poll_background_factor(h, false);
  if (system_dirty_ || h != system_h_) {
    std::string error;
    if (!build_local_global_system(h, error)) {
      s.healthy = false;
      s.termination = "factorization_failed";
      s.warning = "local_global: " + error;
      return s;
    }
    ++refactorizations_;
  }
  const int n = static_cast<int>(x_.cols());
  xn_ = x_;
  vn_ = v_;
  // Inertial prediction y = x_n + h v_n is the first iterate (fixed vertices have v = 0).
  x_ += h * v_;
  const double inv_h = 1.0 / h, inv_h2 = inv_h * inv_h;
  double denom = 0.0;
  double omega = 1.0;  // Chebyshev weight
  if (x_prev_.cols() != n) x_prev_ = x_;
  for (int k = 0; k < config_.iterations; ++k) {
    // Local step: forces at the iterate (springs along their current directions, dashpots
    // on the current relative velocities, volume term, attachments, gravity, damping).
    v_ = (x_ - xn_) * inv_h;
    assemble(0.0);
    double rr = 0.0;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) reduction(+ : rr) schedule(static)
    for (int i = 0; i < n; ++i) {
      const int fi = free_index_[static_cast<std::size_t>(i)];
      if (fi < 0) continue;
      // -r = f - M (x - y)/h^2, with y = x_n + h v_n
      const Eigen::Vector3d res = f_.col(i) - mass_[i] * inv_h2 * (x_.col(i) - xn_.col(i) - h * vn_.col(i));
      lg_rhs_.row(fi) = res.transpose();
      rr += res.squaredNorm();
    }
    const double r_norm = std::sqrt(rr);
    if (k == 0) {
      // Scale: the residual of the prediction, at least the weight of the body (near
      // equilibrium the residual vanishes and a relative criterion would ask for ever more).
      double weight = 0.0;
      for (int i = 0; i < n; ++i) weight += (mass_[i] * gravity_).squaredNorm();
      denom = std::max({r_norm, std::sqrt(weight), 1e-300});
      s.initial_residual = r_norm / denom;
    }
    s.final_residual = r_norm / denom;
    if (config_.tolerance > 0.0 && s.final_residual <= config_.tolerance) {
      if (s.termination.empty()) s.termination = "converged";
      break;
    }
    // Global step: one back-substitution pair for the three coordinates.
    if (factor_stale_) {
      solve_with_stale_factor(lg_rhs_, lg_dx_, h);  // after a cut, until the new factor is ready
    } else {
      system_.solve(lg_rhs_, lg_dx_, threads_);
    }
    // Chebyshev semi-iterative acceleration from the third iteration on (see above):
    // x^{k+1} = w (gamma (xhat - x^k) + x^k - x^{k-1}) + x^{k-1}, xhat the plain update.
    if (k == kChebyshevStart) {
      omega = 2.0 / (2.0 - kChebyshevRho * kChebyshevRho);
    } else if (k > kChebyshevStart) {
      omega = 4.0 / (4.0 - kChebyshevRho * kChebyshevRho * omega);
    }
    const bool accelerate = k >= kChebyshevStart;
#pragma omp parallel for num_threads(threads_) if (threads_ > 1) schedule(static)
    for (int i = 0; i < n; ++i) {
      const int fi = free_index_[static_cast<std::size_t>(i)];
      if (fi < 0) continue;
      const Eigen::Vector3d xk = x_.col(i);
      const Eigen::Vector3d xhat = xk + lg_dx_.row(fi).transpose();
      x_.col(i) = accelerate ? Eigen::Vector3d(omega * (kChebyshevGamma * (xhat - xk) + xk - x_prev_.col(i)) +
                                               x_prev_.col(i))
                             : xhat;
      x_prev_.col(i) = xk;
    }
    ++s.iterations;
  }
  if (s.termination.empty()) s.termination = "max_iterations";
  v_ = (x_ - xn_) * inv_h;
  return s;
}

}  // namespace arnav::host
