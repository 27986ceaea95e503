#include "host/sim/step_health.hpp"

#include "host/sim/tet_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace arnav::host {

void report(StepSummary& summary, const std::string& text, bool unhealthy) {
  if (!summary.warning.empty()) summary.warning += "; ";
  summary.warning += text;
  if (unhealthy) summary.healthy = false;
}

void check_state(const Eigen::Matrix3Xd& x_World_mm, const Eigen::Matrix3Xd& v_World_mm_s, StepSummary& summary) {
  if (!x_World_mm.allFinite() || !v_World_mm_s.allFinite()) {
    report(summary, "non-finite positions or velocities (NaN/Inf)", true);
    return;
  }
  const double vmax = v_World_mm_s.size() ? v_World_mm_s.colwise().norm().maxCoeff() : 0.0;
  if (vmax > kBlowUpSpeed_mm_s) {
    report(summary, "velocity blow-up: " + std::to_string(vmax) + " mm/s", true);
  }
}

double kinetic_energy(const Eigen::VectorXd& mass_kg, const Eigen::Matrix3Xd& v_World_mm_s) {
  return 0.5 * (v_World_mm_s.colwise().squaredNorm().transpose().array() * mass_kg.array()).sum();
}

void EnergyLedger::reset(double ke_ee, double u_g) {
  e0_ = ke_ee;
  u0_ = u_g;
  work_ = 0.0;
  abs_work_ = 0.0;
}

void EnergyLedger::add_work(double work) {
  work_ += work;
  abs_work_ += std::abs(work);
}

void EnergyLedger::check(double ke_ee, double u_g, StepSummary& summary) const {
  if (!std::isfinite(ke_ee) || !std::isfinite(u_g)) return;  // reported by check_state
  const double created = (ke_ee + u_g) - (e0_ + u0_ + work_);
  const double budget = e0_ + abs_work_ + std::abs(u_g - u0_);
  const double tolerance = std::max(floor_, kLedgerRelativeTolerance * budget);
  summary.energy_created_mN_mm = created;
  summary.energy_allowance_mN_mm = budget + tolerance;
  if (created > budget + tolerance) {
    report(summary,
           "energy balance violated: " + std::to_string(created) + " mN*mm created against a budget of " +
               std::to_string(budget) + " mN*mm (+ tolerance " + std::to_string(tolerance) +
               " mN*mm; solver unconverged in stiff regions, or unstable)",
           true);
  }
}

double energy_floor_mN_mm(const SimProblem& problem) {
  // The softest material over the whole volume: a stiff inclusion must not widen the
  // tolerance of the soft tissue round it (where an unconverged solve shows first).
  const TetMesh& mesh = problem.mesh;
  double volume = 0.0, softest = std::numeric_limits<double>::infinity();
  for (std::size_t t = 0; t < mesh.tets.size(); ++t) {
    const std::size_t region = t < mesh.tet_region.size() ? static_cast<std::size_t>(mesh.tet_region[t]) : 0;
    if (region < problem.region_materials.size()) softest = std::min(softest, problem.region_materials[region].youngs_modulus_kPa);
    volume += std::abs(signed_volume_mm3(mesh.rest_positions_World_mm, mesh.tets[t]));
  }
  if (!std::isfinite(softest)) return 1e-6;
  return std::max(1e-6, 0.5 * softest * volume * kLedgerFloorStrain * kLedgerFloorStrain);
}

namespace {
std::string seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f s", s);
  return buf;
}
}  // namespace

void InversionMonitor::update(int inverted, int total_elements, double dt_s, StepSummary& summary, const char* what) {
  summary.inverted_elements = inverted;
  if (inverted <= 0) {
    if (episode_s_ > 0.0)
      report(summary, std::string("inverted ") + what + ": recovered after " + seconds(episode_s_), false);
    episode_s_ = 0.0;
    collapse_s_ = 0.0;
    return;
  }
  episode_s_ += dt_s;
  worst_episode_s_ = std::max(worst_episode_s_, episode_s_);
  ++steps_with_;
  peak_ = std::max(peak_, inverted);
  const bool collapsing = total_elements > 0 && inverted > kCollapseFraction * total_elements;
  collapse_s_ = collapsing ? collapse_s_ + dt_s : 0.0;
  std::string text = std::string("inverted ") + what + ": " + std::to_string(inverted) + " of " + std::to_string(total_elements) +
                     " for " + seconds(episode_s_);
  if (collapse_s_ > kCollapseTime_s) {
    report(summary,
           text + ": mesh collapse (more than " + std::to_string(static_cast<int>(100 * kCollapseFraction)) + " % inverted for more than " +
               seconds(kCollapseTime_s) + ")",
           true);
  } else {
    report(summary, text + " (counted; the model keeps recovering)", false);
  }
}

double gravity_potential(const Eigen::VectorXd& mass_kg, const Eigen::Matrix3Xd& x_World_mm, const Eigen::Vector3d& g) {
  return -(mass_kg.transpose() * (g.transpose() * x_World_mm).transpose())(0);
}

void check_vertex_indices(const std::vector<int>& vertices, int num_vertices, const char* what) {
  for (int v : vertices) {
    if (v < 0 || v >= num_vertices) {
      throw std::invalid_argument(std::string(what) + ": vertex " + std::to_string(v) + " is outside the mesh (0.." +
                                  std::to_string(num_vertices - 1) + ")");
    }
  }
}

void check_state_shape(const Eigen::Matrix3Xd& x, const Eigen::Matrix3Xd& v, int num_vertices) {
  if (x.cols() != num_vertices || v.cols() != num_vertices) {
    throw std::invalid_argument("set_state: expected 3 x " + std::to_string(num_vertices) + " positions and velocities (got " +
                                std::to_string(x.cols()) + " and " + std::to_string(v.cols()) + " columns)");
  }
  if (!x.allFinite() || !v.allFinite()) throw std::invalid_argument("set_state: positions or velocities are not finite");
}

void check_dt(double dt_s) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) {
    throw std::invalid_argument("step: dt must be finite and > 0 s (got " + std::to_string(dt_s) + ")");
  }
}

}  // namespace arnav::host
