#include "host/sim/fem/fem_linear_solver.hpp"

#include <Eigen/CholmodSupport>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <vector>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace arnav::host {

struct FemLinearSolver::Factors {
  Eigen::CholmodSupernodalLLT<SparseMatrixLower, Eigen::Lower> cholmod;
  Eigen::SimplicialLDLT<SparseMatrixLower, Eigen::Lower> ldlt;
  Eigen::VectorXd inv_diag;
};

FemLinearSolver::Kind FemLinearSolver::parse(const std::string& name) {
  if (name == "cholmod") return Kind::Cholmod;
  if (name == "eigen_ldlt") return Kind::EigenLdlt;
  if (name == "pcg") return Kind::PcgFactor;
  if (name == "pcg_jacobi") return Kind::PcgJacobi;
  throw std::invalid_argument("corotational_fem: unknown linear_solver '" + name +
                              "' (use cholmod, eigen_ldlt, pcg or pcg_jacobi)");
}

FemLinearSolver::FemLinearSolver(Kind kind, int refactor_every, int max_iterations, double tolerance)
    : kind_(kind), refactor_every_(refactor_every), max_iterations_(max_iterations), tolerance_(tolerance),
      f_(std::make_unique<Factors>()) {
  // A failed factorisation is reported in the summary; CHOLMOD need not print it too.
  f_->cholmod.cholmod().print = 0;
  if (refactor_every < 0) throw std::invalid_argument("corotational_fem: refactor_every must be >= 0");
  if (max_iterations < 1) throw std::invalid_argument("corotational_fem: iterations must be >= 1");
  if (!(tolerance > 0.0)) throw std::invalid_argument("corotational_fem: tolerance must be > 0");
}

FemLinearSolver::~FemLinearSolver() = default;

void FemLinearSolver::pattern_changed() {
  analyzed_ = false;
  have_factor_ = false;
}

void FemLinearSolver::force_refactor() { have_factor_ = false; }

bool FemLinearSolver::factorize(const SparseMatrixLower& A, LinearSolveSummary& s) {
  const auto t0 = std::chrono::steady_clock::now();
  bool ok = true;
  if (kind_ == Kind::EigenLdlt) {
    if (!analyzed_) f_->ldlt.analyzePattern(A);
    f_->ldlt.factorize(A);
    ok = f_->ldlt.info() == Eigen::Success && (f_->ldlt.vectorD().array() > 0.0).all();
  } else if (kind_ == Kind::PcgJacobi) {
    f_->inv_diag = A.diagonal().cwiseInverse();
    ok = (A.diagonal().array() > 0.0).all();
  } else {
    if (!analyzed_) f_->cholmod.analyzePattern(A);
    f_->cholmod.factorize(A);
    ok = f_->cholmod.info() == Eigen::Success;
  }
  analyzed_ = true;
  s.factorized = true;
  s.factor_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  have_factor_ = ok;
  steps_since_factor_ = 0;
  if (!ok) {
    s.ok = false;
    s.termination = "factorization_failed";
    s.message = "system matrix is not positive definite (unconstrained rigid modes, or inverted/degenerate elements)";
  }
  return ok;
}

void FemLinearSolver::apply_factor(const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  switch (kind_) {
    case Kind::EigenLdlt: z = f_->ldlt.solve(r); break;
    case Kind::PcgJacobi: z = f_->inv_diag.cwiseProduct(r); break;
    default: z = f_->cholmod.solve(r); break;
  }
}

LinearSolveSummary FemLinearSolver::solve(const SparseMatrixLower& A, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                                          double load_scale) {
  LinearSolveSummary s;
  const bool due = !have_factor_ || kind_ == Kind::PcgJacobi ||
                   (refactor_every_ > 0 && steps_since_factor_ + 1 >= refactor_every_);
  if (due && !factorize(A, s)) return s;
  if (!s.factorized) ++steps_since_factor_;
  const auto Asym = A.selfadjointView<Eigen::Lower>();
  const double b_norm = std::max(b.norm(), load_scale);
  if (b_norm == 0.0) {
    x.setZero();
    s.termination = "converged";
    return s;
  }
  if (kind_ == Kind::Cholmod || kind_ == Kind::EigenLdlt) {
    s.initial_residual = b.norm() / b_norm;
    apply_factor(b, x);
    s.iterations = 1;
    s.final_residual = (b - Asym * x).norm() / b_norm;
    s.termination = s.factorized ? "direct" : "direct_lagged";
    if (!s.factorized && s.final_residual > refresh_residual_) {
      // The lagged factor no longer solves this system: refactorise now.
      if (!factorize(A, s)) return s;
      apply_factor(b, x);
      s.final_residual = (b - Asym * x).norm() / b_norm;
      s.termination = "direct_refreshed";
    }
    return s;
  }
  // Preconditioned conjugate gradients, warm started from x.
  Eigen::VectorXd r = b - Asym * x;
  s.initial_residual = r.norm() / b_norm;
  Eigen::VectorXd z, p, q;
  double rz = 0;
  double res = s.initial_residual;
  int it = 0;
  int cap = max_iterations_;
  std::vector<double> alphas, betas;  // CG coefficients: the Lanczos tridiagonal, for kappa
  for (;;) {
    if (res <= tolerance_) break;
    if (it >= cap) {
      // Cap reached far from the solution with a lagged factor: refresh it and give CG
      // another `iterations` (restarted: the preconditioner changed).
      if (kind_ != Kind::PcgFactor || s.factorized || res <= refresh_residual_) break;
      if (!factorize(A, s)) return s;
      s.message = "preconditioner refreshed after " + std::to_string(it) + " iterations at residual " + std::to_string(res);
      cap = it + max_iterations_;
      rz = 0;
      alphas.clear();
      betas.clear();
      p.resize(0);
      continue;
    }
    apply_factor(r, z);
    const double rz_new = r.dot(z);
    if (p.size() == 0) {
      p = z;
    } else {
      p = z + (rz_new / rz) * p;
      betas.push_back(rz_new / rz);
    }
    rz = rz_new;
    q = Asym * p;
    const double pq = p.dot(q);
    if (!(pq > 0.0)) {  // not positive definite along p: stop with what we have
      s.message = "CG found a direction of non-positive curvature";
      break;
    }
    const double alpha = rz / pq;
    alphas.push_back(alpha);
    x += alpha * p;
    r -= alpha * q;
    res = r.norm() / b_norm;
    ++it;
  }
  s.iterations = it;
  s.final_residual = res;
  const int m = static_cast<int>(alphas.size());
  if (estimate_condition_ && m >= 2) {
    // T_jj = 1/a_j + b_(j-1)/a_(j-1), T_j,j+1 = sqrt(b_j)/a_j (CG <-> Lanczos); its extreme
    // eigenvalues converge to those of the preconditioned matrix from inside.
    Eigen::VectorXd diag(m), sub(m - 1);
    for (int j = 0; j < m; ++j) diag[j] = 1.0 / alphas[j] + (j > 0 ? betas[j - 1] / alphas[j - 1] : 0.0);
    for (int j = 0; j + 1 < m; ++j) sub[j] = std::sqrt(betas[j]) / alphas[j];
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig;
    eig.computeFromTridiagonal(diag, sub, Eigen::EigenvaluesOnly);
    if (eig.info() == Eigen::Success && eig.eigenvalues()[0] > 0.0) {
      s.condition_estimate = eig.eigenvalues()[m - 1] / eig.eigenvalues()[0];
    }
  }
  s.termination = res <= tolerance_ ? "converged" : "max_iterations";
  return s;
}

}  // namespace arnav::host
