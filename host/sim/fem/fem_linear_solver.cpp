#include "host/sim/fem/fem_linear_solver.hpp"

#include <cholmod.h>

#include <Eigen/CholmodSupport>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <omp.h>

#include "host/sim/fem/single_precision_factor.hpp"
#include <algorithm>
#include <utility>
#include <vector>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <sys/resource.h>
#include <unistd.h>

namespace arnav::host {

namespace {
// Eigen's CHOLMOD wrapper, with access to the factor (for its single-precision copy).
class Cholmod : public Eigen::CholmodSupernodalLLT<SparseMatrixLower, Eigen::Lower> {
 public:
  const cholmod_factor& factor() const { return *m_cholmodFactor; }
  // Becomes a copy of `other` (symbolic analysis and numeric factor): a later factorize()
  // of a matrix with the same pattern is numeric only, without a second ordering/analysis.
  void copy_from(Cholmod& other) {
    if (m_cholmodFactor != nullptr) cholmod_free_factor(&m_cholmodFactor, &cholmod());
    m_cholmodFactor = cholmod_copy_factor(other.m_cholmodFactor, &cholmod());
    const bool ok = m_cholmodFactor != nullptr;
    m_isInitialized = ok;
    m_analysisIsOk = ok;
    m_factorizationIsOk = ok;
    m_info = ok ? Eigen::Success : Eigen::NumericalIssue;
  }
};

// Debian's CHOLMOD parallelises the scatter of supernode updates with OpenMP at a
// compiled-in 4 threads (CHOLMOD_OMP_NUM_THREADS): thousands of tiny parallel regions per
// factorisation, whose spin-waits cost more than they save on 2 cores (bundled liver, METIS
// ordering, OpenBLAS 1 thread: 121 ms CPU per factorisation with them, 73 ms without;
// `arnav-fem-bench factor`, docs/benchmarks.md). This guard makes OpenMP regions opened by
// the calling thread serial while it lives; the setting is per thread (OpenMP 5.0
// max-active-levels ICV, GCC >= 11), so the assembly's own threads are not affected.
class SerialOpenMpRegions {
 public:
  SerialOpenMpRegions() : saved_(omp_get_max_active_levels()) { omp_set_max_active_levels(0); }
  ~SerialOpenMpRegions() { omp_set_max_active_levels(saved_); }
  SerialOpenMpRegions(const SerialOpenMpRegions&) = delete;
  SerialOpenMpRegions& operator=(const SerialOpenMpRegions&) = delete;

 private:
  int saved_;
};

// What a background job did.
constexpr int kJobFailed = 0;        // factorisation failed: the matrix was not positive definite
constexpr int kJobFactor = 1;        // a new factor is ready

std::unique_ptr<Cholmod> make_cholmod() {
  auto c = std::make_unique<Cholmod>();
  // A failed factorisation is reported in the summary; CHOLMOD need not print it too.
  c->cholmod().print = 0;
  return c;
}
}  // namespace

struct FemLinearSolver::Factors {
  std::unique_ptr<Cholmod> cholmod = make_cholmod();  // the factor in use
  SinglePrecisionFactor single;                       // its float copy (single_precision_)
  Eigen::SimplicialLDLT<SparseMatrixLower, Eigen::Lower> ldlt;
  Eigen::VectorXd inv_diag;
  // Background refactorisation: the worker owns `pending` and `snapshot` while a job runs.
  std::unique_ptr<Cholmod> pending;
  SinglePrecisionFactor single_pending;
  SparseMatrixLower snapshot;
  // After a cut (pattern_extended): inverses of the 3x3 diagonal blocks of the DOFs the
  // factor in use does not have.
  std::vector<Eigen::Matrix3d> tail_inv;
  std::vector<int> tail_alias;  // their aggregation vertex in the factor (-1: none)
  // Cut-region correction (prepare_preconditioner): the DOFs whose entries changed since the
  // factor's pattern (and rings of neighbours), the rows of A there, the factor of A_SS.
  std::vector<int> region_dofs;
  Eigen::SparseMatrix<double, Eigen::RowMajor, int> region_rows;
  Eigen::SimplicialLLT<SparseMatrixLower, Eigen::Lower> region_solver;
  std::vector<int> region_analysed;  // the region of the solver's symbolic analysis
  Eigen::Index region_analysed_nnz = -1;
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
  if (refactor_every < 0) throw std::invalid_argument("corotational_fem: refactor_every must be >= 0");
  if (max_iterations < 1) throw std::invalid_argument("corotational_fem: iterations must be >= 1");
  if (!(tolerance > 0.0)) throw std::invalid_argument("corotational_fem: tolerance must be > 0");
}

FemLinearSolver::~FemLinearSolver() { discard_background(); }  // the job uses f_

void FemLinearSolver::set_background_refactor(bool on) {
  if (on && kind_ != Kind::PcgFactor) {
    throw std::invalid_argument(
        "corotational_fem: refactor_in_background needs linear_solver pcg (a lagged direct solve would depend on "
        "when the worker finishes; PCG converges on the current matrix with any factor)");
  }
  if (!on) discard_background();
  if (on && !f_->pending) f_->pending = make_cholmod();
  background_ = on;
}

void FemLinearSolver::set_single_precision_preconditioner(bool on) {
  if (solves_ > 0 && on != single_precision_) {
    throw std::logic_error("FemLinearSolver: set the preconditioner precision before the first solve");
  }
  single_precision_ = on;
}

void FemLinearSolver::wait_for_background() {
  if (job_.valid()) job_.wait();
}

void FemLinearSolver::discard_background() {
  if (job_.valid()) job_.wait();
  job_ = {};
}

void FemLinearSolver::pattern_changed() {
  discard_background();  // its snapshot has the old pattern
  cut_regions_.clear();
  ++pattern_version_;
  analyzed_ = false;
  have_factor_ = false;
  pending_version_ = -1;
  f_->snapshot = SparseMatrixLower();
}

void FemLinearSolver::pattern_extended(int old_vertices, const std::vector<int>& alias, const std::vector<int>& changed_vertices) {
  if (kind_ != Kind::PcgFactor || !have_factor_) {
    pattern_changed();
    return;
  }
  const int known = static_cast<int>(alias_.size());
  if (known < old_vertices) {  // identity for the vertices before (once, and after a rebuild of the pattern)
    alias_.resize(static_cast<std::size_t>(old_vertices));
    for (int v = known; v < old_vertices; ++v) alias_[static_cast<std::size_t>(v)] = v;
  }
  alias_.resize(static_cast<std::size_t>(old_vertices));
  for (int a : alias) alias_.push_back(a);
  // The factor in use stays (padded for the new DOFs: prepare_padding); a running job
  // finishes on its snapshot and is taken if it is newer (poll_background).
  ++pattern_version_;
  analyzed_ = false;
  if (!f_->pending) f_->pending = make_cholmod();
  refresh_requested_ = true;
  cut_regions_.push_back({pattern_version_, changed_vertices});
}

void FemLinearSolver::prepare_preconditioner(const SparseMatrixLower& A) {
  region_active_ = false;
  if (kind_ != Kind::PcgFactor) return;
  if (factor_dofs_ < A.rows()) prepare_padding(A);
  // Cut-region correction: the vertices whose entries changed since the factor's pattern.
  cut_regions_.erase(std::remove_if(cut_regions_.begin(), cut_regions_.end(),
                                    [&](const CutRegion& c) { return c.version <= factor_version_; }),
                     cut_regions_.end());
  if (cut_region_rings_ < 0 || cut_regions_.empty() || factor_version_ == pattern_version_) return;
  const auto n = static_cast<int>(A.rows());
  std::vector<int> pos(static_cast<std::size_t>(n), -1);
  std::vector<int>& dofs = f_->region_dofs;
  dofs.clear();
  const auto add_vertex = [&](int v) {
    if (v < 0 || 3 * v + 2 >= n || pos[static_cast<std::size_t>(3 * v)] >= 0) return;
    for (int d = 0; d < 3; ++d) {
      pos[static_cast<std::size_t>(3 * v + d)] = 0;
      dofs.push_back(3 * v + d);
    }
  };
  // Newest cuts first; when the worker's factor is late (a loaded machine) and the region
  // would grow past an eighth of the DOFs (at most 1,500), the older cuts' vertices and
  // further rings are left to the old factor alone: the region's factorisation stays a small
  // fraction of a full one (still SPD, only a weaker correction).
  const std::size_t cap = std::min<std::size_t>(1500, std::max<std::size_t>(150, static_cast<std::size_t>(n) / 8));
  for (auto it = cut_regions_.rbegin(); it != cut_regions_.rend(); ++it) {
    std::size_t fresh = 0;
    for (int v : it->vertices) fresh += (v >= 0 && 3 * v + 2 < n && pos[static_cast<std::size_t>(3 * v)] < 0) ? 3 : 0;
    if (!dofs.empty() && dofs.size() + fresh > cap) break;
    for (int v : it->vertices) add_vertex(v);
  }
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* values = A.valuePtr();
  // Rings of neighbours (vertices coupled to the region in A): one pass over the entries each.
  for (int ring = 0; ring < cut_region_rings_; ++ring) {
    std::vector<int> more;
    for (int c = 0; c < n; ++c)
      for (int k = outer[c]; k < outer[c + 1]; ++k) {
        const int r = inner[k];
        const bool rin = pos[static_cast<std::size_t>(r)] >= 0, cin = pos[static_cast<std::size_t>(c)] >= 0;
        if (rin != cin) more.push_back((rin ? c : r) / 3);
      }
    std::sort(more.begin(), more.end());
    more.erase(std::unique(more.begin(), more.end()), more.end());
    if (dofs.size() + 3 * more.size() > cap) break;
    for (int v : more) add_vertex(v);
  }
  std::sort(dofs.begin(), dofs.end());
  for (std::size_t i = 0; i < dofs.size(); ++i) pos[static_cast<std::size_t>(dofs[i])] = static_cast<int>(i);
  // Rows S of the symmetric matrix (s x n) and its S x S block, from the lower triangle.
  const auto m = static_cast<Eigen::Index>(dofs.size());
  std::vector<Eigen::Triplet<double>> rows, block;
  for (int c = 0; c < n; ++c)
    for (int k = outer[c]; k < outer[c + 1]; ++k) {
      const int r = inner[k];
      const int pr = pos[static_cast<std::size_t>(r)], pc = pos[static_cast<std::size_t>(c)];
      if (pr >= 0) rows.emplace_back(pr, c, values[k]);
      if (pc >= 0 && r != c) rows.emplace_back(pc, r, values[k]);
      if (pr >= 0 && pc >= 0) block.emplace_back(pr, pc, values[k]);  // lower triangle of the block (r >= c)
    }
  f_->region_rows.resize(m, n);
  f_->region_rows.setFromTriplets(rows.begin(), rows.end());
  SparseMatrixLower local(m, m);
  local.setFromTriplets(block.begin(), block.end());
  // The symbolic analysis is kept while the region and its pattern stay (frames between cuts).
  if (dofs != f_->region_analysed || local.nonZeros() != f_->region_analysed_nnz) {
    f_->region_solver.analyzePattern(local);
    f_->region_analysed = dofs;
    f_->region_analysed_nnz = local.nonZeros();
  }
  f_->region_solver.factorize(local);
  region_active_ = f_->region_solver.info() == Eigen::Success;
}

void FemLinearSolver::apply_preconditioner(const Eigen::VectorXd& r, Eigen::VectorXd& z) const {
  if (!region_active_) {
    apply_factor(r, z);
    return;
  }
  // M^-1 = T + (I - T A) P (I - A T), T = E A_SS^-1 E^T (exact solve of the changed region
  // on the current matrix), P the (padded) old factor: symmetric, and positive definite
  // whenever P is (r^T T r = 0 means E^T r = 0, and then (I - A T) r = r).
  const std::vector<int>& dofs = f_->region_dofs;
  const auto m = static_cast<Eigen::Index>(dofs.size());
  Eigen::VectorXd rs(m);
  for (Eigen::Index i = 0; i < m; ++i) rs[i] = r[dofs[static_cast<std::size_t>(i)]];
  const Eigen::VectorXd u = f_->region_solver.solve(rs);
  const Eigen::VectorXd y = r - f_->region_rows.transpose() * u;
  apply_factor(y, z);
  const Eigen::VectorXd t = f_->region_rows * z;
  const Eigen::VectorXd c = f_->region_solver.solve(t);
  for (Eigen::Index i = 0; i < m; ++i) z[dofs[static_cast<std::size_t>(i)]] += u[i] - c[i];
}

void FemLinearSolver::prepare_padding(const SparseMatrixLower& A) {
  const Eigen::Index nf = factor_dofs_, n = A.rows();
  f_->tail_inv.resize(static_cast<std::size_t>((n - nf) / 3));
  f_->tail_alias.assign(f_->tail_inv.size(), -1);
  for (std::size_t i = 0; i < f_->tail_alias.size(); ++i) {
    int a = static_cast<int>(nf / 3) + static_cast<int>(i);
    while (a >= nf / 3 && static_cast<std::size_t>(a) < alias_.size() && alias_[static_cast<std::size_t>(a)] >= 0 && alias_[static_cast<std::size_t>(a)] < a)
      a = alias_[static_cast<std::size_t>(a)];
    f_->tail_alias[i] = a < nf / 3 ? a : -1;
  }
  const int* outer = A.outerIndexPtr();
  const int* inner = A.innerIndexPtr();
  const double* values = A.valuePtr();
  for (Eigen::Index v = 0; v < (n - nf) / 3; ++v) {
    Eigen::Matrix3d B;
    for (int c = 0; c < 3; ++c) {
      const Eigen::Index col = nf + 3 * v + c;
      const int k0 = outer[col];
      // Lower triangle, rows sorted: the column's first entries are its diagonal block's.
      for (int r = c; r < 3; ++r) {
        const double value = (k0 + r - c < outer[col + 1] && inner[k0 + r - c] == col + r - c) ? values[k0 + r - c] : 0.0;
        B(r, c) = B(c, r) = value;
      }
    }
    const Eigen::LLT<Eigen::Matrix3d> llt(B);
    if (llt.info() == Eigen::Success) {
      f_->tail_inv[static_cast<std::size_t>(v)] = llt.solve(Eigen::Matrix3d::Identity());
    } else {  // not positive definite (PCG will say so): the diagonal, kept positive
      f_->tail_inv[static_cast<std::size_t>(v)] = B.diagonal().cwiseAbs().cwiseMax(1e-300).cwiseInverse().asDiagonal();
    }
  }
}

void FemLinearSolver::force_refactor() {
  // Background mode keeps the old factor as preconditioner until the new one is ready.
  if (background_ && have_factor_) {
    refresh_requested_ = true;
  } else {
    have_factor_ = false;
  }
}

void FemLinearSolver::poll_background(LinearSolveSummary& s) {
  if (!job_.valid() || job_.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
  const int done = job_.get();
  if (done == kJobFailed) {
    s.message = "background factorisation failed (matrix not positive definite); the previous factor is kept";
    return;
  }
  // An inline refresh after the snapshot was taken is newer: keep it.
  if (have_factor_ && pending_stamp_ > factor_stamp_) {
    std::swap(f_->cholmod, f_->pending);
    std::swap(f_->single, f_->single_pending);
    std::swap(factor_version_, pending_version_);
    std::swap(factor_dofs_, pending_dofs_);
    analyzed_ = factor_version_ == pattern_version_;
    factor_stamp_ = pending_stamp_;
    steps_since_factor_ = 0;
    s.background_swapped = true;
  }
}

void FemLinearSolver::start_background(const SparseMatrixLower& A, LinearSolveSummary& s) {
  if (f_->snapshot.rows() == A.rows() && f_->snapshot.nonZeros() == A.nonZeros()) {
    std::copy(A.valuePtr(), A.valuePtr() + A.nonZeros(), f_->snapshot.valuePtr());  // same pattern: values only
  } else {
    f_->snapshot = A;
  }
  pending_stamp_ = started_stamp_ = solves_;
  refresh_requested_ = false;
  s.background_started = true;
  const bool analyze = pending_version_ != pattern_version_;  // a new pattern (or never analysed)
  pending_version_ = pattern_version_;
  pending_dofs_ = A.rows();
  Cholmod* L = f_->pending.get();
  SinglePrecisionFactor* single = single_precision_ ? &f_->single_pending : nullptr;
  const SparseMatrixLower* M = &f_->snapshot;
  const int nice_level = background_nice_;
  job_ = std::async(std::launch::async, [L, single, M, analyze, nice_level] {
    // The worker yields the core to the stepping thread whenever they compete (a loaded
    // machine): Linux applies setpriority to the calling thread only (a fresh thread per job).
    if (nice_level > 0) setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), nice_level);
    const SerialOpenMpRegions serial;
    if (analyze) L->analyzePattern(*M);
    L->factorize(*M);
    if (L->info() != Eigen::Success) return kJobFailed;
    if (single) single->assign(L->factor());
    return kJobFactor;
  });
}

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
    const SerialOpenMpRegions serial;
    if (!analyzed_) f_->cholmod->analyzePattern(A);
    f_->cholmod->factorize(A);
    ok = f_->cholmod->info() == Eigen::Success;
    if (ok && single_precision_ && kind_ == Kind::PcgFactor) f_->single.assign(f_->cholmod->factor());
  }
  analyzed_ = true;
  factor_version_ = pattern_version_;
  factor_dofs_ = A.rows();
  factor_stamp_ = started_stamp_ = solves_;
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
    default:
      if (factor_dofs_ < r.size()) {
        // A factor from before a cut (pattern_extended): its DOFs by it, the appended ones
        // by their diagonal blocks; symmetric positive definite, so PCG stays valid.
        const Eigen::Index nf = factor_dofs_;
        Eigen::VectorXd head = r.head(nf);
        for (std::size_t i = 0; i < f_->tail_inv.size(); ++i) {
          const int a = f_->tail_alias[i];
          if (a >= 0) head.segment<3>(3 * a) += r.segment<3>(nf + 3 * static_cast<Eigen::Index>(i));
        }
        Eigen::VectorXd zh;
        if (single_precision_ && kind_ == Kind::PcgFactor && !f_->single.empty()) {
          f_->single.solve(head, zh);
        } else {
          zh = f_->cholmod->solve(head);
        }
        z.resize(r.size());
        z.head(nf) = zh;
        for (std::size_t i = 0; i < f_->tail_inv.size(); ++i) {
          const Eigen::Index k = nf + 3 * static_cast<Eigen::Index>(i);
          const int a = f_->tail_alias[i];
          z.segment<3>(k) = f_->tail_inv[i] * r.segment<3>(k);
          if (a >= 0) z.segment<3>(k) += zh.segment<3>(3 * a);
        }
      } else if (single_precision_ && kind_ == Kind::PcgFactor && !f_->single.empty()) {
        f_->single.solve(r, z);
      } else {
        z = f_->cholmod->solve(r);
      }
      break;
  }
}

LinearSolveSummary FemLinearSolver::solve(const SparseMatrixLower& A, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                                          double load_scale) {
  LinearSolveSummary s;
  ++solves_;
  if (background_ || job_.valid()) poll_background(s);
  if (!background_ && kind_ == Kind::PcgFactor && factor_pending()) {
    // After a cut (pattern_extended): PCG on the old factor while the new one is made on the
    // worker (started here, from the matrix of this solve); no inline refactorisation.
    if (!job_.valid()) start_background(A, s);
    if (!s.factorized) ++steps_since_factor_;
  } else if (background_) {
    if (!have_factor_) {
      if (!factorize(A, s)) return s;  // nothing to precondition with yet: inline
      // The spare factor starts as a copy of this one (~5 ms for the liver's 30 MB, instead
      // of a second ordering and symbolic analysis, ~70 ms), so that the first background
      // refactorisation can start at the next solve and is numeric only.
      if (!job_.valid()) {
        f_->pending->copy_from(*f_->cholmod);
        pending_version_ = f_->pending->info() == Eigen::Success ? factor_version_ : -1;
        pending_dofs_ = factor_dofs_;
      }
    } else if (!job_.valid() && (refresh_requested_ || (refactor_every_ > 0 && solves_ - started_stamp_ >= refactor_every_))) {
      start_background(A, s);
    }
  } else {
    const bool due = !have_factor_ || kind_ == Kind::PcgJacobi ||
                     (refactor_every_ > 0 && steps_since_factor_ + 1 >= refactor_every_);
    if (due && !factorize(A, s)) return s;
    if (!s.factorized) ++steps_since_factor_;
  }
  s.factor_age = static_cast<int>(solves_ - factor_stamp_);
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
  prepare_preconditioner(A);
  const bool worker = background_ || job_.valid();  // a fresher factor can come from the worker
  Eigen::VectorXd r = b - Asym * x;
  s.initial_residual = r.norm() / b_norm;
  Eigen::VectorXd z, p, q;
  double rz = 0;
  double res = s.initial_residual;
  int it = 0;
  int cap = max_iterations_;
  bool extended = false;
  std::vector<double> alphas, betas;  // CG coefficients: the Lanczos tridiagonal, for kappa
  // Refactorise inline and restart CG (the preconditioner changed).
  auto restart = [&] {
    cap = it + max_iterations_;
    rz = 0;
    alphas.clear();
    betas.clear();
    p.resize(0);
  };
  auto refresh = [&](const std::string& why) {
    if (!factorize(A, s)) return false;
    prepare_preconditioner(A);
    s.message = "preconditioner refreshed after " + std::to_string(it) + " iterations: " + why;
    restart();
    return true;
  };
  bool waited = false;
  for (;;) {
    if (res <= tolerance_) break;
    if (it >= cap) {
      // Cap reached far from the solution with a lagged factor: refresh it and give CG
      // another `iterations`.
      if (kind_ != Kind::PcgFactor || s.factorized || res <= refresh_residual_) break;
      if (worker && !extended) {
        // Background mode: a fresher factor is on its way; another `iterations` with this
        // one cost far less than refactorising inline (which stays the last resort).
        extended = true;
        cap = it + max_iterations_;
        s.message = "PCG extended after " + std::to_string(it) + " iterations at residual " + std::to_string(res);
        continue;
      }
      if (job_.valid() && !waited) {
        // A factorisation is under way: waiting for its rest costs less than a new one.
        waited = true;
        job_.wait();
        poll_background(s);
        if (s.background_swapped) {
          prepare_preconditioner(A);
          s.message = "waited for the background factor after " + std::to_string(it) + " iterations at residual " +
                      std::to_string(res);
          restart();
          continue;
        }
      }
      if (!refresh("residual " + std::to_string(res))) return s;
      continue;
    }
    apply_preconditioner(r, z);
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
    if (!(pq > 0.0)) {
      // The preconditioner is SPD, so A is not positive definite along p. With a lagged
      // factor, a fresh factorisation tells whether A itself is (and fails if not).
      if (kind_ == Kind::PcgFactor && !s.factorized) {
        if (!refresh("direction of non-positive curvature")) return s;
        continue;
      }
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
  // Background mode: a factor with which PCG needed the extension (above the safeguard
  // residual after `iterations`) is replaced as soon as the worker is free, before the
  // fixed cadence says so. (Ending above `tolerance` alone is normal with a small cap.)
  if (background_ && extended) refresh_requested_ = true;
  s.factor_age = static_cast<int>(solves_ - factor_stamp_);
  return s;
}

}  // namespace arnav::host
