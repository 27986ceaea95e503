#pragma once
// Checks and set-up every tissue model does the same way when it is built, so that the
// same bad input gets the same message whichever model the scene chose.
#include <Eigen/Core>

#include <string_view>

#include "host/sim/model_config.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// substeps, iterations and threads >= 1, tolerance >= 0; throws std::invalid_argument
// naming the model ("xpbd: substeps must be >= 1").
void check_iterative_config(const ModelConfig& config, std::string_view model);

// Lumped vertex masses (kg) of a non-empty mesh; throws std::invalid_argument naming the
// model and the vertex when a vertex belongs to no tet (zero mass), or the tet when a
// rest volume is not positive.
Eigen::VectorXd checked_masses_kg(const SimProblem& problem, std::string_view model);

}  // namespace arnav::host
