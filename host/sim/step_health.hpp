#pragma once
// Run-time health checks shared by the tissue models: a model must say when it leaves its
// stable range (NaN/Inf, velocity blow-up, inverted elements, time step too large)
// instead of exploding silently. Units: mm, s, kg.
#include <Eigen/Core>

#include <string>
#include <vector>

#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// A vertex faster than this is a numerical blow-up, not tissue motion (100 m/s).
inline constexpr double kBlowUpSpeed_mm_s = 1.0e5;

// Appends `text` to summary.warning ("; "-separated) and, if `unhealthy`, clears healthy.
void report(StepSummary& summary, const std::string& text, bool unhealthy);

// Checks positions and velocities for NaN/Inf and speed beyond kBlowUpSpeed_mm_s.
void check_state(const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s, StepSummary& summary);

// 0.5 * sum m_i |v_i|^2 in mN*mm.
double kinetic_energy(const Eigen::VectorXd& mass_kg, const Eigen::Matrix3Xd& v_World_mm_s);

// Energy balance: kinetic + stored energy may not exceed what was there at the last reset
// plus the work of every external agent since: attachment springs (grasps, the blade's push,
// registration pulls: targets moved, springs added, stiffened or removed), the cut (the
// energy a topology change adds or takes: vertices moved onto the cut, split elements, the
// mass moved between vertices; TissueModel::apply_mesh_change) and gravity. Fixed vertices
// hold still and do no work. Energy created by the solver (instability, or an unconverged
// iteration whose state stores more energy than was put in) beyond the tolerance is
// reported as unhealthy. Units mN*mm.
// Tolerance (docs/sim.md "Run-time health"): kLedgerRelativeTolerance of the budget, and at
// least the floor: the strain energy of a uniform strain of kLedgerFloorStrain over the whole
// body in its softest material (energy_floor_mN_mm), so that an unloaded scene (a free organ, no gravity: budget 0)
// does not stop on round-off or on the few micro-joules an XPBD sweep's energy estimate
// differs from the exact one, while a diverging step (energy growing by orders of magnitude
// per step) still crosses it within a step or two.
inline constexpr double kLedgerRelativeTolerance = 1e-3;
inline constexpr double kLedgerFloorStrain = 1e-3;

// 0.5 * E_softest * V_body * kLedgerFloorStrain^2 (mN*mm): the ledger's floor for a body.
double energy_floor_mN_mm(const SimProblem& problem);

class EnergyLedger {
 public:
  // The smallest energy the check resolves (energy_floor_mN_mm of the model's problem);
  // 1e-6 mN*mm until set.
  void set_floor(double floor_mN_mm) { floor_ = floor_mN_mm; }
  // ke_ee: kinetic + elastic (incl. attachment springs); u_g: gravity potential.
  void reset(double ke_ee, double u_g);
  void add_work(double work);
  // Reports "energy balance violated" when the created energy exceeds the energy
  // budget (stored at reset + |work| + |gravity work|) plus the tolerance.
  void check(double ke_ee, double u_g, StepSummary& summary) const;

 private:
  double e0_ = 0.0, u0_ = 0.0, work_ = 0.0, abs_work_ = 0.0, floor_ = 1e-6;
};

// The health rule for inverted elements (docs/sim.md, "Run-time health"): a few elements
// inverted under an extreme load are a counted warning and the model keeps running and
// recovering; only a collapse - more than kCollapseFraction of the elements inverted for
// longer than kCollapseTime_s of simulated time - is unhealthy. The monitor also keeps the
// statistics the benchmarks and the patient-mesh suite report.
inline constexpr double kCollapseFraction = 0.10;
inline constexpr double kCollapseTime_s = 1.0;

class InversionMonitor {
 public:
  // Once per step with the inverted elements at its end; sets summary.inverted_elements and
  // reports the warning (and a collapse as unhealthy). `what` names the elements ("tets").
  void update(int inverted, int total_elements, double dt_s, StepSummary& summary, const char* what = "tets");
  // Forget the current episode (set_state: the state now comes from outside).
  void reset_episode() { episode_s_ = 0.0; collapse_s_ = 0.0; }

  double episode_s() const { return episode_s_; }            // current run of steps with inversions
  double worst_episode_s() const { return worst_episode_s_; }  // longest such run so far
  long long steps_with_inversions() const { return steps_with_; }
  int peak_inverted() const { return peak_; }

 private:
  double episode_s_ = 0.0, worst_episode_s_ = 0.0, collapse_s_ = 0.0;
  long long steps_with_ = 0;
  int peak_ = 0;
};

// Gravity potential -sum m_i g.x_i (mN*mm), for the ledger.
double gravity_potential(const Eigen::VectorXd& mass_kg, const Eigen::Matrix3Xd& x_World_mm, const Eigen::Vector3d& g);

// Throws std::invalid_argument unless every index is a vertex of the mesh.
void check_vertex_indices(const std::vector<int>& vertices, int num_vertices, const char* what);

// Throws std::invalid_argument unless both matrices are 3 x num_vertices and finite.
void check_state_shape(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, int num_vertices);

// Throws std::invalid_argument unless dt_s is finite and > 0.
void check_dt(double dt_s);

// One step of dt_s as `substeps` equal substeps through substep(h) -> StepSummary, folded
// into one summary: iterations and wall time summed, the first substep's initial residual,
// the last one's residual, termination, energies and inverted elements, warnings prefixed
// "substep k: "; stops at the first unhealthy substep. One substep: its summary as is.
template <typename Substep>
StepSummary run_substeps(int substeps, double dt_s, Substep&& substep) {
  if (substeps <= 1) return substep(dt_s);
  StepSummary total;
  for (int k = 0; k < substeps; ++k) {
    const StepSummary s = substep(dt_s / substeps);
    total.iterations += s.iterations;
    if (k == 0) total.initial_residual = s.initial_residual;
    total.final_residual = s.final_residual;
    total.termination = s.termination;
    total.wall_time_ms += s.wall_time_ms;
    total.kinetic_energy = s.kinetic_energy;
    total.elastic_energy = s.elastic_energy;
    total.inverted_elements = s.inverted_elements;
    if (!s.warning.empty()) report(total, "substep " + std::to_string(k) + ": " + s.warning, !s.healthy);
    if (!s.healthy) break;
  }
  return total;
}

}  // namespace arnav::host
