#pragma once
// Implicit FEM on P1 tetrahedra with the stable Neo-Hookean energy (Smith, de Goes & Kim
// 2018) and projected Newton: the material option `material_model: stable_neo_hookean` of
// kind corotational_fem (docs/sim.md). Frame World; units mm, kg, s, mN, kPa.
//
// Energy density (defined for every F, inverted elements included; zero at rest):
//   Psi(F) = mu/2 (|F|^2 - 3) - mu (J - 1) + lambda'/2 (J - 1)^2,  J = det F,
// with lambda' = lambda + mu, so that for small strain Psi -> mu |eps|^2 + lambda/2 tr(eps)^2:
// the linear (and co-rotational) model with the same Lame parameters (mu, lambda).
// P = dPsi/dF = mu F + (lambda' (J - 1) - mu) cof(F); the 9x9 Hessian
//   mu I + lambda' vec(cof F) vec(cof F)^T + (lambda' (J - 1) - mu) d2J/dF2
// is indefinite under compression and inversion; each element's Hessian is projected to
// positive semi-definite (a Cholesky test first; if it fails, the negative modes of the
// analytic eigensystem, Smith, de Goes & Kim 2019, are removed), so every Newton system is
// positive definite.
//
// Integrators (ModelConfig.integrator):
//   implicit_euler  minimises the incremental potential of backward Euler
//                   E(x) = 1/2 (x - x^)^T M (x - x^) + h^2 (Psi(x) + U_ext(x)) + damping,
//                   x^ = x_n + h v_n, damping (Rayleigh) = h/2 (x - x_n)^T (alpha M + sum beta_e K_e(x_n)) (x - x_n)
//                   with up to ModelConfig.iterations Newton iterations per step (started at x_n),
//                   each followed by a backtracking (Armijo) line search on E; stops when the
//                   gradient is below tolerance x the step's load. v = (x - x_n) / h.
//   quasi_static    the same Newton iterations on Psi + U_ext (no inertia) per call.
// Linear solves: fem_linear_solver.hpp (default cholmod; pcg keeps a lagged factor as
// preconditioner, its max iterations fixed at 100). Vessel beams are not coupled in this
// material (said once in the first step's warning).
#include <Eigen/Core>

#include <memory>
#include <optional>
#include <vector>

#include "host/sim/fem/corotational_fem.hpp"
#include "host/sim/fem/fem_linear_solver.hpp"
#include "host/sim/fem/fem_mesh_change.hpp"
#include "host/sim/fem/symmetric_pattern.hpp"
#include "host/sim/model_config.hpp"
#include "host/sim/step_control.hpp"
#include "host/sim/step_health.hpp"
#include "host/sim/fem/fem_attachments.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// The element energy and its derivatives in F (for the model and its tests). Lame
// parameters are those of linear elasticity (the lambda' shift is applied inside).
namespace stable_neo_hookean {
using Matrix9d = Eigen::Matrix<double, 9, 9>;
double energy_density(const Eigen::Matrix3d& F, double mu, double lambda);
Eigen::Matrix3d first_piola(const Eigen::Matrix3d& F, double mu, double lambda);
// d2Psi/dF2 in column-major vec(F) order; `project`: clamped to positive semi-definite.
// `projected` (optional) tells whether the eigen-decomposition was needed.
Matrix9d hessian(const Eigen::Matrix3d& F, double mu, double lambda, bool project, bool* projected = nullptr);
// Reference projection for the tests: full 9x9 eigen-decomposition, negative eigenvalues -> 0.
Matrix9d project_numerically(const Matrix9d& H);
}  // namespace stable_neo_hookean

class StableNeoHookeanFem final : public TissueModel {
 public:
  // Throws std::invalid_argument for an unknown integrator/solver, a degenerate or inverted
  // rest tet or a material out of range.
  StableNeoHookeanFem(const SimProblem& problem, const ModelConfig& config, const FemOptions& options = {});
  ~StableNeoHookeanFem() override;

  std::string name() const override { return "corotational_fem/stable_neo_hookean/" + integrator_; }
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
  // In place after a cut (docs/sim-fem.md "After a cut"), as CorotationalFem does it
  // (fem_mesh_change.hpp): element data (rest shape, Lame parameters, quarter masses) of the
  // changed and appended tets only (and of the few whose passive flag the new embedding
  // flips), lumped masses and state of their vertices and of the appended ones, the
  // embedding's driven vertices and rigid groups, the sparse pattern grown by the new vertex
  // pairs and cleared of the uncoupled ones in one merge pass (unchanged tets' maps
  // remapped). The new pattern is analysed and factorised at the next solve. Throws
  // std::invalid_argument, before changing anything, for a changed tet of non-positive rest
  // volume or a vertex left without mass.
  std::optional<MeshChangeStats> apply_mesh_change(const SimProblem& problem, const std::vector<int>& changed_tets,
                                                   const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s) override;

  // Introspection for tests and benchmarks.
  const InversionMonitor& inversions() const { return inversions_; }
  // Step control (step_control.hpp): an unhealthy step redone from its saved state with 2-8x
  // the substeps (each with the configured Newton iterations; the budget is budget_factor(dt));
  // redone steps, steps at each factor.
  const SubstepControl& step_control() const { return control_; }
  int last_newton_iterations() const { return last_newton_; }
  int last_projected_elements() const { return last_projected_; }  // eigen-projected in the last assembly
  double elastic_energy() const;                                     // Psi summed over the tets, mN*mm
  // Where the last (sub-)step's time went (wall ms, summed over its Newton iterations) and
  // the linear solver's iterations (PCG) in it.
  struct Timing {
    double assemble_ms = 0, solve_ms = 0, line_search_ms = 0;
    int linear_iterations = 0, factorizations = 0;
  };
  const Timing& last_timing() const { return timing_; }
  // Last assembled Newton system (lower triangle).
  const SparseMatrixLower& system_matrix() const { return A_; }

 private:
  struct Tet {
    std::array<int, 4> v;
    Eigen::Matrix3d Dm_inv;
    Eigen::Matrix<double, 9, 12> dFdx;  // vec(F) = dFdx * (x_0, x_1, x_2, x_3)
    double volume, mu, lambda, beta;
    bool passive = false;  // below the quality bound: mu = lambda = beta = 0 (no elastic term), not counted inverted
  };
  Tet make_element(const SimProblem& problem, int mesh_tet, double& quarter_mass, double& quarter_alpha) const;
  void build_pattern();
  // Elastic forces into f_el_ and the projected stiffness (times scale_k) plus the
  // Rayleigh-beta matrix (when `damping_matrix`) into the value arrays; returns Psi.
  double assemble_elastic(const Eigen::Matrix3Xd& x, bool damping_matrix);
  double elastic_energy_of(const Eigen::Matrix3Xd& x) const;
  double attachment_energy(const Eigen::Matrix3Xd& x) const;
  StepSummary substep(double dt_s);

  std::string integrator_;
  FemOptions options_;
  int threads_ = 1;
  int substeps_ = 1;
  int newton_iterations_ = 10;
  double tolerance_ = 1e-6;
  Eigen::Vector3d gravity_;
  Eigen::Matrix3Xd X_, x_, v_;
  Eigen::VectorXd mass_, mass_alpha_;
  std::vector<Tet> tets_;                             // in mesh order
  std::vector<double> quarter_mass_, quarter_alpha_;  // per tet: its share of each vertex's m and alpha m
  fem::TetPairCounts pair_tets_;                      // tets per vertex pair (made at the first apply_mesh_change)
  fem::FemAttachmentSet attachments_{"corotational_fem"};
  std::vector<char> fixed_;       // user_fixed_ or held by embedded_
  std::vector<char> user_fixed_;  // the problem's / set_fixed_vertices
  EmbeddedMotion embedded_;       // driven vertices and rigid groups (embedded_elements.hpp)
  void merge_fixed_with_embedding();
  std::unique_ptr<SymmetricPattern> pattern_;
  std::vector<int> tet_map_;  // 90 entries per tet (full block maps)
  ElementPartition partition_;
  SparseMatrixLower A_, K_, D_;  // system, elastic stiffness, Rayleigh-beta stiffness at x_n
  Eigen::VectorXd f_el_, sol_;
  FemLinearSolver solver_;
  InversionMonitor inversions_;
  Timing timing_;
  int last_newton_ = 0;
  int last_projected_ = 0;
  double last_dt_ = -1.0;
  std::string note_;
  SubstepControl control_;
  Eigen::Matrix3Xd x_saved_, v_saved_;  // the state an unhealthy step is redone from
  InversionMonitor inversions_saved_;
};

}  // namespace arnav::host
