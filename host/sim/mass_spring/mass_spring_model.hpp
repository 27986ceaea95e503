#pragma once
// Mass-spring tissue model with Voigt elements (spring + dashpot in parallel on every tet
// edge, after the liver model of paper 000), lumped vertex masses, gravity, attachments.
// Frame World; units mm, kg, s, mN.
//
// Volume term (after Teschner et al. 2004): E_V = kv/2 (det F - 1)^2 per tet with
// kv = 0.5 E V0. Edge springs alone have no sense of volume or orientation: a 100 mm block
// of 5 kPa tissue collapsed under its own weight without it. The modulus is fixed (not
// from nu) so that the implicit system stays well conditioned; the network behaves like
// an isotropic material with nu of about 0.3 (nu of the region only enters the stress).
//
// Integrators (ModelConfig::integrator):
//  - "explicit": symplectic (semi-explicit) Euler, v += h M^-1 f(x, v); x += h v.
//    Conditionally stable: h < (2/w)(sqrt(1+z^2) - z), w^2 bounded by Gershgorin
//    (max_i 2 sum k / m_i, attachments included), z the damping ratio of that mode.
//    A step whose substep exceeds the bound is NOT taken: the summary says so
//    (healthy=false) and names the substeps that would be stable.
//  - "semi_implicit": linearised backward Euler (Baraff & Witkin 1998), one Newton step
//    per substep, (M - hC - h^2 K) dv = h (f + h K v), solved by Jacobi-preconditioned CG
//    (ModelConfig::iterations, tolerance). The spring tangent drops the compressive part
//    of the geometric stiffness so the matrix stays SPD: unconditionally stable for any
//    dt, with numerical damping that grows with dt. linear_solver "laplacian" replaces the
//    Jacobi preconditioner by the prefactored local/global matrix below.
//  Fallback: an explicit or local/global step that ends unhealthy (diverged) is undone and
//  redone semi-implicitly, and the semi-implicit integrator takes the next 1 s (warning).
//  - "local_global": backward Euler solved by `iterations` local/global iterations with a
//    constant matrix factored once by CHOLMOD (fast mass-spring, Liu et al. 2013; see
//    local_global_step.cpp). Refactored only when h, the fixed set or the attachments
//    change (lazily, at the next step), and after a cut (apply_mesh_change: on a worker
//    thread, truncated PCG on the old factor until it is ready).
// Springs do not know orientation: an inverted tet whose edges have their rest length
// feels no spring force, so the volume term carries an inversion barrier below J = 0.1
// (volume_energy). Inverted tets are still counted every step and reported (a counted
// warning; healthy=false only for a collapse, InversionMonitor in step_health.hpp).
#include <Eigen/Core>

#include <cstdint>
#include <future>
#include <memory>
#include <unordered_map>
#include <vector>

#include "host/sim/attachment_set.hpp"
#include "host/sim/mass_spring/prefactored_system.hpp"
#include "host/sim/mass_spring/spring_network.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/step_control.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/tet_geometry.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// Volume term of one tet, E(J) = kv/2 (J - 1)^2 + inversion barrier: energy (mN*mm),
// dE/dJ and the Gauss-Newton curvature d2E/dJ2.
double volume_energy(double J, double kv);
double volume_slope(double J, double kv);
double volume_curvature(double J, double kv);

class MassSpringModel final : public TissueModel {
 public:
  enum class Integrator { kExplicit, kSemiImplicit, kLocalGlobal };
  // Throws std::invalid_argument on an invalid problem or config.
  MassSpringModel(const SimProblem& problem, Integrator integrator, const ModelConfig& config);

  std::string name() const override;
  StepSummary step(double dt_s) override;

  AttachmentId add_attachment(const AttachmentSpec& spec) override;
  void set_attachment_target(AttachmentId id, const Eigen::Vector3d& target_World_mm) override;
  void set_attachment_stiffness(AttachmentId id, double stiffness_mN_per_mm) override;
  void remove_attachment(AttachmentId id) override;
  void set_fixed_vertices(const std::vector<int>& vertices) override;

  const Eigen::Matrix3Xd& positions_World_mm() const override { return x_; }
  const Eigen::Matrix3Xd& velocities_World_mm_s() const override { return v_; }
  void set_state(const Eigen::Matrix3Xd& positions_World_mm, const Eigen::Matrix3Xd& velocities_World_mm_s) override;
  std::vector<ElementMeasure> element_measures() const override;
  // In place after a cut, every integrator: the changed tets' spring, volume and mass
  // contributions out, the new ones in (springs found by edge), per-tet data replaced or
  // appended. O(changed tets) plus, for explicit, the O(mesh) stability bound. The
  // prefactored system (local_global, semi_implicit with the laplacian preconditioner) is
  // assembled and factored again on a worker thread; until that factor is ready the global
  // step solves the new system by PCG preconditioned by the old factor (rows of the vertices
  // it knew) and the diagonal (new vertices), to 1e-10 relative (local_global_step.cpp).
  // A cut while a factorisation runs queues one more; attachments or fixed vertices changed
  // meanwhile refactor inline at the next step, as before.
  std::optional<MeshChangeStats> apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                   const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s) override;

  // Largest explicit substep (s) that is stable for the current springs and attachments.
  double explicit_stable_substep_s() const;
  // The substeps an explicit step of dt_s takes (docs/sim.md, "Step control and refusal at
  // load"): the configured count when its substep is within the stability bound; beyond it,
  // the count the bound needs with 25 % margin, up to SubstepControl::budget_substeps; 0 when
  // the bound needs more than that budget (the step is refused). After a cut lowered the
  // bound, the same with no budget (a cut never stops the model).
  int explicit_substeps(double dt_s) const;
  // The smallest substep count whose substep is within the stability bound at dt_s.
  int explicit_substeps_needed(double dt_s) const;
  // Elastic energy of springs and attachments at the current state (mN*mm).
  double elastic_energy() const;
  const SpringNetwork& springs() const { return springs_; }
  // local_global: numeric factorisations so far, and the last one's wall time (ms).
  int refactorizations() const { return refactorizations_; }
  // After cuts: factorisations made on the worker thread and adopted, global solves run by
  // PCG on an old factor while one was pending, and their PCG iterations.
  int background_factorizations() const { return background_factorizations_; }
  int stale_solves() const { return stale_solves_; }
  int stale_pcg_iterations() const { return stale_pcg_iterations_; }
  bool factor_pending() const { return pending_factor_.valid() || factor_stale_; }
  // Blocks until the pending background factorisations (if any) are done and the current
  // one adopted (tests).
  void wait_for_factor();
  // Tests: while held, a finished background factorisation is not adopted (the global step
  // keeps solving by PCG on the old factor).
  void hold_background_factor(bool hold) { hold_factor_ = hold; }
  // PCG iterations per global solve on an old factor (default 2: about three times a step
  // with a current factor) and its relative tolerance (default 1e-8).
  void set_stale_pcg(int max_iterations, double relative_tolerance) {
    stale_pcg_limit_ = max_iterations;
    stale_pcg_tolerance_ = relative_tolerance;
  }
  double last_factor_ms() const { return system_.last_factor_ms(); }
  // explicit / local_global: steps redone with the semi-implicit integrator after they
  // diverged (step() below; docs/sim.md).
  int fallbacks() const { return fallbacks_; }
  // semi_implicit (also the fallback): steps redone with more substeps after they ended
  // unhealthy (energy created, non-finite), up to kMaxRetrySubsteps times the configured ones
  // for a step of up to 1/60 s, more for a longer one (SubstepControl::budget_factor; the
  // factor that held is kept until the tissue calms).
  // explicit: its steps count at the factor explicit_substeps() took (steps_at_factor()).
  int retries() const { return control_.redone_steps(); }
  const SubstepControl& step_control() const { return control_; }
  static constexpr int kMaxRetrySubsteps = SubstepControl::kMaxFactor;

 private:
  StepSummary step_guarded(double dt_s);    // step() before the embedded vertices are driven
  std::string explicit_substeps_warning(double dt_s, int substeps) const;
  StepSummary semi_implicit_guarded(double dt_s);  // semi-implicit step, redone with more substeps when unhealthy
  StepSummary step_unguarded(double dt_s);  // one step with integrator_ and config_
  bool passive(int t) const { return static_cast<std::size_t>(t) < passive_.size() && passive_[static_cast<std::size_t>(t)] != 0; }
  void merge_fixed();  // fixed_ = user_fixed_ or held by the embedding
  void explicit_substep(double h);
  StepSummary semi_implicit_substep(double h);
  StepSummary local_global_substep(double h);
  // semi_implicit with linear_solver "laplacian": z = (h^2 A)^-1 r with the local/global matrix.
  void precondition_with_laplacian(const Eigen::Matrix3Xd& r, Eigen::Matrix3Xd& z, double h);
  bool build_local_global_system(double h, std::string& error);
  // Accumulates spring (and attachment) forces into f_ (3 x n), gravity and mass damping
  // included; with h > 0 also fills the per-spring tangent data and the CG right-hand side.
  void assemble(double h);
  // out = (M - hC - h^2 K) p (fixed rows zero); returns p.out.
  double apply_system(const Eigen::Matrix3Xd& p, Eigen::Matrix3Xd& out);
  void scatter_springs_to_buffers();
  struct StateMeasure {
    double elastic_energy = 0.0;  // springs, volume terms, attachments (mN*mm)
    int inverted_tets = 0;
  };
  StateMeasure measure_state() const;
  void update_omega_bound();
  void reset_ledger();

  Integrator integrator_;
  ModelConfig config_;
  bool laplacian_pc_ = false;  // semi_implicit: CG preconditioned by the prefactored Laplacian
  int threads_;
  Eigen::Matrix3Xd x_, v_;
  Eigen::VectorXd mass_, inv_mass_, mass_damping_;  // mass_damping_: Rayleigh alpha * m (kg/s)
  std::vector<unsigned char> fixed_;       // held by the solver: user_fixed_ or embedded (below)
  std::vector<unsigned char> user_fixed_;  // set_fixed_vertices / the problem's
  // Tets below the quality bound (problem.embedded): no spring stiffness, no volume term;
  // driven vertices and rigid groups are held in the solver and moved after each step.
  std::vector<std::uint8_t> passive_;
  EmbeddedMotion embedded_;
  Eigen::Vector3d gravity_;
  bool vessels_ignored_ = false;  // the problem declares vessels this model cannot couple
  SpringNetwork springs_;
  AttachmentSet attachments_;

  // Tets, for element measures and inversion checks.
  std::vector<std::array<int, 4>> tets_;
  std::vector<Eigen::Matrix3d> Dm_inv_;
  std::vector<Lame> tet_lame_;
  std::vector<double> volume_stiffness_;  // kv = 0.5 E V0 per tet, mN*mm
  std::vector<double> inv_6v0_;           // 1 / (6 V0): J = 6 V / (6 V0)
  std::vector<std::array<Eigen::Vector3d, 4>> vol_grad_;  // semi-implicit: g_a of the substep
  std::vector<double> vol_coef_;                          // semi-implicit: h^2 kv

  double omega_max_ = 0.0;  // Gershgorin bound of sqrt(max eig M^-1 K), 1/s
  double zeta_ = 0.0;       // damping ratio of that mode
  // A cut lowered the explicit integrator's stability bound (its small pieces): from then on
  // a step whose substep is beyond the bound takes the substeps the bound needs (+25 %)
  // instead of being refused (docs/sim.md "Run-time health").
  bool bound_lowered_by_cut_ = false;
  double current_h_ = 0.0;  // substep of the current semi-implicit solve
  InversionMonitor inversions_;  // inverted tets: counted warning (step_health.hpp)
  double fallback_left_s_ = 0.0;  // simulated time the semi-implicit fallback still runs
  int fallbacks_ = 0;
  SubstepControl control_;  // semi-implicit steps: redone with more substeps when unhealthy
  // The state an undone step is redone from (step_guarded, semi_implicit_guarded; members: no
  // allocation per step).
  Eigen::Matrix3Xd x_before_step_, v_before_step_;
  EnergyLedger ledger_;

  // Work buffers, sized once (no allocation per step).
  std::vector<Eigen::Matrix3Xd> thread_buffers_;
  Eigen::Matrix3Xd f_, rhs_, dv_, r_, z_, p_, q_, diag_;
  std::vector<Eigen::Vector3d> spring_dir_;  // unit direction per spring (semi-implicit)
  std::vector<double> spring_s1_, spring_s2_;  // tangent block S = s1 n n^T + s2 I

  // local_global: the constant matrix over the free vertices and its factor.
  PrefactoredSystem system_;
  PrefactoredSystem::Matrix base_;  // masses, springs, volume terms (lower), for base_h_
  bool base_valid_ = false;         // false after set_fixed_vertices
  double base_h_ = 0.0;
  bool system_dirty_ = true;
  double system_h_ = 0.0;
  int refactorizations_ = 0;
  std::vector<int> free_index_;  // vertex -> row of the system, -1 for fixed vertices
  Eigen::Matrix3Xd xn_, vn_;     // state at the start of the substep
  Eigen::MatrixX3d lg_rhs_, lg_dx_;
  Eigen::Matrix3Xd x_prev_;      // previous local/global iterate (Chebyshev acceleration)
  // Local updates: spring of each edge (key min << 32 | max) and tets using each spring,
  // built at the first one.
  std::unordered_map<std::uint64_t, int> spring_of_edge_;
  std::vector<int> spring_tets_;
  // Background factorisation after a cut (local_global_step.cpp).
  struct PendingFactor;
  std::future<std::unique_ptr<PendingFactor>> pending_factor_;
  int free_count_ = 0;             // rows of the current system
  bool factor_stale_ = false;      // system_ factors an older matrix (pc_free_index_ rows)
  bool refactor_again_ = false;    // the mesh changed while a factorisation ran
  bool stale_ready_ = false;       // pc_row_, pc_diag_ match the current mesh
  bool hold_factor_ = false;
  int stale_pcg_limit_ = 2;
  double stale_pcg_tolerance_ = 1e-8;
  int mesh_version_ = 0;           // bumped by every cut and every inline factorisation
  std::vector<int> pc_free_index_; // vertex -> row of system_ while stale (-1: fixed or unknown)
  std::vector<int> pc_alias_;      // per vertex: the vertex it moves with in the preconditioner (itself, or a neighbour for a vertex made by a cut)
  std::vector<int> pc_row_;        // row of the current system -> row of system_ (own or its alias's; -1: none)
  std::vector<char> pc_own_;       // the row is the factor's own (else aliased: plus the diagonal)
  Eigen::VectorXd pc_diag_;        // diagonal of the current matrix
  Eigen::MatrixX3d pc_rhs_, pc_sol_, pcg_r_, pcg_z_, pcg_p_, pcg_q_;
  int background_factorizations_ = 0, stale_solves_ = 0, stale_pcg_iterations_ = 0;
  void launch_background_factor();
  void poll_background_factor(double h, bool wait);
  void prepare_stale_preconditioner(double h);
  void stale_precondition(const Eigen::MatrixX3d& r, Eigen::MatrixX3d& z);
  void apply_local_global_matrix(const Eigen::MatrixX3d& p, Eigen::MatrixX3d& out, double h) const;
  int solve_with_stale_factor(const Eigen::MatrixX3d& b, Eigen::MatrixX3d& x, double h);
};

}  // namespace arnav::host
