#include "host/sim/step_health.hpp"

#include <cmath>
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
