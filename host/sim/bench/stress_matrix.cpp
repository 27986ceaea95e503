#include "host/sim/bench/stress_matrix.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <limits>
#include <stdexcept>

#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

constexpr double kBudget_ms = 1000.0 / 60.0;  // one display frame

// Process CPU time (all threads), ms: what a frame costs when it gets a core (the machine is shared).
double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5))];
}

std::string csv_text(std::string s) {
  std::replace(s.begin(), s.end(), ',', ';');
  std::replace(s.begin(), s.end(), '\n', ' ');
  return s.substr(0, 300);
}

// The problem of one case: the scene's with the case's Poisson ratio, contrast and load.
// The liver's own region ("default"; the first when none is named so).
std::size_t liver_region(const SimProblem& p) {
  const auto& names = p.mesh.region_names;
  const auto base = std::find(names.begin(), names.end(), "default");
  return base == names.end() ? 0 : static_cast<std::size_t>(base - names.begin());
}

SimProblem case_problem(const Scene& scene, const StressCase& c) {
  SimProblem p = scene.problem;
  const std::size_t liver = liver_region(p);
  for (std::size_t r = 0; r < p.region_materials.size(); ++r) {
    if (c.poisson_ratio >= 0.0) p.region_materials[r].poisson_ratio = c.poisson_ratio;
    if (c.contrast > 0.0 && r != liver)
      p.region_materials[r].youngs_modulus_kPa = c.contrast * p.region_materials[liver].youngs_modulus_kPa;
  }
  p.gravity_World_mm_s2 *= c.load_g;
  return p;
}

// Which factor of the configured substeps a frame ended at, from the step control's warning
// (step_control.hpp: "step redone with Nx the substeps" / "Nx the substeps (...)"); 1 if none.
int control_factor(const std::string& warning) {
  const std::size_t at = warning.find("step control: ");
  if (at == std::string::npos) return 1;
  std::size_t k = at + 14;
  const std::string redone = "step redone with ";
  if (warning.compare(k, redone.size(), redone) == 0) k += redone.size();
  int f = 0;
  while (k < warning.size() && warning[k] >= '0' && warning[k] <= '9') f = 10 * f + (warning[k++] - '0');
  return f > 0 ? f : 1;
}

struct CaseResult {
  std::string outcome;  // held | refused_at_load | stopped
  std::string note;     // refusal or the stopping frame's warning
  std::string named_outcome;  // refused: the outcome of the setting the refusal names (model.substeps >= N)
  int frames_run = 0, control_frames = 0, redone_frames = 0, max_factor = 1, fallback_frames = 0;
  std::vector<double> wall_ms, cpu_ms;
  double max_displacement_mm = 0.0;
  double build_ms = 0.0;
  int max_substeps = 0;                        // the most substeps a frame took (configured x factor)
  double peak_ledger_use = 0.0;                // the most of the energy ledger's allowance used (> 1: stopped)
  std::vector<Eigen::Matrix3Xd> trajectory;    // volume vertices after each frame (when recorded)
};

CaseResult run_case(const Scene& scene, const ModelConfig& config, const StressCase& c, const StressMatrixOptions& o,
                    bool try_named = true, bool record = false) {
  CaseResult r;
  const SimProblem problem = case_problem(scene, c);
  try {
    check_setting_holds(problem, config, c.dt_s);
  } catch (const std::invalid_argument& e) {
    r.outcome = "refused_at_load";
    r.note = e.what();
    // Does the setting the refusal names hold? (Runs it: "no case refused that the model can hold".)
    const std::string key = "model.substeps >= ";
    if (const std::size_t at = r.note.find(key); try_named && at != std::string::npos) {
      ModelConfig named = config;
      named.substeps = std::stoi(r.note.substr(at + key.size()));
      const CaseResult n = run_case(scene, named, c, o, false);
      r.named_outcome = n.outcome + " at model.substeps " + std::to_string(named.substeps) + ", median " +
                        std::to_string(percentile(n.wall_ms, 0.5)) + " ms";
    }
    return r;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<TissueModel> model = make_tissue_model(problem, config);
  std::vector<AttachmentId> ids;
  std::vector<Eigen::Vector3d> targets;
  if (c.pull_mm > 0.0) {
    // The lowest surface patch (the hanging tip), pulled c.pull_mm down at once in frame 1.
    const std::vector<int> patch = lowest_surface_patch(scene, 10.0);
    for (int i : patch) {
      const Eigen::Vector3d at = scene.organ_surface.positions_World_mm.col(i);
      ids.push_back(model->add_attachment({scene.organ_embedding.material_point(problem.mesh, i), at,
                                           o.pull_stiffness_mN_per_mm / static_cast<double>(patch.size())}));
      targets.push_back(at - Eigen::Vector3d(0, 0, c.pull_mm));
    }
  }
  r.build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  const Eigen::Matrix3Xd& rest = problem.mesh.rest_positions_World_mm;
  r.outcome = "held";
  for (int f = 1; f <= o.frames; ++f) {
    for (std::size_t j = 0; j < ids.size(); ++j) model->set_attachment_target(ids[j], targets[j]);
    const double cpu0 = process_cpu_ms();
    const StepSummary s = model->step(c.dt_s);
    r.cpu_ms.push_back(process_cpu_ms() - cpu0);
    r.wall_ms.push_back(s.wall_time_ms);
    r.frames_run = f;
    const int factor = control_factor(s.warning);
    r.max_factor = std::max(r.max_factor, factor);
    r.max_substeps = std::max(r.max_substeps, config.substeps * factor);
    if (s.warning.find("step control") != std::string::npos) ++r.control_frames;
    if (s.warning.find("step redone") != std::string::npos) ++r.redone_frames;
    if (s.warning.find("fallback") != std::string::npos) ++r.fallback_frames;
    if (s.energy_allowance_mN_mm > 0.0) r.peak_ledger_use = std::max(r.peak_ledger_use, s.energy_created_mN_mm / s.energy_allowance_mN_mm);
    const Eigen::Matrix3Xd& x = model->positions_World_mm();
    if (!s.healthy || !x.allFinite()) {
      r.outcome = "stopped";
      r.note = "frame " + std::to_string(f) + ": " + (s.warning.empty() ? std::string("non-finite state") : s.warning);
      break;
    }
    r.max_displacement_mm = std::max(r.max_displacement_mm, (x - rest).colwise().norm().maxCoeff());
    if (record) r.trajectory.push_back(x);
  }
  return r;
}

// A run against a reference, frame by frame: the largest over frames of the RMS and of the
// maximum vertex distance (mm); infinity when either did not run every frame.
struct TrajectoryDistance {
  double rms_mm = 0.0, max_mm = 0.0;
};
TrajectoryDistance distance(const std::vector<Eigen::Matrix3Xd>& a, const std::vector<Eigen::Matrix3Xd>& b, int frames) {
  const double inf = std::numeric_limits<double>::infinity();
  if (static_cast<int>(a.size()) != frames || static_cast<int>(b.size()) != frames) return {inf, inf};
  TrajectoryDistance d;
  for (int f = 0; f < frames; ++f) {
    const Eigen::VectorXd e = (a[f] - b[f]).colwise().norm();
    d.rms_mm = std::max(d.rms_mm, std::sqrt(e.squaredNorm() / static_cast<double>(e.size())));
    d.max_mm = std::max(d.max_mm, e.maxCoeff());
  }
  return d;
}

// The error of a held run against its converged reference (StressMatrixOptions::reference_factor).
struct ReferenceError {
  int substeps = 0;            // the reference's configured substeps
  std::string outcome;         // the reference run's (held, or why not)
  TrajectoryDistance error;    // the run against the reference
  TrajectoryDistance change;   // the reference against the same at half its substeps (its own error, about)
  double displacement_rms_mm = 0.0;  // the reference's largest RMS displacement from rest (scale)
};

ReferenceError reference_error(const Scene& scene, const ModelConfig& config, const StressCase& c,
                               const StressMatrixOptions& o, const CaseResult& run) {
  ReferenceError r;
  ModelConfig fine = config, half = config;
  fine.substeps = o.reference_factor * std::max(run.max_substeps, config.substeps);
  half.substeps = std::max(1, fine.substeps / 2);
  r.substeps = fine.substeps;
  const CaseResult ref = run_case(scene, fine, c, o, false, true);
  const CaseResult ref_half = run_case(scene, half, c, o, false, true);
  r.outcome = ref.outcome + (ref.note.empty() ? "" : ": " + ref.note.substr(0, 120));
  r.error = distance(run.trajectory, ref.trajectory, o.frames);
  r.change = distance(ref_half.trajectory, ref.trajectory, o.frames);
  const Eigen::Matrix3Xd& rest = scene.problem.mesh.rest_positions_World_mm;
  for (const Eigen::Matrix3Xd& x : ref.trajectory)
    r.displacement_rms_mm = std::max(r.displacement_rms_mm, std::sqrt((x - rest).colwise().squaredNorm().mean()));
  return r;
}

}  // namespace

std::vector<StressCase> stress_cases() {
  std::vector<StressCase> out{{.name = "baseline"}};
  for (double nu : {0.3, 0.45, 0.49, 0.499}) {
    char n[32];
    std::snprintf(n, sizeof n, "nu_%g", nu);
    out.push_back({.name = n, .poisson_ratio = nu});
  }
  for (double k : {1.0, 10.0, 100.0, 1000.0}) {
    char n[32];
    std::snprintf(n, sizeof n, "contrast_%g", k);
    out.push_back({.name = n, .contrast = k});
  }
  for (int hz : {120, 60, 30, 20}) out.push_back({.name = "dt_1/" + std::to_string(hz), .dt_s = 1.0 / hz});
  for (double g : {3.0, 10.0}) {
    char n[32];
    std::snprintf(n, sizeof n, "load_%gg", g);
    out.push_back({.name = n, .load_g = g});
  }
  out.push_back({.name = "pull_50mm", .pull_mm = 50.0});
  const StressCase all{.name = "all_extremes", .poisson_ratio = 0.499, .contrast = 1000.0, .dt_s = 1.0 / 20, .load_g = 10.0, .pull_mm = 50.0};
  out.push_back(all);
  // All extremes but one (which combination a model cannot hold).
  StressCase c = all;
  c.name = "all_but_nu", c.poisson_ratio = -1.0;
  out.push_back(c);
  c = all, c.name = "all_but_contrast", c.contrast = -1.0;
  out.push_back(c);
  c = all, c.name = "all_but_dt", c.dt_s = 1.0 / 60;
  out.push_back(c);
  c = all, c.name = "all_but_load", c.load_g = 1.0;
  out.push_back(c);
  c = all, c.name = "all_but_pull", c.pull_mm = 0.0;
  out.push_back(c);
  return out;
}

nlohmann::json run_stress_matrix(const Scene& scene, const StressMatrixOptions& o, std::ostream& csv, std::ostream& log) {
  std::vector<ModelVariant> variants;
  for (const ModelVariant& v : model_variants())
    if (o.models.empty() || std::find(o.models.begin(), o.models.end(), v.label) != o.models.end()) variants.push_back(v);
  if (variants.size() != (o.models.empty() ? model_variants().size() : o.models.size()))
    throw std::invalid_argument("--model: an unknown variant label (see model_variants(): arnav-sim-bench --help)");
  std::vector<StressCase> cases;
  for (const StressCase& c : stress_cases())
    if (o.cases.empty() || std::find(o.cases.begin(), o.cases.end(), c.name) != o.cases.end()) cases.push_back(c);
  if (cases.size() != (o.cases.empty() ? stress_cases().size() : o.cases.size()))
    throw std::invalid_argument("--stress-case: an unknown case name (baseline, nu_0.3, contrast_1000, dt_1/20, load_10g, pull_50mm, ...)");

  csv << "model,case,poisson_ratio,contrast,dt_s,load_g,pull_mm,outcome,frames_run,step_control_frames,redone_frames,"
         "max_factor,fallback_frames,median_ms,p95_ms,max_ms,median_cpu_ms,within_16.7ms,build_ms,max_displacement_mm,peak_ledger_use,named_setting,"
         "ref_substeps,ref_outcome,err_rms_mm,err_max_mm,ref_change_rms_mm,ref_change_max_mm,ref_displacement_rms_mm,note\n";
  nlohmann::json summary;
  summary["scene"] = scene.source;
  summary["mesh"] = {{"tets", scene.problem.mesh.num_tets()},
                     {"vertices", scene.problem.mesh.num_vertices()},
                     {"quality", describe(scene.mesh_quality)}};
  summary["frames_per_case"] = o.frames;
  summary["budget_ms"] = kBudget_ms;
  int held = 0, refused = 0, refused_named_held = 0, stopped = 0, adapted = 0, adapted_within = 0, held_within = 0;
  std::vector<double> adapted_medians;
  nlohmann::json stops = nlohmann::json::array(), per_model = nlohmann::json::object(), references = nlohmann::json::array();
  for (const ModelVariant& v : variants) {
    nlohmann::json m = {{"held", 0}, {"refused_at_load", 0}, {"stopped", 0}, {"adapted", 0}};
    ModelConfig config = v.config;
    if (o.substeps > 0) config.substeps = o.substeps;
    for (const StressCase& c : cases) {
      const CaseResult r = run_case(scene, config, c, o, true, o.reference_factor > 0);
      const double median = percentile(r.wall_ms, 0.5);
      const bool within = !r.wall_ms.empty() && median <= kBudget_ms;
      m[r.outcome] = m[r.outcome].get<int>() + 1;
      if (r.outcome == "held") {
        ++held;
        held_within += within ? 1 : 0;
        if (r.control_frames > 0) {
          ++adapted;
          adapted_within += within ? 1 : 0;
          adapted_medians.push_back(median);
          m["adapted"] = m["adapted"].get<int>() + 1;
        }
      }
      if (r.outcome == "refused_at_load") {
        ++refused;
        refused_named_held += r.named_outcome.rfind("held", 0) == 0 ? 1 : 0;
      }
      if (r.outcome == "stopped") {
        ++stopped;
        stops.push_back({{"model", v.label}, {"case", c.name}, {"note", r.note.substr(0, 300)}});
      }
      // Error against run time: the adapted runs and the baseline against their reference.
      std::string ref_columns = ",,,,,,";
      if (o.reference_factor > 0 && r.outcome == "held" && (r.control_frames > 0 || c.name == "baseline")) {
        const ReferenceError e = reference_error(scene, config, c, o, r);
        ref_columns = std::to_string(e.substeps) + ',' + csv_text(e.outcome) + ',' + std::to_string(e.error.rms_mm) + ',' +
                      std::to_string(e.error.max_mm) + ',' + std::to_string(e.change.rms_mm) + ',' +
                      std::to_string(e.change.max_mm) + ',' + std::to_string(e.displacement_rms_mm);
        references.push_back({{"model", v.label}, {"case", c.name}, {"adapted", r.control_frames > 0},
                              {"median_ms", median}, {"median_cpu_ms", percentile(r.cpu_ms, 0.5)},
                              {"max_factor", r.max_factor}, {"ref_substeps", e.substeps}, {"ref_outcome", e.outcome},
                              {"err_rms_mm", e.error.rms_mm}, {"err_max_mm", e.error.max_mm},
                              {"ref_change_rms_mm", e.change.rms_mm}, {"ref_displacement_rms_mm", e.displacement_rms_mm}});
        log << "  reference at " << e.substeps << " substeps (" << e.outcome << "): error RMS " << e.error.rms_mm
            << " mm, max " << e.error.max_mm << " mm; reference's own change at half " << e.change.rms_mm << " mm RMS"
            << std::endl;
      }
      const SimProblem p = case_problem(scene, c);
      const Material& liver = p.region_materials[liver_region(p)];
      double contrast = 1.0;
      for (const Material& mat : p.region_materials) contrast = std::max(contrast, mat.youngs_modulus_kPa / liver.youngs_modulus_kPa);
      csv << v.label << ',' << c.name << ',' << liver.poisson_ratio << ',' << contrast << ',' << c.dt_s << ','
          << c.load_g << ',' << c.pull_mm << ',' << r.outcome << ',' << r.frames_run << ',' << r.control_frames << ','
          << r.redone_frames << ',' << r.max_factor << ',' << r.fallback_frames << ',' << median << ','
          << percentile(r.wall_ms, 0.95) << ',' << percentile(r.wall_ms, 1.0) << ',' << percentile(r.cpu_ms, 0.5) << ',' << (within ? 1 : 0) << ',' << r.build_ms << ','
          << r.max_displacement_mm << ',' << r.peak_ledger_use << ',' << csv_text(r.named_outcome) << ',' << ref_columns << ',' << csv_text(r.note) << '\n'
          << std::flush;
      log << v.label << " " << c.name << ": " << r.outcome << " median " << median << " ms, step control " << r.control_frames
          << " frames (max " << r.max_factor << "x)" << (r.note.empty() ? "" : " - " + r.note.substr(0, 160))
          << (r.named_outcome.empty() ? "" : "; named setting: " + r.named_outcome) << std::endl;
    }
    per_model[v.label] = m;
  }
  summary["cases"] = static_cast<int>(variants.size() * cases.size());
  summary["held"] = held;
  summary["refused_at_load"] = refused;
  summary["refused_named_setting_held"] = refused_named_held;  // the setting the refusal names, run: held
  summary["stopped_mid_run"] = stopped;
  summary["stops"] = stops;
  summary["held_median_within_budget"] = held_within;
  summary["adapted_runs"] = adapted;  // held with the step control acting in some frame
  summary["adapted_median_within_budget"] = adapted_within;
  summary["adapted_median_of_medians_ms"] = percentile(adapted_medians, 0.5);
  summary["per_model"] = per_model;
  if (o.reference_factor > 0) {
    summary["reference_factor"] = o.reference_factor;
    summary["references"] = references;  // error against run time (adapted runs and baselines)
  }
  return summary;
}

}  // namespace arnav::host
