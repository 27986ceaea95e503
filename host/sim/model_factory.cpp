#include "host/sim/model_factory.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#ifdef ARNAV_SIM_HAVE_MASS_SPRING
#include "host/sim/mass_spring/mass_spring_model.hpp"
#endif
#ifdef ARNAV_SIM_HAVE_XPBD
#include "host/sim/xpbd/xpbd_model.hpp"
#endif
#ifdef ARNAV_SIM_HAVE_FEM
#include "host/sim/fem/corotational_fem.hpp"
#endif
// Further models add their include, their variants and their branch in make_tissue_model
// below, guarded by their ARNAV_SIM_HAVE_* definition.

namespace arnav::host {

namespace {
void check_common(const ModelConfig& config) {
  if (config.iterations < 1) throw std::invalid_argument("model config: iterations must be >= 1");
  if (config.substeps < 1) throw std::invalid_argument("model config: substeps must be >= 1");
  if (config.threads < 1) throw std::invalid_argument("model config: threads must be >= 1");
}
std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& s : items) out += (out.empty() ? "" : ", ") + s;
  return out;
}
}  // namespace

std::vector<std::string> available_model_kinds() {
  std::vector<std::string> kinds;
#ifdef ARNAV_SIM_HAVE_MASS_SPRING
  kinds.push_back("mass_spring");
#endif
#ifdef ARNAV_SIM_HAVE_XPBD
  kinds.push_back("xpbd");
#endif
#ifdef ARNAV_SIM_HAVE_FEM
  kinds.push_back("corotational_fem");
#endif
  return kinds;
}

std::vector<ModelVariant> model_variants() {
  std::vector<ModelVariant> out;
#ifdef ARNAV_SIM_HAVE_MASS_SPRING
  {
    ModelConfig c;
    c.kind = "mass_spring";
    c.integrator = "explicit";
    c.substeps = 20;  // 0.83 ms substeps at 60 Hz: below the bound for soft tissue, 10-15 mm cells
    out.push_back({"mass_spring/explicit", c});
    c.integrator = "semi_implicit";
    c.substeps = 1;
    c.iterations = 20;
    c.tolerance = 1e-4;
    out.push_back({"mass_spring/semi_implicit", c});
    // Prefactored backward Euler (docs/sim.md). 10 local/global iterations (Chebyshev
    // accelerated) settle every case of the stability matrix; the 2 ms setting is 1
    // iteration (docs/benchmarks.md).
    c.integrator = "local_global";
    c.iterations = 10;
    c.tolerance = 0.0;
    out.push_back({"mass_spring/local_global", c});
  }
#endif
#ifdef ARNAV_SIM_HAVE_XPBD
  {
    ModelConfig c;
    c.kind = "xpbd";
    // Small steps (Macklin 2019): 16 substeps of one sweep each beat 4 x 4 at the same
    // cost (liver: surface error 2.9 against 8.0 mm; stability matrix: passes 10^2
    // contrast; docs/benchmarks.md).
    c.iterations = 1;
    c.substeps = 16;
    c.tolerance = 0.0;
    out.push_back({"xpbd", c});
    // Stable Neo-Hookean, small steps: one sweep per substep; its explicitly integrated
    // shear needs ~40 substeps per 1/60 s on the liver mesh (docs/sim.md).
    c.energy = "neo_hookean";
    c.iterations = 1;
    c.substeps = 40;
    out.push_back({"xpbd/neo_hookean", c});
  }
#endif
#ifdef ARNAV_SIM_HAVE_FEM
  {
    // Real-time setting (docs/sim-fem.md): PCG on the current co-rotated matrix with a
    // lagged CHOLMOD factor as preconditioner. quasi_static is not listed: it needs the
    // scene to support the body (fixed vertices or attachments) and reports unhealthy
    // without; scenes ask for it by name.
    ModelConfig c;
    c.kind = "corotational_fem";
    c.integrator = "implicit_euler";
    c.linear_solver = "pcg";
    c.iterations = 20;
    c.tolerance = 1e-4;
    c.refactor_every = 30;
    out.push_back({"corotational_fem/implicit_euler", c});
    // Stable Neo-Hookean material, projected Newton (docs/sim.md): up to 2 Newton iterations
    // per step, each solved by PCG on a CHOLMOD factor of the projected (positive definite)
    // system refreshed every 30 steps (and whenever PCG stalls).
    ModelConfig n;
    n.kind = "corotational_fem";
    n.material_model = "stable_neo_hookean";
    n.integrator = "implicit_euler";
    n.linear_solver = "pcg";
    n.refactor_every = 30;
    n.iterations = 2;
    n.tolerance = 1e-3;
    out.push_back({"corotational_fem/stable_neo_hookean/implicit_euler", n});
  }
#endif
  return out;
}

ModelConfig recommended_model_config(const std::string& kind) {
  ModelConfig c;
  c.kind = kind;
  if (kind == "mass_spring") {
    c.integrator = "local_global";
    c.iterations = 10;
    c.tolerance = 0.0;
  } else if (kind == "xpbd") {
    c.iterations = 1;
    c.substeps = 16;
    c.tolerance = 0.0;
  } else if (kind == "corotational_fem") {
    c.integrator = "implicit_euler";
    c.linear_solver = "pcg";
    c.iterations = 3;
    c.tolerance = 1e-4;
    c.refactor_every = 30;
    c.refactor_in_background = true;
    c.single_precision_preconditioner = true;
    c.blas_threads = 1;
  } else {
    throw std::invalid_argument("model kind '" + kind + "' is unknown: this build offers " + join(available_model_kinds()));
  }
  const auto kinds = available_model_kinds();
  if (std::find(kinds.begin(), kinds.end(), kind) == kinds.end())
    throw std::invalid_argument("model kind '" + kind + "' is not built in: this build offers " + join(kinds));
  return c;
}

void check_setting_holds(const SimProblem& problem, const ModelConfig& config, double dt_s, const std::string& dt_source) {
  check_common(config);
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) throw std::invalid_argument("time_step_s must be finite and > 0");
  const std::string at_dt = dt_source.empty() ? "time_step_s " + std::to_string(dt_s) : dt_source;
#ifdef ARNAV_SIM_HAVE_MASS_SPRING
  if (config.kind == "mass_spring" && config.integrator == "explicit") {
    // Beyond the stability bound the model takes the substeps the bound needs, up to the step
    // control's budget (MassSpringModel::explicit_substeps); refused only when that budget
    // cannot hold it.
    const MassSpringModel probe(problem, MassSpringModel::Integrator::kExplicit, config);
    if (probe.explicit_substeps(dt_s) == 0) {
      const double h_s = dt_s / config.substeps, h_max_s = probe.explicit_stable_substep_s();
      throw std::invalid_argument(
          "model.substeps: " + std::to_string(config.substeps) + " substeps of the explicit mass-spring integrator give " +
          std::to_string(h_s) + " s per substep, beyond its stability bound " + std::to_string(h_max_s) +
          " s for the stiffest springs even at the step control's budget of " +
          std::to_string(SubstepControl::budget_substeps(config.substeps, dt_s)) +
          " substeps (every step would be refused): use model.substeps >= " +
          std::to_string(probe.explicit_substeps_needed(dt_s)) + " at " + at_dt +
          ", or model.integrator: semi_implicit or local_global");
    }
  }
#endif
  if (config.kind == "corotational_fem" && config.integrator == "quasi_static" && problem.fixed_vertices.empty()) {
    throw std::invalid_argument(
        "model.integrator: quasi_static finds the equilibrium of a supported body, and this scene fixes no vertex (its "
        "stiffness is singular under rigid motion: every step would be refused): add boundary.fixed (e.g. the "
        "ligaments' box), or use model.integrator: implicit_euler");
  }
}

std::unique_ptr<TissueModel> make_tissue_model(const SimProblem& problem, const ModelConfig& config) {
  check_common(config);
#ifdef ARNAV_SIM_HAVE_MASS_SPRING
  if (config.kind == "mass_spring") {
    if (config.integrator == "explicit") {
      return std::make_unique<MassSpringModel>(problem, MassSpringModel::Integrator::kExplicit, config);
    }
    if (config.integrator == "semi_implicit" || config.integrator.empty()) {
      return std::make_unique<MassSpringModel>(problem, MassSpringModel::Integrator::kSemiImplicit, config);
    }
    if (config.integrator == "local_global") {
      return std::make_unique<MassSpringModel>(problem, MassSpringModel::Integrator::kLocalGlobal, config);
    }
    throw std::invalid_argument("model config: mass_spring integrator '" + config.integrator +
                                "' is unknown: use explicit, semi_implicit or local_global");
  }
#endif
#ifdef ARNAV_SIM_HAVE_XPBD
  if (config.kind == "xpbd") {
    if (!config.integrator.empty() && config.integrator != "xpbd") {
      throw std::invalid_argument("model config: xpbd has no integrator '" + config.integrator + "' (leave it empty)");
    }
    return std::make_unique<XpbdModel>(problem, config);
  }
#endif
#ifdef ARNAV_SIM_HAVE_FEM
  if (config.kind == "corotational_fem") return make_corotational_fem(problem, config);
#endif
  throw std::invalid_argument("model config: unknown tissue model kind '" + config.kind +
                              "': this build offers " + join(available_model_kinds()));
}

}  // namespace arnav::host
