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
#include <cmath>

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

bool MassSpringModel::build_local_global_system(double h, std::string& error) {
  const int n = static_cast<int>(x_.cols());
  // The part from masses, springs and volume terms changes only with h and the fixed set;
  // attachments are added to it here (a grasp costs a sparse sum and a numeric
  // factorisation, not a new assembly).
  if (!base_valid_ || h != base_h_) {
    free_index_.assign(static_cast<std::size_t>(n), -1);
    int nf = 0;
    for (int i = 0; i < n; ++i)
      if (!fixed_[static_cast<std::size_t>(i)]) free_index_[static_cast<std::size_t>(i)] = nf++;
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(static_cast<std::size_t>(nf + 3 * springs_.size() + 10 * static_cast<int>(tets_.size())));
    auto add = [&](int a, int b, double w) {  // lower triangle, free vertices only
      const int fa = free_index_[static_cast<std::size_t>(a)], fb = free_index_[static_cast<std::size_t>(b)];
      if (fa < 0 || fb < 0) return;
      trip.emplace_back(std::max(fa, fb), std::min(fa, fb), w);
    };
    for (int i = 0; i < n; ++i) add(i, i, mass_[i] / (h * h) + mass_damping_[i] / h);
    for (int s = 0; s < springs_.size(); ++s) {
      const int i = springs_.ends[s][0], j = springs_.ends[s][1];
      const double w = springs_.stiffness_mN_per_mm[s] + springs_.damping_mN_s_per_mm[s] / h;
      add(i, i, w);
      add(j, j, w);
      add(i, j, -w);  // also keeps every spring pair in the pattern
    }
    for (std::size_t t = 0; t < tets_.size(); ++t) {
      const double kv = kLocalGlobalVolumeWeight * volume_stiffness_[t];
      if (kv <= 0.0) continue;
      std::array<Eigen::Vector3d, 4> b;
      for (int a = 1; a < 4; ++a) b[a] = Dm_inv_[t].row(a - 1).transpose();
      b[0] = -(b[1] + b[2] + b[3]);
      for (int a = 0; a < 4; ++a)
        for (int c = 0; c <= a; ++c) add(tets_[t][a], tets_[t][c], kv * b[a].dot(b[c]));
    }
    base_.resize(nf, nf);
    base_.setFromTriplets(trip.begin(), trip.end());
    base_h_ = h;
    base_valid_ = true;
    lg_rhs_.resize(nf, 3);
    lg_dx_.resize(nf, 3);
  }
  std::vector<Eigen::Triplet<double>> trip;
  for (int id : attachments_.active()) {
    const Attachment& at = attachments_[id];
    for (int a = 0; a < at.count; ++a)
      for (int c = 0; c <= a; ++c) {
        const int fa = free_index_[static_cast<std::size_t>(at.vertices[a])];
        const int fc = free_index_[static_cast<std::size_t>(at.vertices[c])];
        if (fa < 0 || fc < 0) continue;
        // An off-diagonal pair on one vertex stands for both (a, c) and (c, a).
        const double twice = (c < a && fa == fc) ? 2.0 : 1.0;
        trip.emplace_back(std::max(fa, fc), std::min(fa, fc),
                          twice * at.stiffness_mN_per_mm * at.weights[a] * at.weights[c]);
      }
  }
  bool ok = false;
  if (trip.empty()) {
    ok = system_.factorize(base_);
  } else {
    PrefactoredSystem::Matrix attached(base_.rows(), base_.cols());
    attached.setFromTriplets(trip.begin(), trip.end());
    const PrefactoredSystem::Matrix A = base_ + attached;
    ok = system_.factorize(A);
  }
  if (!ok) {
    error = system_.message();
    return false;
  }
  system_h_ = h;
  system_dirty_ = false;
  return true;
}

StepSummary MassSpringModel::local_global_substep(double h) {
  StepSummary s;
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
    system_.solve(lg_rhs_, lg_dx_, threads_);
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
