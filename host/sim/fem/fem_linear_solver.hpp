#pragma once
// Linear solves of the FEM step: A x = b with A symmetric positive definite, stored as
// its lower triangle (symmetric_pattern.hpp). Four strategies, picked by the scene:
//   Cholmod      CHOLMOD supernodal Cholesky; refactor_every = 1 is exact every step,
//                N > 1 reuses a lagged factor as an approximate direct solve.
//   EigenLdlt    Eigen SimplicialLDLT (no SuiteSparse), same factor policy.
//   PcgFactor    preconditioned CG on the current matrix with the lagged CHOLMOD factor
//                as preconditioner (refreshed every refactor_every steps; 0 = never after
//                the first), warm started from the caller's x.
//   PcgJacobi    CG with the diagonal as preconditioner, warm started.
// PcgFactor can refactorise in the background (set_background_refactor): a worker thread
// factorises a snapshot of the matrix while PCG keeps preconditioning with the last
// factor; the new factor replaces it at the first solve after the worker is done.
#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "host/sim/fem/symmetric_pattern.hpp"

namespace arnav::host {

struct LinearSolveSummary {
  int iterations = 0;            // CG iterations (1 for a direct solve)
  double initial_residual = 0;   // ||b - A x0|| / max(||b||, load_scale)
  double final_residual = 0;     // ||b - A x|| / max(||b||, load_scale)
  std::string termination;       // "direct", "direct_lagged", "direct_refreshed", "converged",
                                 // "max_iterations", "factorization_failed"
  bool factorized = false;       // a numeric factorisation ran in this solve
  double factor_ms = 0;
  bool ok = true;                // false: factorisation failed (A not positive definite)
  double condition_estimate = 0; // CG kinds with estimate_condition: Lanczos estimate of
                                 // lambda_max/lambda_min of the preconditioned matrix (lower bound)
  std::string message;
  int factor_age = 0;             // solves since the matrix of the factor used was taken (0: this one)
  bool background_started = false;  // a background factorisation of this matrix was started
  bool background_swapped = false;  // a background factor was swapped in before this solve
};

class FemLinearSolver {
 public:
  enum class Kind { Cholmod, EigenLdlt, PcgFactor, PcgJacobi };
  // Parses "cholmod" | "eigen_ldlt" | "pcg" | "pcg_jacobi"; throws std::invalid_argument otherwise.
  static Kind parse(const std::string& name);

  FemLinearSolver(Kind kind, int refactor_every, int max_iterations, double tolerance);
  ~FemLinearSolver();  // waits for a background factorisation
  FemLinearSolver(const FemLinearSolver&) = delete;
  FemLinearSolver& operator=(const FemLinearSolver&) = delete;

  // PcgFactor only (std::invalid_argument otherwise). On: a refactorisation that is due
  // (refactor_every solves since the last one was started, or requested by
  // force_refactor) runs on a worker thread on a copy of the matrix while this and the
  // following solves keep the last factor; the first factor, one after pattern_changed()
  // and the residual safeguard's refresh stay inline. Results then depend on how fast the
  // worker is (not bit-reproducible); off (default) is deterministic.
  void set_background_refactor(bool on);
  bool background_refactor() const { return background_; }
  // Nice level (0-19) of the background worker thread: on a machine with more runnable
  // threads than cores the stepping thread gets most of a core and the refactorisation
  // the rest (default 5: about 3:1 against the stepping thread, ahead of niced builds; 19
  // starves the worker under load and the lagged factor ages; docs/sim-fem.md).
  void set_background_nice(int nice_level) { background_nice_ = nice_level; }
  // Waits until a running background factorisation is done (for tests).
  void wait_for_background();

  // The pattern changed (symbolic analysis again) or values changed in a way the lagged
  // factor must not survive (fixed set, time step).
  void pattern_changed();
  void force_refactor();
  // PcgFactor after a cut (CorotationalFem::apply_mesh_change): the matrix gained entries
  // and possibly DOFs (appended at the end: old_vertices.. old_vertices + alias.size() - 1).
  // The factor in use stays the preconditioner of the DOFs it has (a factor of the matrix
  // before the cut); an appended vertex w is aggregated with the older vertex alias[w -
  // old_vertices] (free, nearby; -1: none, e.g. fixed): z = R^T L^-T L^-1 R r + D^-1 r on
  // the appended DOFs, R adding each appended vertex's residual to its alias', D the
  // appended vertices' 3x3 diagonal blocks (symmetric positive definite). A factor of the new pattern (symbolic
  // analysis included) is made on a worker thread from the matrix of the next solve, whether
  // refactor_in_background is on or not; it replaces the old one at the first solve after
  // it is done. A cut while that job runs: its factor (closer to the new matrix) is taken
  // when done and another job follows for the newest pattern. Other kinds: pattern_changed().
  // changed_vertices: the vertices whose matrix entries the cut changed (those of the
  // changed tets before and after, the appended ones). While the factor in use is older
  // than the pattern, PCG corrects it there (set_cut_region_rings): with S the DOFs of the
  // vertices changed since the factor's pattern (plus rings of neighbours) and
  // T = E A_SS^-1 E^T the exact solve on them with the current matrix, the preconditioner is
  // T + (I - T A) P (I - A T), P the padded old factor: symmetric positive definite, and
  // exact in the region where the old factor still couples the two sides of the cut.
  void pattern_extended(int old_vertices, const std::vector<int>& alias, const std::vector<int>& changed_vertices = {});
  // Rings of neighbours added to the corrected region (default 1); -1: no correction (the
  // padded old factor alone, as before).
  void set_cut_region_rings(int rings) { cut_region_rings_ = rings; }
  // True while the factor in use belongs to an older pattern (a cut's factor is pending).
  bool factor_pending() const { return have_factor_ && factor_version_ != pattern_version_; }

  // Solves A x = b; x holds the warm start on entry (iterative kinds). Residuals are
  // relative to max(||b||, load_scale): near equilibrium b vanishes, and a criterion
  // relative to ||b|| alone would demand ever more digits of a vanishing update.
  LinearSolveSummary solve(const SparseMatrixLower& A, const Eigen::VectorXd& b, Eigen::VectorXd& x,
                           double load_scale = 0.0);

  Kind kind() const { return kind_; }
  // Costs an O(iterations^2) eigenvalue solve per CG solve: for studies, not for real time.
  void set_estimate_condition(bool on) { estimate_condition_ = on; }
  // A lagged factor whose result leaves a relative residual above this (direct kinds), or
  // with which PCG ends its iterations above it, is refactorised at once and the solve
  // repeated ("direct_refreshed" / PCG restarted): lagging must not turn into divergence.
  void set_refresh_residual(double r) { refresh_residual_ = r; }
  // PcgFactor: precondition with a single-precision copy of the factor
  // (single_precision_factor.hpp): half the memory traffic per application; PCG corrects
  // the rounding. Set before the first solve (std::logic_error afterwards: factors already
  // made, in the background too, would not match the setting).
  void set_single_precision_preconditioner(bool on);

 private:
  bool factorize(const SparseMatrixLower& A, LinearSolveSummary& s);
  void apply_factor(const Eigen::VectorXd& r, Eigen::VectorXd& z) const;
  void poll_background(LinearSolveSummary& s);
  void start_background(const SparseMatrixLower& A, LinearSolveSummary& s);
  void discard_background();

  Kind kind_;
  int refactor_every_;
  int max_iterations_;
  double tolerance_;
  bool estimate_condition_ = false;
  double refresh_residual_ = 0.1;
  bool analyzed_ = false;
  bool have_factor_ = false;
  int steps_since_factor_ = 0;
  bool background_ = false;
  int background_nice_ = 5;
  bool single_precision_ = false;
  bool refresh_requested_ = false;  // background mode: force_refactor() asked for a new factor
  long solves_ = 0;                 // solve() calls so far
  long factor_stamp_ = 0;           // solves_ when the active factor's matrix was taken
  long started_stamp_ = 0;          // solves_ when the last background job was started
  long pending_stamp_ = 0;          // solves_ of the running job's snapshot
  // Pattern versions (pattern_extended): of the current matrix, of the factor in use and of
  // the pending factor (its symbolic analysis); the DOFs each factor covers.
  long pattern_version_ = 0, factor_version_ = 0, pending_version_ = 0;
  Eigen::Index factor_dofs_ = 0, pending_dofs_ = 0;
  std::vector<int> alias_;  // per vertex: the older vertex an appended one is aggregated with (identity before the first cut)
  void prepare_padding(const SparseMatrixLower& A);
  // Padding and cut-region correction of the factor in use for the matrix A.
  void prepare_preconditioner(const SparseMatrixLower& A);
  void apply_preconditioner(const Eigen::VectorXd& r, Eigen::VectorXd& z) const;
  struct CutRegion {
    long version;               // pattern version the cut made
    std::vector<int> vertices;  // vertices whose entries it changed
  };
  std::vector<CutRegion> cut_regions_;  // since the factor in use
  int cut_region_rings_ = 1;
  bool region_active_ = false;
  std::future<int> job_;            // the running background job (JobResult in the .cpp)
  struct Factors;
  std::unique_ptr<Factors> f_;
};

}  // namespace arnav::host
