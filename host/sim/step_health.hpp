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
// plus the external work since (attachment targets moved, springs added) plus the work of
// gravity. Energy created by the solver (instability, or an unconverged iteration whose
// state stores more energy than was put in) is reported as unhealthy. Units mN*mm.
class EnergyLedger {
 public:
  // ke_ee: kinetic + elastic (incl. attachment springs); u_g: gravity potential.
  void reset(double ke_ee, double u_g);
  void add_work(double work);
  // Reports "energy balance violated" when the created energy exceeds the energy
  // budget (stored at reset + |work| + |gravity work|) plus a floor.
  void check(double ke_ee, double u_g, StepSummary& summary) const;

 private:
  double e0_ = 0.0, u0_ = 0.0, work_ = 0.0, abs_work_ = 0.0;
};

// Gravity potential -sum m_i g.x_i (mN*mm), for the ledger.
double gravity_potential(const Eigen::VectorXd& mass_kg, const Eigen::Matrix3Xd& x_World_mm, const Eigen::Vector3d& g);

// Throws std::invalid_argument unless every index is a vertex of the mesh.
void check_vertex_indices(const std::vector<int>& vertices, int num_vertices, const char* what);

// Throws std::invalid_argument unless both matrices are 3 x num_vertices and finite.
void check_state_shape(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, int num_vertices);

// Throws std::invalid_argument unless dt_s is finite and > 0.
void check_dt(double dt_s);

}  // namespace arnav::host
