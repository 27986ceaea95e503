#pragma once
// Co-rotational linear FEM on P1 tetrahedra (paper 001), optionally stiffened by vessel
// beams embedded in the tets (host/sim/beams, K = Kp + J^T Kb J). Frame World; units mm,
// kg, s, mN, kPa.
//
// Per element the rotation R of F = Ds Dm^-1 is extracted (rotation_extraction.hpp,
// valid for inverted elements); the elastic force is f = -V R sigma(R^T F - I) g with the
// linear stress sigma, and the stiffness R K R^T is scattered into a fixed pattern
// (stiffness warping: dR/dx is neglected, as in SOFA and paper 001).
// Integrators (ModelConfig.integrator):
//   implicit_euler  one linearised backward-Euler solve per step for the new velocity:
//                   (M + dt C + dt^2 K) v+ = M v + dt f(x), C = alpha M + beta K (Rayleigh).
//   quasi_static    one Newton-like step per call toward equilibrium: K dx = f(x), shortened
//                   by a backtracking line search on the total potential energy; repeated
//                   calls converge; velocities report dx/dt.
// Linear solvers: fem_linear_solver.hpp. ModelConfig.threads workers assemble in parallel
// (OpenMP); ModelConfig.substeps splits step(dt) into equal sub-steps.
// What the model cannot handle is reported in the StepSummary (healthy=false + warning)
// and the state is left as it was before the failing (sub-)step.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <optional>
#include <vector>

#include "host/sim/beams/beam_embedding.hpp"
#include "host/sim/fem/fem_linear_solver.hpp"
#include "host/sim/fem/fem_mesh_change.hpp"
#include "host/sim/fem/symmetric_pattern.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/step_control.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/fem/fem_attachments.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// Settings beyond ModelConfig (limits of what the model reports as unhealthy).
struct FemOptions {
  double max_speed_mm_s = kBlowUpSpeed_mm_s;  // above this a step is rejected as unstable
  double refresh_residual = 0.1;    // lagged factor refreshed when its residual exceeds this
  double strain_warning = 0.3;      // co-rotated strain beyond which linear elasticity is
                                    // reported as out of range (warning, still healthy)
  VesselBeamOptions beams;          // used only when the problem declares vessels
  int background_nice = 5;          // refactor_in_background: nice level of the worker thread
                                    // (FemLinearSolver::set_background_nice)
  int cut_region_rings = 1;         // after a cut, while PCG runs on the old factor: the changed
                                    // vertices and this many rings of neighbours are solved
                                    // exactly on the current matrix (-1: off; FemLinearSolver::pattern_extended)
};

class CorotationalFem final : public TissueModel {
 public:
  // Throws std::invalid_argument for an unknown integrator/solver, a degenerate or
  // inverted rest tet, a material out of range, or a vessel outside the mesh.
  CorotationalFem(const SimProblem& problem, const ModelConfig& config, const FemOptions& options = {});
  ~CorotationalFem() override;

  std::string name() const override { return "corotational_fem/" + integrator_; }
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
  // In place after a cut (docs/sim-fem.md "After a cut"): per-element data (rest shape,
  // Lame parameters, quarter masses, warm-start rotation) of the changed and appended tets
  // only, lumped masses and state of their vertices and of the appended ones (fixed ones
  // among them held), the sparse pattern grown by the new vertex pairs (one merge pass
  // over the entries, the unchanged tets' maps remapped, not recomputed). As for the
  // lagged refactorisation: with refactor_in_background (pcg), PCG keeps preconditioning
  // with the factor from before the cut (appended vertices aggregated with an older
  // neighbour, plus their 3x3 diagonal blocks) while the factor of the new pattern is made
  // on a worker thread (FemLinearSolver::pattern_extended); otherwise (deterministic) the
  // new pattern is analysed and factorised at the next step. Returns nothing (the caller rebuilds) when a vessel beam is embedded in a
  // changed tet or holds one of its vertices. Throws std::invalid_argument, before
  // changing anything, for a changed tet of non-positive rest volume or a vertex left
  // without mass.
  std::optional<MeshChangeStats> apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                   const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s) override;
  // After a cut: the factor of the new pattern is still being made (PCG runs on the old one).
  bool factor_pending() const { return solver_.factor_pending(); }
  // FemOptions::cut_region_rings (benchmarks compare the settings on one model).
  void set_cut_region_rings(int rings);

  // Introspection for tests and benchmarks.
  int num_beam_elements() const { return static_cast<int>(beams_.size()); }
  const std::optional<VesselEmbedding>& vessel_embedding() const { return embedding_; }
  // Last assembled system matrix (lower triangle) and the last linear solve.
  const SparseMatrixLower& system_matrix() const { return A_; }
  const LinearSolveSummary& last_linear_solve() const { return last_solve_; }
  // Where the last (sub-)step's time went, ms: rotations + forces + scatter, linear solve
  // (including any factorisation); wall time and process CPU time (all threads). On a
  // shared machine the CPU time is what the work costs when it gets a core.
  // The *_thread_cpu_ms are the calling thread's CPU time only: with a background
  // factorisation running, the process CPU time also counts the worker.
  struct Timing {
    double assemble_ms = 0, solve_ms = 0;
    double assemble_cpu_ms = 0, solve_cpu_ms = 0;
    double assemble_thread_cpu_ms = 0, solve_thread_cpu_ms = 0;
  };
  const Timing& last_timing() const { return timing_; }
  void set_estimate_condition(bool on) { solver_.set_estimate_condition(on); }
  // refactor_in_background: blocks until the running background factorisation is done
  // (tests use it to make the background path deterministic).
  void wait_for_background() { solver_.wait_for_background(); }
  const InversionMonitor& inversions() const { return inversions_; }
  // Step control (step_control.hpp): an unhealthy step redone from its saved state with 2-8x
  // the substeps (the budget is budget_factor(dt)); redone steps, steps at each factor.
  const SubstepControl& step_control() const { return control_; }

 private:
  struct Tet {
    std::array<int, 4> v;
    Eigen::Matrix3d Dm_inv;
    std::array<Eigen::Vector3d, 4> g;  // shape function gradients (rest)
    double volume, mu, lambda, beta;
    bool passive = false;  // below the quality bound (problem.embedded): no elastic term, not assembled
  };
  struct Beam {
    std::vector<int> v;
    Eigen::MatrixXd K;       // rest stiffness J^T Kb J
    Eigen::VectorXd X;       // rest positions of its vertices
    std::array<int, 2> tets;
    double beta;
  };

  void build_pattern();
  void update_fixed_entries();
  // apply_mesh_change, in parts (an element-exclusion flag would be honoured in
  // make_element and in the pattern groups of grow_pattern).
  Tet make_element(const SimProblem& problem, int mesh_tet, double& quarter_mass, double& quarter_alpha) const;
  // changes: the changed tets before and after the cut (pairs no tet, attachment or beam
  // couples any more leave the pattern).
  void grow_pattern(const std::vector<int>& stored_changed, int old_vertices, const std::vector<fem::TetChange>& changes);
  // For each vertex from old_vertices on: the nearest (rest) free older vertex it shares a
  // changed tet with (through other new vertices if need be), -1 for fixed or isolated ones
  // (FemLinearSolver::pattern_extended aggregates them in the old factor).
  std::vector<int> preconditioner_aliases(const std::vector<int>& stored_changed, int old_vertices) const;
  struct AssemblyStats {
    double energy = 0;
    int inverted = 0;
    double max_strain = 0;  // largest |co-rotated strain component| of any tet
  };
  AssemblyStats assemble(double dt_s, bool dynamic);
  void assemble_element(int id, double dt_s, bool dynamic, double& energy, int& inverted, double& max_strain);
  StepSummary substep(double dt_s);
  // Total potential (elastic + gravity + attachments), mN*mm; updates the warm-start rotations.
  double potential_energy(const Eigen::Matrix3Xd& x);
  double external_potential(const Eigen::Matrix3Xd& x) const;

  std::string integrator_;
  FemOptions options_;
  int threads_ = 1;
  int substeps_ = 1;
  Eigen::Vector3d gravity_;
  Eigen::Matrix3Xd X_, x_, v_;
  Eigen::VectorXd mass_, mass_alpha_, mass_damped_;  // lumped m, alpha m, m + dt alpha m
  std::vector<Tet> tets_;                  // in tet_order_ (spatial order), not mesh order
  std::vector<int> tet_order_;             // stored tet i is mesh tet tet_order_[i]
  std::vector<int> stored_of_mesh_;        // inverse of tet_order_ (made at the first apply_mesh_change)
  std::vector<double> quarter_mass_, quarter_alpha_;  // per stored tet: its share of each vertex's m and alpha m
  fem::TetPairCounts pair_tets_;           // tets per vertex pair (made at the first apply_mesh_change)
  std::vector<Beam> beams_;
  std::optional<VesselEmbedding> embedding_;
  std::vector<Eigen::Quaterniond> q_;      // per-tet rotation (warm start)
  std::vector<Eigen::Matrix3d> R_beam_;
  fem::FemAttachmentSet attachments_{"corotational_fem"};
  std::vector<char> fixed_;               // per vertex: user_fixed_ or held by embedded_
  std::vector<char> user_fixed_;          // the problem's / set_fixed_vertices
  // Embedded treatment of tets below the quality bound (embedded_elements.hpp): driven
  // vertices and rigid groups are held (Dirichlet) in the solve, their mass moved, and
  // written after every step. A local update after a cut must redo this for the new
  // problem.embedded (restore_mass, reset, move_mass, merge_fixed_with_embedding).
  EmbeddedMotion embedded_;
  void apply_embedding(const SimProblem& problem, Eigen::VectorXd& mass_alpha);  // constructor
  void merge_fixed_with_embedding();
  std::vector<int> fixed_entries_;        // nonzeros in rows/cols of fixed DOFs (off-diagonal)
  std::unique_ptr<SymmetricPattern> pattern_;
  std::vector<int> tet_map_;                   // 30 run starts per tet (10 blocks, compact_block_map)
  std::vector<std::vector<int>> beam_maps_;
  ElementPartition partition_;            // element ids: tets [0, T), beams [T, T+B)
  SparseMatrixLower A_;
  Eigen::VectorXd f_, f_ext_, rhs_, sol_, last_dx_;
  FemLinearSolver solver_;
  LinearSolveSummary last_solve_;
  Timing timing_;
  InversionMonitor inversions_;
  double last_dt_ = -1.0;
  std::string note_;  // said once in the next step's warning (e.g. blas_threads not honoured)
  SubstepControl control_;
  // The state an unhealthy step is redone from (members: no allocation per step). The
  // lagged factor is not saved: a redo at another sub-step size refactorises (last_dt_).
  Eigen::Matrix3Xd x_saved_, v_saved_;
  std::vector<Eigen::Quaterniond> q_saved_;
  std::vector<Eigen::Matrix3d> R_beam_saved_;
  Eigen::VectorXd last_dx_saved_;
  InversionMonitor inversions_saved_;
};

// Factory entry (used by host/sim/model_factory when arnav_sim_fem is built).
std::unique_ptr<TissueModel> make_corotational_fem(const SimProblem& problem, const ModelConfig& config);

}  // namespace arnav::host
