#pragma once
// The stress matrix of issue 29 (docs/benchmarks.md, "Stress matrix"): every model variant
// on a patient liver under one stress at a time from the scene's own setting - Poisson ratio
// 0.3/0.45/0.49/0.499, stiffness contrast of the scene's stiff regions (tumour) 1-1000x the
// liver, frame time step 1/120-1/20 s, load 1-10 g, a sudden 50 mm pull - plus all extremes at
// once and all extremes but one. Each case is refused at load (check_setting_holds; the
// setting the refusal names is then run too) or run: held (healthy every frame) or stopped
// (an unhealthy frame: what issue 29 forbids). Frame time (wall and process CPU, ms) of the
// runs against the 16.7 ms budget; frames where the step control acted. With
// reference_factor > 0, the adapted runs (and each model's baseline) are compared frame by
// frame with a reference: the same case at reference_factor times the largest substep count
// the run used, its convergence shown by the same at half that count (error against run time).
#include <nlohmann/json.hpp>

#include <ostream>
#include <string>
#include <vector>

#include "host/scene/scene.hpp"

namespace arnav::host {

struct StressCase {
  std::string name;
  double poisson_ratio = -1.0;  // < 0: the scene's
  double contrast = -1.0;       // stiff regions' E / the liver's E; < 0: the scene's
  double dt_s = 1.0 / 60.0;
  double load_g = 1.0;          // gravity scaled
  double pull_mm = 0.0;         // sudden pull of the lowest surface patch (0: none)
};

// The cases, the baseline (the scene's setting) first. Names: baseline, nu_0.3, ...,
// contrast_1, ..., dt_1/120, ..., load_3g, load_10g, pull_50mm, all_extremes, all_but_nu,
// all_but_contrast, all_but_dt, all_but_load, all_but_pull.
std::vector<StressCase> stress_cases();

struct StressMatrixOptions {
  int frames = 60;                   // frames per case (each of the case's dt_s)
  std::vector<std::string> models;   // variant labels (empty: every model_variants())
  std::vector<std::string> cases;    // case names (empty: every stress_cases())
  double pull_stiffness_mN_per_mm = 200.0;  // the pulled patch in all (the patient suite's grasp)
  int reference_factor = 0;          // > 0: reference runs (above) at this factor; 0: none
  int substeps = 0;                  // > 0: every variant at this many configured substeps
};

// Runs the matrix on `scene` (its problem, materials and fixed set); one CSV row per case to
// `csv` (header first) and progress to `log`; returns the JSON summary. Throws
// std::invalid_argument for an unknown model or case name.
nlohmann::json run_stress_matrix(const Scene& scene, const StressMatrixOptions& options, std::ostream& csv, std::ostream& log);

}  // namespace arnav::host
