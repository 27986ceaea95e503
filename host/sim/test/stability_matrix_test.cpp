// Numerical stability matrix: every model the factory offers (model_variants(), so new
// models join automatically) across the stress cases of issue 3 section 4, on a small box
// "lobe" (90 x 45 x 30 mm, 216 tets) clamped at x = 0, gravity off so that rest is known.
//
// Pass: no NaN/Inf, bounded energy, return to rest after release, and no step reported
// unhealthy. A case a model cannot pass is listed in kKnownLimits below: there the model
// must have DETECTED it (some step healthy=false with a warning). In every case a
// non-finite state that a step reported as healthy (a silent NaN) fails the test.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <algorithm>
#include <map>
#include <string>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/model_factory.hpp"
#include "host/sim/mass_spring/mass_spring_model.hpp"
#include "host/sim/xpbd/xpbd_model.hpp"

namespace arnav::host {
namespace {

constexpr int kNx = 6, kNy = 3, kNz = 2;
const Eigen::Vector3d kSize_mm(90, 45, 30);
constexpr double kE_kPa = 5.0;                  // parenchyma
constexpr double kCell_mm = 15.0;
constexpr double kTissueStiffness_mN_per_mm = kE_kPa * kCell_mm;  // E h: one cell's stiffness

struct Case {
  std::string name;
  double contrast = 1.0;           // vessel E / parenchyma E
  double nu = 0.45;
  double dt_s = 1.0 / 60.0;
  std::string initial{};           // "", "inverted", "compressed_80", "rotated_180"
  double pull_mm = 10.0;           // attachment pull distance (0: none)
  double attach_factor = 1.0;      // attachment stiffness / tissue stiffness
};

std::vector<Case> cases() {
  std::vector<Case> out;
  out.push_back({.name = "baseline"});
  for (double c : {1e1, 1e2, 1e3, 1e4}) {
    Case k{.name = "contrast_1e" + std::to_string(static_cast<int>(std::lround(std::log10(c)))), .contrast = c};
    out.push_back(k);
  }
  out.push_back({.name = "nu_0_30", .nu = 0.30});
  out.push_back({.name = "nu_0_49", .nu = 0.49});
  out.push_back({.name = "nu_0_499", .nu = 0.499});
  out.push_back({.name = "dt_1ms", .dt_s = 0.001});
  out.push_back({.name = "dt_100ms", .dt_s = 0.1});
  out.push_back({.name = "inverted", .initial = "inverted", .pull_mm = 0.0});
  out.push_back({.name = "compressed_80", .initial = "compressed_80", .pull_mm = 0.0});
  out.push_back({.name = "rotated_180", .initial = "rotated_180", .pull_mm = 0.0});
  out.push_back({.name = "pull_50mm", .pull_mm = 50.0});
  out.push_back({.name = "attachment_100x", .attach_factor = 100.0});
  return out;
}

// Known limits: (model label, case) -> why. Each must be refused at load (check_setting_holds)
// or detected at run time; a case not listed here must not be refused at load.
// XPBD's 10^3 / 10^4 contrast (16 x 1 sweeps did not converge in the stiff vessel: energy
// created; neo_hookean 40 x 1: its explicit-like shear blew up) left this list with the step
// control (issue 29): those steps are redone with 2-8x the substeps (the counts are printed).
const std::map<std::pair<std::string, std::string>, std::string>& known_limits() {
  // The explicit integrator takes a power-of-two factor of its substeps up to the step's
  // budget (8x at 1/60 s) when its bound needs it (contrast 100, a 100 ms step and the 100x
  // attachment now hold that way); beyond the budget it is refused.
  const std::string explicit_bound =
      "explicit bound 2/omega ~ sqrt(m/k) shrinks with stiffness: beyond 8x the substeps refused at load naming the "
      "substeps needed";
  static const std::map<std::pair<std::string, std::string>, std::string> limits = {
      {{"mass_spring/explicit", "contrast_1e3"}, explicit_bound},
      {{"mass_spring/explicit", "contrast_1e4"}, explicit_bound},
  };
  return limits;
}

struct Outcome {
  bool silent_non_finite = false;  // non-finite state in a step reported healthy
  bool non_finite = false;
  bool unhealthy = false;          // some step reported healthy=false
  std::string first_warning;       // of the first unhealthy step
  double max_energy = 0.0;         // kinetic + elastic, mN*mm
  double energy_bound = 0.0;
  double rest_error_mm = 0.0;      // max vertex distance from rest after release
  double median_ms = 0.0;          // median step wall time
  std::string step_control;        // SubstepControl counts (XPBD, mass-spring semi-implicit steps)
  std::string refused_at_load;     // check_setting_holds: why the setting cannot hold (not run then)
};

SimProblem make_problem(const Case& c) {
  SimProblem p;
  p.mesh = make_box_tet_mesh(kNx, kNy, kNz, kSize_mm);
  // A "vessel" along x through the middle cells: region 1.
  p.mesh.region_names = {"parenchyma", "vessel"};
  for (int t = 0; t < p.mesh.num_tets(); ++t) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int v : p.mesh.tets[t]) centroid += 0.25 * p.mesh.rest_positions_World_mm.col(v);
    const bool vessel = centroid.y() > kCell_mm && centroid.y() < 2 * kCell_mm && centroid.z() < kCell_mm;
    p.mesh.tet_region[t] = vessel ? 1 : 0;
  }
  Material parenchyma{.youngs_modulus_kPa = kE_kPa, .poisson_ratio = c.nu, .damping_mass_per_s = 10.0};
  Material vessel = parenchyma;
  vessel.youngs_modulus_kPa = kE_kPa * c.contrast;
  p.region_materials = {parenchyma, vessel};
  p.gravity_World_mm_s2.setZero();
  if (c.initial != "rotated_180") {
    for (int k = 0; k <= kNz; ++k)
      for (int j = 0; j <= kNy; ++j) p.fixed_vertices.push_back(box_vertex_index(kNx, kNy, 0, j, k));
  }
  return p;
}

Outcome run_case(const ModelVariant& variant, const Case& c) {
  const SimProblem problem = make_problem(c);
  Outcome out;
  try {
    check_setting_holds(problem, variant.config, c.dt_s);
  } catch (const std::invalid_argument& e) {
    out.refused_at_load = e.what();
    return out;
  }
  auto model = make_tissue_model(problem, variant.config);
  Eigen::Matrix3Xd rest = problem.mesh.rest_positions_World_mm;
  std::vector<double> wall;
  auto observe = [&](const StepSummary& s) {
    wall.push_back(s.wall_time_ms);
    const bool finite = model->positions_World_mm().allFinite() && model->velocities_World_mm_s().allFinite();
    if (!finite) out.non_finite = true;
    if (!finite && s.healthy) out.silent_non_finite = true;
    if (!s.healthy && !out.unhealthy) {
      out.unhealthy = true;
      out.first_warning = s.warning;
    }
    const double e = s.kinetic_energy + s.elastic_energy;
    out.max_energy = std::max(out.max_energy, std::isfinite(e) ? e : std::numeric_limits<double>::infinity());
  };

  // Initial conditions.
  Eigen::Matrix3Xd x = rest;
  if (c.initial == "inverted") {
    // Interior vertex pushed through the top face: the tets around it invert.
    x(2, box_vertex_index(kNx, kNy, 3, 1, 1)) = kSize_mm.z() + 10.0;
    x(2, box_vertex_index(kNx, kNy, 4, 2, 1)) = -10.0;
  } else if (c.initial == "compressed_80") {
    x.row(0) *= 0.2;  // 80 % compression toward the clamped face
  } else if (c.initial == "rotated_180") {
    const Eigen::Vector3d centre = 0.5 * kSize_mm;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    x = (R * (x.colwise() - centre)).colwise() + centre;
    rest = x;  // a rigid motion: the body must stay at this rest state
  }
  model->set_state(x, Eigen::Matrix3Xd::Zero(3, x.cols()));
  double initial_energy = 0.0;
  {
    // Energy scale for the bound: stored energy of the initial state, or the work an
    // attachment can put in (0.5 k d^2).
    const StepSummary s0 = model->step(c.dt_s);
    observe(s0);
    initial_energy = s0.kinetic_energy + s0.elastic_energy;
  }
  const double k_attach = c.attach_factor * kTissueStiffness_mN_per_mm;
  out.energy_bound = 10.0 * std::max({initial_energy, 0.5 * k_attach * c.pull_mm * c.pull_mm, 1.0});

  const double pull_s = 0.5, hold_s = 0.25, settle_s = 2.0;
  if (c.pull_mm > 0.0) {
    // The free corner "lobe" pulled sideways (y) by a point attachment, then released.
    const int tip = box_vertex_index(kNx, kNy, kNx, kNy, kNz);
    const Eigen::Vector3d start = rest.col(tip);
    const AttachmentId id =
        model->add_attachment({.point = {{tip}, {1.0}}, .target_World_mm = start, .stiffness_mN_per_mm = k_attach});
    for (double t = 0.0; t < pull_s + hold_s; t += c.dt_s) {
      const double f = std::min(1.0, (t + c.dt_s) / pull_s);
      model->set_attachment_target(id, start + Eigen::Vector3d(0, f * c.pull_mm, 0));
      observe(model->step(c.dt_s));
    }
    model->remove_attachment(id);
  }
  for (double t = 0.0; t < settle_s; t += c.dt_s) observe(model->step(c.dt_s));
  const Eigen::Matrix3Xd& xf = model->positions_World_mm();
  out.rest_error_mm = xf.allFinite() ? (xf - rest).colwise().norm().maxCoeff() : std::numeric_limits<double>::infinity();
  std::nth_element(wall.begin(), wall.begin() + static_cast<std::ptrdiff_t>(wall.size() / 2), wall.end());
  out.median_ms = wall[wall.size() / 2];
  if (const auto* xpbd = dynamic_cast<const XpbdModel*>(model.get())) out.step_control = xpbd->step_control().counts();
  if (const auto* ms = dynamic_cast<const MassSpringModel*>(model.get())) out.step_control = ms->step_control().counts();
  return out;
}

using Param = std::tuple<ModelVariant, Case>;

class StabilityMatrix : public ::testing::TestWithParam<Param> {};

TEST_P(StabilityMatrix, PassesOrDetectsKnownLimit) {
  const auto& [variant, c] = GetParam();
  const Outcome o = run_case(variant, c);
  const double tolerance_mm = 0.01 * kSize_mm.maxCoeff();
  const bool refused = !o.refused_at_load.empty();
  const bool passed =
      !refused && !o.non_finite && o.max_energy <= o.energy_bound && o.rest_error_mm < tolerance_mm && !o.unhealthy;
  RecordProperty("rest_error_mm", std::to_string(o.rest_error_mm));
  RecordProperty("max_energy", std::to_string(o.max_energy));
  RecordProperty("energy_bound", std::to_string(o.energy_bound));
  RecordProperty("detected", o.unhealthy ? o.first_warning : "");
  RecordProperty("refused_at_load", o.refused_at_load);
  std::printf("[matrix] %-34s %-16s passed=%d finite=%d energy=%.3g/%.3g rest_error=%.3g mm unhealthy=%d median=%.3f ms %s %s\n",
              variant.label.c_str(), c.name.c_str(), passed, !o.non_finite, o.max_energy, o.energy_bound,
              o.rest_error_mm, o.unhealthy, o.median_ms, o.step_control.c_str(),
              refused ? ("refused at load: " + o.refused_at_load.substr(0, 200)).c_str() : o.first_warning.substr(0, 160).c_str());
  EXPECT_FALSE(o.silent_non_finite) << "NaN/Inf in a step reported healthy";
  const auto it = known_limits().find({variant.label, c.name});
  if (it == known_limits().end()) {
    EXPECT_TRUE(passed) << "finite=" << !o.non_finite << " energy " << o.max_energy << " (bound " << o.energy_bound
                        << ") rest error " << o.rest_error_mm << " mm (tolerance " << tolerance_mm
                        << ") warning: " << o.first_warning;
  } else {
    // Also fails when the model now passes the case: then the entry is stale, remove it.
    // Refused at load (check_setting_holds, naming the setting that works), or detected at
    // run time (a step reported unhealthy with a warning).
    EXPECT_TRUE(refused || (o.unhealthy && !o.first_warning.empty()))
        << "known limit (" << it->second << ") was neither refused at load nor detected at run time"
        << (passed ? " (the case passes now: remove it from kKnownLimits)" : "");
  }
}

std::string param_name(const ::testing::TestParamInfo<Param>& info) {
  std::string s = std::get<0>(info.param).label + "__" + std::get<1>(info.param).name;
  for (char& ch : s)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  return s;
}

INSTANTIATE_TEST_SUITE_P(AllModels, StabilityMatrix,
                         ::testing::Combine(::testing::ValuesIn(model_variants()), ::testing::ValuesIn(cases())),
                         param_name);

}  // namespace
}  // namespace arnav::host
