#pragma once
// Summary returned next to every calibration result (conventions.md: after Ceres'
// Summary): what ran, how long, how well it fits and why it stopped.
#include <string>

namespace arnav::calib {

struct SolverSummary {
  std::string method;          // e.g. "pivot: algebraic least squares"
  int iterations = 0;          // 0 for closed-form solvers
  double initial_cost = 0.0;   // RMS residual before refinement (same unit as final)
  double final_cost = 0.0;     // RMS residual of the returned result
  std::string termination;     // "closed form", "converged: step < 1e-9 mm", ...
  double wall_time_s = 0.0;
};

}  // namespace arnav::calib
