#pragma once
// Builds the tissue model a scene asks for (ModelConfig::kind) behind the one interface.
// Only what the problem declares is built: attachments are allocated when added, beam
// machinery only with vessels (in the models that support them).
#include <memory>
#include <string>
#include <vector>

#include "host/sim/model_config.hpp"
#include "host/sim/tissue_model.hpp"

namespace arnav::host {

// Throws std::invalid_argument naming the bad field (unknown kind or integrator,
// non-positive iterations/substeps/threads) or the bad mesh element.
std::unique_ptr<TissueModel> make_tissue_model(const SimProblem& problem, const ModelConfig& config);

// Refuses at load a setting the model cannot hold at the time step dt_s (issue 29; docs/sim.md
// "Step control"): throws std::invalid_argument naming the key, the reason and the setting
// that would work. What the step control holds at run time (up to 8x the substeps) is not
// refused. Refused today: the explicit mass-spring integrator with a substep beyond its
// stability bound for the stiffest springs (every step would be refused), and the
// quasi-static FEM (both materials) on a problem with no fixed vertex (its stiffness is
// singular: every step would be refused). `dt_source` says where dt_s comes from in the
// message ("time_step_s 0.016667" when empty; arnav-host: its model.rate_hz). Cost: one model
// build for the explicit mass-spring, nothing for the others.
void check_setting_holds(const SimProblem& problem, const ModelConfig& config, double dt_s, const std::string& dt_source = "");

// One buildable model with its defaults: every kind and integrator compiled in. The
// stability matrix and benchmarks iterate over this list, so a new model joins them by
// being added here.
struct ModelVariant {
  std::string label;   // "<kind>/<integrator>" or "<kind>"
  ModelConfig config;  // kind and integrator set; solver defaults for real-time use
};
std::vector<ModelVariant> model_variants();

// The recommended real-time configuration of one model kind (docs/sim.md, "Choosing a
// model"): what a scene gets when it names only the kind, and what `arnav-sim --model KIND`
// starts from. mass_spring: local_global, 10 iterations; xpbd: 16 substeps x 1 sweep;
// corotational_fem: implicit Euler, PCG 3 on a background-refactorised (every 30 steps)
// single-precision CHOLMOD factor, the 60 Hz setting of docs/benchmarks.md.
// Throws std::invalid_argument for a kind this build does not offer (naming those it does).
ModelConfig recommended_model_config(const std::string& kind);

// Kinds compiled into this build, e.g. {"mass_spring", "xpbd"}.
std::vector<std::string> available_model_kinds();

}  // namespace arnav::host
