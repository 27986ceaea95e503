#include "host/bench/deform_bench.hpp"

#include <algorithm>
#include <cstdio>
#include <chrono>
#include <ctime>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>

#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

constexpr double kFrame_s = 1.0 / 60.0;
// Heavy mass damping so that every dynamic model settles within the run: the scenarios
// compare equilibria (sag, pull), not transients. Damping does not change an equilibrium.
constexpr double kBenchDamping_per_s = 20.0;
const Eigen::Vector3d kPull_mm(25.0, 0.0, 0.0);   // tool displacement of the grasped point
constexpr double kGraspStiffness_mN_per_mm = 200.0;  // whole grasp
constexpr double kGraspRadius_mm = 10.0;
constexpr double kPullRamp_s = 0.25;  // 25 mm in 0.25 s: 100 mm/s tool speed
// The reference stops when no vertex moves more than this in one iteration (0.1 um).
constexpr double kReferenceUpdate_mm = 1e-4;
constexpr double kRelaxStep_s = 0.05;
const Material kVesselWall{.youngs_modulus_kPa = 500.0, .poisson_ratio = 0.45, .density_kg_per_mm3 = 1.06e-6};

struct Setup {
  SimProblem problem;
  std::vector<AttachmentSpec> grasp;  // the tool's jaws: a patch of surface points
};

// The tool grasps a patch of the organ surface: the points within kGraspRadius_mm of
// the lowest surface point (the tip of the hanging lobe), sharing the grasp stiffness.
// Same points in every bundled scene (same surface file). A single grasped vertex would
// invert its tets under a 25 mm pull.
std::vector<int> grasp_patch(const Scene& s) { return lowest_surface_patch(s, kGraspRadius_mm); }

Setup make_setup(const Scene& s, const std::string& scenario) {
  Setup out;
  out.problem = s.problem;
  for (auto& m : out.problem.region_materials) m.damping_mass_per_s = kBenchDamping_per_s;
  if (scenario == "vessel_stiffened") {
    if (!s.vessels) throw LoadError(s.source + ": vessel_stiffened needs a scene with vessels");
    out.problem.vessels = s.vessels->rest;
    out.problem.vessel_material = kVesselWall;
    out.problem.vessel_material.damping_mass_per_s = kBenchDamping_per_s;
  } else if (scenario == "lobe_pull") {
    const std::vector<int> patch = grasp_patch(s);
    for (int g : patch)
      out.grasp.push_back({s.organ_embedding.material_point(s.problem.mesh, g), s.organ_surface.positions_World_mm.col(g) + kPull_mm,
                           kGraspStiffness_mN_per_mm / static_cast<double>(patch.size())});
  } else if (scenario != "gravity_sag") {
    throw std::invalid_argument("unknown scenario '" + scenario + "' (gravity_sag, lobe_pull, vessel_stiffened)");
  }
  return out;
}

struct Observed {
  Eigen::Vector3d tumour;
  Eigen::Matrix3Xd surface;
};

Observed observe(const Scene& s, const Eigen::Matrix3Xd& x) {
  return {tumour_centroid_World_mm(s, 0, x), s.organ_embedding.apply(s.problem.mesh, x)};
}

struct Reference {
  Observed rest, solved;
  ReferenceInfo info;
};

Reference solve_reference(const Scene& s, const std::string& scenario, int threads, int max_iterations) {
  const auto t0 = std::chrono::steady_clock::now();
  Setup setup = make_setup(s, scenario);
  ModelConfig c;
  c.kind = "corotational_fem";
  c.integrator = "implicit_euler";  // quasi_static diverges on these meshes (see docs/benchmarks.md)
  c.linear_solver = "cholmod";
  c.refactor_every = 1;
  c.tolerance = 1e-12;
  c.threads = threads;
  std::unique_ptr<TissueModel> model = make_tissue_model(setup.problem, c);
  for (const auto& a : setup.grasp) model->add_attachment(a);
  Reference r;
  r.info.scenario = scenario;
  r.info.scene = s.source;
  r.info.vertices = s.problem.mesh.num_vertices();
  r.info.tets = s.problem.mesh.num_tets();
  r.rest = observe(s, s.problem.mesh.rest_positions_World_mm);
  // Pseudo-time relaxation to the static equilibrium: implicit Euler with an exact
  // (CHOLMOD) solve every step, large steps and the heavy bench damping, iterated until
  // the largest vertex update is below 0.1 um. At that fixed point v = 0 and f(x) = 0:
  // the equilibrium a quasi-static solve would give.
  for (int it = 1; it <= max_iterations; ++it) {
    const Eigen::Matrix3Xd before = model->positions_World_mm();
    const StepSummary st = model->step(kRelaxStep_s);
    if (!st.healthy) throw std::runtime_error("reference solve (" + scenario + ") failed: " + st.warning);
    r.info.iterations = it;
    r.info.last_max_increment_mm = (model->positions_World_mm() - before).colwise().norm().maxCoeff();
    if (it % 10 == 0)
      std::cerr << "  reference iteration " << it << ": max update " << r.info.last_max_increment_mm << " mm, "
                << std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() << " s\n";
    if (r.info.last_max_increment_mm < kReferenceUpdate_mm) {
      r.info.converged = true;
      break;
    }
  }
  r.solved = observe(s, model->positions_World_mm());
  r.info.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return r;
}

struct Setting {
  std::string label;
  ModelConfig config;
};

std::vector<Setting> settings(bool quick, bool fine, int threads) {
  std::vector<Setting> out;
  auto add = [&](const std::string& label, ModelConfig c) {
    c.threads = threads;
    out.push_back({label, c});
  };
  const std::vector<std::string> kinds = available_model_kinds();
  auto have = [&](const char* k) { return std::find(kinds.begin(), kinds.end(), k) != kinds.end(); };
  if (have("xpbd")) {
    ModelConfig c;
    c.kind = "xpbd";
    c.tolerance = 0.0;
    const std::vector<std::pair<int, int>> grid =
        quick ? std::vector<std::pair<int, int>>{{4, 4}} : std::vector<std::pair<int, int>>{{1, 5}, {2, 5}, {4, 4}, {8, 4}};
    for (auto [sub, it] : grid) {
      c.substeps = sub;
      c.iterations = it;
      add("xpbd s" + std::to_string(sub) + " i" + std::to_string(it), c);
    }
    // Small steps (Macklin et al. 2019): many substeps of one sweep each, with the
    // fixed-corotated energy and with the stable Neo-Hookean one ("nh": one sweep per
    // substep only).
    if (!quick) {
      c.iterations = 1;
      for (int sub : {5, 10, 16, 20, 40}) {
        c.substeps = sub;
        add("xpbd s" + std::to_string(sub) + " i1", c);
      }
      c.energy = "neo_hookean";
      for (int sub : {5, 10, 20, 40}) {
        c.substeps = sub;
        add("xpbd nh s" + std::to_string(sub) + " i1", c);
      }
    }
  }
  if (have("mass_spring") && !quick) {
    ModelConfig c;
    c.kind = "mass_spring";
    c.integrator = "semi_implicit";
    c.tolerance = 1e-4;
    c.iterations = 20;
    add("mass_spring semi_implicit cg20", c);
    c.linear_solver = "laplacian";  // CG preconditioned by the prefactored local/global matrix
    c.iterations = 5;
    add("mass_spring semi_implicit laplacian cg5", c);
    c.linear_solver.clear();
    c.iterations = 20;
    c.integrator = "explicit";
    c.substeps = 20;
    add("mass_spring explicit s20", c);
    // Prefactored backward Euler (local/global): iterations per 1/60 s frame.
    c.integrator = "local_global";
    c.substeps = 1;
    c.tolerance = 0.0;
    for (int it : {1, 2, 4, 10}) {
      c.iterations = it;
      add("mass_spring local_global i" + std::to_string(it), c);
    }
  }
  if (have("corotational_fem")) {
    ModelConfig c;
    c.kind = "corotational_fem";
    c.integrator = "implicit_euler";
    c.linear_solver = "pcg";
    c.tolerance = 1e-4;
    c.refactor_every = 30;
    c.iterations = 20;
    add("fem implicit pcg20 refactor30", c);
    if (!quick && !fine) {  // exact solves every step: only affordable on the coarse mesh
      c.linear_solver = "cholmod";
      c.refactor_every = 1;
      add("fem implicit cholmod", c);
    }
    if (!quick) {
      c.linear_solver = "pcg";
      c.iterations = 5;
      c.refactor_every = 60;
      add("fem implicit pcg5 refactor60", c);
      // Real-time settings (docs/benchmarks.md, "Real time on 2 cores"); timing-dependent
      // (not bit-reproducible); wall time is the frame time, the CPU column adds up all
      // threads. First: PCG capped at 2 iterations on a factor that a worker thread
      // refactorises continuously, applied in single precision, assembly on 2 threads,
      // OpenBLAS on 1 thread.
      c.iterations = 2;
      c.refactor_every = 1;
      c.refactor_in_background = true;
      c.single_precision_preconditioner = true;
      c.blas_threads = 1;
      add("fem implicit pcg2 background float t2", c);
      out.back().config.threads = 2;
      // The 60 Hz point: one assembly thread, a background refactorisation every 30 steps
      // only (a running factorisation slows the stepping thread) and up to 3 iterations.
      c.iterations = 3;
      c.refactor_every = 30;
      add("fem implicit pcg3 background r30 float", c);
    }
    // Stable Neo-Hookean material, projected Newton (docs/sim.md): up to 3 Newton
    // iterations per frame with exact CHOLMOD solves, and 1 iteration per frame solved by
    // PCG on a lagged factor (refreshed every 30 frames).
    ModelConfig n;
    n.kind = "corotational_fem";
    n.material_model = "stable_neo_hookean";
    n.integrator = "implicit_euler";
    n.linear_solver = "cholmod";
    n.iterations = 3;
    n.tolerance = 1e-3;
    if (!fine) add("fem snh newton3 cholmod", n);
    n.linear_solver = "pcg";
    n.iterations = 1;
    n.refactor_every = 30;
    add("fem snh newton1 pcg r30", n);
  }
  return out;
}

double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(q * static_cast<double>(v.size())))];
}

}  // namespace

DeformBenchResult run_deform_bench(const DeformBenchOptions& o) {
  DeformBenchResult result;
  struct Mesh {
    std::string name;
    Scene scene;
  };
  std::vector<Mesh> meshes;
  std::cerr << "arnav-bench deform: loading scenes from " << o.data_dir << "\n";
  auto wanted_mesh = [&](const char* name) { return std::find(o.meshes.begin(), o.meshes.end(), name) != o.meshes.end(); };
  if (o.quick || wanted_mesh("coarse")) meshes.push_back({"coarse", load_scene(o.data_dir + "/" + o.scene_set + "_coarse.scene.yaml")});
  if (!o.quick && wanted_mesh("fine")) meshes.push_back({"fine", load_scene(o.data_dir + "/" + o.scene_set + ".scene.yaml")});
  auto wanted_setting = [&](const std::string& label) {
    if (o.setting_prefixes.empty()) return true;
    for (const std::string& p : o.setting_prefixes)
      if (label.rfind(p, 0) == 0) return true;
    return false;
  };
  // Reference mesh: finer than every model mesh (quick: the coarse mesh itself, smoke only).
  const Scene reference_scene = o.quick ? meshes[0].scene : load_scene(o.data_dir + "/" + o.scene_set + "_reference.scene.yaml");
  const int frames = o.quick ? std::min(o.frames, 5) : o.frames;

  for (const std::string& scenario : o.scenarios) {
    std::cerr << "arnav-bench deform: " << scenario << ": reference on " << reference_scene.problem.mesh.num_tets() << " tets\n";
    Reference ref;
    try {
      ref = solve_reference(reference_scene, scenario, o.threads, o.quick ? 5 : 60);
    } catch (const std::runtime_error& e) {
      // No reference, no errors to measure: say so and go on with the other scenarios.
      std::cerr << "arnav-bench deform: " << scenario << ": skipped: " << e.what() << "\n";
      ReferenceInfo info;
      info.scenario = scenario;
      info.scene = e.what();
      result.references.push_back(info);
      continue;
    }
    result.references.push_back(ref.info);
    const double ref_tumour_disp = (ref.solved.tumour - ref.rest.tumour).norm();
    const double ref_surface_disp = (ref.solved.surface - ref.rest.surface).colwise().norm().maxCoeff();
    for (const Mesh& mesh : meshes) {
      for (const Setting& setting : settings(o.quick, mesh.name == "fine", o.threads)) {
        if (!wanted_setting(setting.label)) continue;
        DeformBenchRow row;
        row.scenario = scenario;
        row.label = setting.label;
        row.mesh = mesh.name;
        row.config = setting.config;
        row.vertices = mesh.scene.problem.mesh.num_vertices();
        row.tets = mesh.scene.problem.mesh.num_tets();
        row.vessels_modelled = scenario == "vessel_stiffened" && setting.config.kind == "corotational_fem";
        row.reference_tumour_displacement_mm = ref_tumour_disp;
        row.reference_max_surface_displacement_mm = ref_surface_disp;
        row.reference_tets = ref.info.tets;
        Setup setup = make_setup(mesh.scene, scenario);
        std::unique_ptr<TissueModel> model;
        try {
          model = make_tissue_model(setup.problem, setting.config);
        } catch (const std::invalid_argument& e) {
          row.healthy = false;
          row.note = std::string("not built: ") + e.what();
          result.rows.push_back(row);
          continue;
        }
        // The tool moves the grasp at a finite speed: the pull ramps over kPullRamp_s.
        std::vector<AttachmentId> jaws;
        for (const auto& a : setup.grasp) {
          AttachmentSpec start = a;
          start.target_World_mm = a.target_World_mm - kPull_mm;
          jaws.push_back(model->add_attachment(start));
        }
        std::vector<double> wall, cpu;
        double inverted_run_s = 0.0;
        for (int f = 0; f < frames; ++f) {
          const double ramp = std::min(1.0, (f + 1) * kFrame_s / kPullRamp_s);
          for (std::size_t j = 0; j < jaws.size(); ++j)
            model->set_attachment_target(jaws[j], setup.grasp[j].target_World_mm - (1.0 - ramp) * kPull_mm);
          const auto t0 = std::chrono::steady_clock::now();
          const double c0 = cpu_ms();
          const StepSummary st = model->step(kFrame_s);
          cpu.push_back(cpu_ms() - c0);
          wall.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
          row.frames_run = f + 1;
          if (st.inverted_elements > 0) {
            ++row.frames_with_inverted;
            inverted_run_s += kFrame_s;
            row.worst_inverted_run_s = std::max(row.worst_inverted_run_s, inverted_run_s);
          } else {
            inverted_run_s = 0.0;
          }
          if (!st.healthy) {
            row.healthy = false;
            row.note = st.warning;
            break;
          }
          if (!st.warning.empty()) row.note = st.warning;  // last warning (e.g. not converged)
        }
        row.median_frame_ms = percentile(wall, 0.5);
        row.p90_frame_ms = percentile(wall, 0.9);
        row.median_frame_cpu_ms = percentile(cpu, 0.5);
        const Observed obs = observe(mesh.scene, model->positions_World_mm());
        row.tumour_error_mm = (obs.tumour - ref.solved.tumour).norm();
        row.max_surface_error_mm = (obs.surface - ref.solved.surface).colwise().norm().maxCoeff();
        if (row.frames_with_inverted > 0) {
          char buf[96];
          std::snprintf(buf, sizeof buf, "inverted tets in %d frames, longest run %.2f s", row.frames_with_inverted, row.worst_inverted_run_s);
          row.note = buf + (row.note.empty() ? std::string() : "; " + row.note);
        }
        if (scenario == "vessel_stiffened" && !row.vessels_modelled) row.note = "model ignores vessels" + (row.note.empty() ? "" : "; " + row.note);
        std::cerr << "  " << scenario << " " << mesh.name << " " << setting.label << ": " << row.median_frame_ms << " ms/frame wall, " << row.median_frame_cpu_ms << " ms CPU, tumour "
                  << row.tumour_error_mm << " mm, surface max " << row.max_surface_error_mm << " mm, inverted frames " << row.frames_with_inverted << " (longest run " << row.worst_inverted_run_s << " s)" << (row.healthy ? "" : " UNHEALTHY")
                  << "\n";
        result.rows.push_back(row);
      }
    }
  }
  return result;
}

void write_deform_csv(const std::string& path, const DeformBenchResult& r) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot write");
  out << "scenario,model,setting,mesh,vertices,tets,frames,median_frame_ms,p90_frame_ms,median_frame_cpu_ms,rate_hz_cpu,tumour_centroid_error_mm,"
         "max_surface_error_mm,reference_tumour_displacement_mm,reference_max_surface_displacement_mm,reference_tets,healthy,vessels_modelled,note\n";
  for (const auto& row : r.rows) {
    std::string note = row.note;
    std::replace(note.begin(), note.end(), ',', ';');
    out << row.scenario << ',' << row.config.kind << ',' << row.label << ',' << row.mesh << ',' << row.vertices << ',' << row.tets << ','
        << row.frames_run << ',' << row.median_frame_ms << ',' << row.p90_frame_ms << ',' << row.median_frame_cpu_ms << ','
        << (row.median_frame_cpu_ms > 0 ? 1000.0 / row.median_frame_cpu_ms : 0.0) << ',' << row.tumour_error_mm << ',' << row.max_surface_error_mm
        << ',' << row.reference_tumour_displacement_mm << ',' << row.reference_max_surface_displacement_mm << ',' << row.reference_tets
        << ',' << (row.healthy ? 1 : 0)
        << ',' << (row.vessels_modelled ? 1 : 0) << ',' << note << '\n';
  }
}

DeformBenchResult read_deform_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open");
  std::string line;
  std::getline(in, line);  // header
  DeformBenchResult r;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty()) continue;
    std::vector<std::string> f;
    std::size_t start = 0;
    for (int k = 0; k < 19; ++k) {  // the note (last) holds no commas (written as ;)
      const std::size_t comma = line.find(',', start);
      f.push_back(line.substr(start, comma == std::string::npos ? std::string::npos : comma - start));
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
    if (f.size() < 19) throw std::runtime_error(path + ":" + std::to_string(line_no) + ": expected 19 columns");
    DeformBenchRow row;
    try {
      row.scenario = f[0];
      row.config.kind = f[1];
      row.label = f[2];
      row.mesh = f[3];
      row.vertices = std::stoi(f[4]);
      row.tets = std::stoi(f[5]);
      row.frames_run = std::stoi(f[6]);
      row.median_frame_ms = std::stod(f[7]);
      row.p90_frame_ms = std::stod(f[8]);
      row.median_frame_cpu_ms = std::stod(f[9]);
      row.tumour_error_mm = std::stod(f[11]);
      row.max_surface_error_mm = std::stod(f[12]);
      row.reference_tumour_displacement_mm = std::stod(f[13]);
      row.reference_max_surface_displacement_mm = std::stod(f[14]);
      row.reference_tets = std::stoi(f[15]);
      row.healthy = f[16] == "1";
      row.vessels_modelled = f[17] == "1";
      row.note = f[18];
    } catch (const std::exception&) {
      throw std::runtime_error(path + ":" + std::to_string(line_no) + ": malformed number");
    }
    r.rows.push_back(row);
  }
  return r;
}

}  // namespace arnav::host
