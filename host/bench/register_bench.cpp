#include "host/bench/register_bench.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <stdexcept>

#include "calibration/lib/plot.hpp"
#include "calibration/lib/point_registration.hpp"
#include "host/register/registration.hpp"
#include "host/register/surface_index.hpp"
#include "host/register/synthetic_data.hpp"
#include "host/register/tracking.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The view of the surface the pointer / camera reaches (taken as anterior): -y of the
// bundled liver's frame.
const Eigen::Vector3d kViewDir(0.0, -1.0, 0.0);

TreStats stats_of(std::vector<double> e) {
  TreStats s;
  if (e.empty()) return s;
  std::sort(e.begin(), e.end());
  double sum = 0;
  for (double v : e) sum += v;
  s.mean = sum / static_cast<double>(e.size());
  s.median = e[e.size() / 2];
  s.p90 = e[std::min(e.size() - 1, static_cast<std::size_t>(std::ceil(0.9 * static_cast<double>(e.size()))) - 1)];
  s.max = e.back();
  return s;
}

// Ground truth problem: the truth scene's mesh with a heterogeneous parenchyma (four
// stiffness bands from a smooth random field, 3-10 kPa; the tumour keeps its own).
SimProblem heterogeneous_problem(const Scene& truth, std::mt19937& rng) {
  SimProblem p = truth.problem;
  std::uniform_real_distribution<double> u(0.0, 2.0 * std::numbers::pi);
  const double a = u(rng), b = u(rng), c = u(rng);
  const Material base = p.region_materials.at(0);
  const int first = static_cast<int>(p.region_materials.size());
  const double moduli[4] = {4.0, 5.5, 7.5, 10.0};
  for (int k = 0; k < 4; ++k) {
    Material m = base;
    m.youngs_modulus_kPa = moduli[k];
    p.region_materials.push_back(m);
    p.mesh.region_names.push_back("band" + std::to_string(k));
  }
  for (int t = 0; t < p.mesh.num_tets(); ++t) {
    if (p.mesh.tet_region[static_cast<std::size_t>(t)] != 0) continue;
    Eigen::Vector3d ctr = Eigen::Vector3d::Zero();
    for (int v : p.mesh.tets[static_cast<std::size_t>(t)]) ctr += p.mesh.rest_positions_World_mm.col(v) / 4.0;
    const double f = std::sin(ctr.x() / 40.0 + a) + std::sin(ctr.y() / 35.0 + b) + std::sin(ctr.z() / 45.0 + c);  // in [-3, 3]
    const int band = std::clamp(static_cast<int>(std::floor((f + 3.0) / 1.5)), 0, 3);
    p.mesh.tet_region[static_cast<std::size_t>(t)] = first + band;
  }
  return p;
}

struct TruthState {
  Eigen::Matrix3Xd x;  // truth mesh positions (Model frame)
  std::string description;
};

// Quasi-static equilibrium of the truth model under the state's loads: exact implicit
// steps of 1 s with the velocity zeroed after each, until no vertex moves 1 um.
TruthState solve_state(const Scene& truth, const SimProblem& het, int state, const Eigen::Vector3d& press_centre) {
  SimProblem p = het;
  // Gravity change: the patient is tilted; the preoperative shape already carries the
  // old gravity, so the load is the difference of the two gravity vectors.
  const double tilt_deg = state == 1 ? 25.0 : (state == 2 ? 20.0 : 30.0);
  const Eigen::Vector3d axis = state == 1 ? Eigen::Vector3d(0, 1, 0) : Eigen::Vector3d(state == 2 ? -1 : 1, 0, 0);
  const Eigen::Vector3d g0 = truth.problem.gravity_World_mm_s2;
  p.gravity_World_mm_s2 = Eigen::AngleAxisd(tilt_deg * std::numbers::pi / 180.0, axis) * g0 - g0;
  for (auto& m : p.region_materials) m.damping_mass_per_s = m.damping_stiffness_s = 0.0;
  ModelConfig c;
  c.kind = "corotational_fem";
  c.integrator = "implicit_euler";
  c.linear_solver = "cholmod";
  c.refactor_every = 1;
  std::unique_ptr<TissueModel> model = make_tissue_model(p, c);
  std::string what = "gravity tilt " + std::to_string(static_cast<int>(tilt_deg)) + " deg";
  // Tool loads are ramped over the first steps (targets moved from the rest position).
  struct Ramp {
    AttachmentId id;
    Eigen::Vector3d from, to;
  };
  std::vector<Ramp> ramps;
  if (state != 1) {  // lobe pull
    const std::vector<int> patch = lowest_surface_patch(truth, 15.0);
    const Eigen::Vector3d pull = state == 0 ? Eigen::Vector3d(15, 0, 0) : Eigen::Vector3d(-10, 0, 0);
    for (int g : patch) {
      const Eigen::Vector3d p0 = truth.organ_surface.positions_World_mm.col(g);
      ramps.push_back({model->add_attachment({truth.organ_embedding.material_point(truth.problem.mesh, g), p0, 200.0 / static_cast<double>(patch.size())}),
                       p0, p0 + pull});
    }
    what += ", lobe pull " + std::to_string(static_cast<int>(pull.norm())) + " mm";
  }
  if (state != 0) {  // a tool presses on the anterior surface
    const double depth = state == 1 ? 10.0 : 8.0;
    const double radius = 12.0;
    int n = 0;
    for (int v = 0; v < truth.organ_surface.positions_World_mm.cols(); ++v)
      if ((truth.organ_surface.positions_World_mm.col(v) - press_centre).norm() < radius) ++n;
    for (int v = 0; v < truth.organ_surface.positions_World_mm.cols(); ++v) {
      const Eigen::Vector3d p0 = truth.organ_surface.positions_World_mm.col(v);
      if ((p0 - press_centre).norm() >= radius) continue;
      ramps.push_back({model->add_attachment({truth.organ_embedding.material_point(truth.problem.mesh, v), p0, 300.0 / n}), p0, p0 - depth * kViewDir});
    }
    what += ", tool press " + std::to_string(static_cast<int>(depth)) + " mm";
  }
  const Eigen::Matrix3Xd zero = Eigen::Matrix3Xd::Zero(3, model->positions_World_mm().cols());
  constexpr int kRampSteps = 10;
  for (int it = 0; it < 200; ++it) {
    const double f = std::min(1.0, (it + 1.0) / kRampSteps);
    for (const Ramp& r : ramps) model->set_attachment_target(r.id, r.from + f * (r.to - r.from));
    const Eigen::Matrix3Xd before = model->positions_World_mm();
    const StepSummary st = model->step(0.1);
    if (!st.healthy)
      throw std::runtime_error("ground-truth state " + std::to_string(state) + " failed at relaxation step " + std::to_string(it) + ": " + st.warning);
    model->set_state(model->positions_World_mm(), zero);
    if (it >= kRampSteps && (model->positions_World_mm() - before).colwise().norm().maxCoeff() < 1e-3) break;
  }
  return {model->positions_World_mm(), what};
}

}  // namespace

std::vector<RegisterBenchRow> run_register_bench(const RegisterBenchOptions& o) {
  std::vector<RegisterBenchRow> rows;
  std::cerr << "loading scenes...\n";
  const Scene truth = load_scene(o.data_dir + "/" + o.scene_dir + "/" + o.truth_scene);
  const Scene reg = load_scene(o.data_dir + "/" + o.scene_dir + "/" + o.registration_scene);
  std::cerr << "truth: " << truth.problem.mesh.num_tets() << " tets; registration: " << reg.problem.mesh.num_tets() << " tets\n";
  std::mt19937 rng(o.seed);

  // Targets: 45 interior (at least 5 mm deep) and 15 on the surface, in the rest shape.
  const SurfaceIndex rest_surface(truth.organ_surface.positions_World_mm, truth.organ_surface.tris);
  std::vector<MaterialPoint> target_points;  // in the truth mesh
  Eigen::Matrix3Xd targets_rest(3, 60);
  std::vector<char> interior(60, 0);
  {
    std::uniform_int_distribution<int> pick_tet(0, truth.problem.mesh.num_tets() - 1);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    int k = 0;
    while (k < 45) {
      const auto& t = truth.problem.mesh.tets[static_cast<std::size_t>(pick_tet(rng))];
      double w[4], s = 0;
      for (double& wi : w) s += (wi = -std::log(std::max(u(rng), 1e-12)));
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      MaterialPoint mp;
      for (int j = 0; j < 4; ++j) {
        w[j] /= s;
        p += w[j] * truth.problem.mesh.rest_positions_World_mm.col(t[static_cast<std::size_t>(j)]);
        mp.vertices.push_back(t[static_cast<std::size_t>(j)]);
        mp.weights.push_back(w[j]);
      }
      if (rest_surface.closest(p).distance_mm < 5.0) continue;
      targets_rest.col(k) = p;
      interior[static_cast<std::size_t>(k)] = 1;
      target_points.push_back(mp);
      ++k;
    }
    std::uniform_int_distribution<int> pick_v(0, static_cast<int>(truth.organ_surface.positions_World_mm.cols()) - 1);
    while (k < 60) {
      const int v = pick_v(rng);
      targets_rest.col(k) = truth.organ_surface.positions_World_mm.col(v);
      target_points.push_back(truth.organ_embedding.material_point(truth.problem.mesh, v));
      ++k;
    }
  }
  const Embedding reg_targets = embed_points(reg.problem.mesh, targets_rest, 5.0, "benchmark target");
  // Landmarks: three well-spread surface vertices (extremes along x and the top).
  std::vector<int> landmark_vertices;
  {
    Eigen::Index i = 0;
    truth.organ_surface.positions_World_mm.row(0).minCoeff(&i);
    landmark_vertices.push_back(static_cast<int>(i));
    truth.organ_surface.positions_World_mm.row(0).maxCoeff(&i);
    landmark_vertices.push_back(static_cast<int>(i));
    truth.organ_surface.positions_World_mm.row(1).minCoeff(&i);
    landmark_vertices.push_back(static_cast<int>(i));
  }
  // The centre of the visible side: where the tool presses and the patches start.
  Eigen::Index seed_v = 0;
  (truth.organ_surface.positions_World_mm.transpose() * kViewDir).maxCoeff(&seed_v);
  const Eigen::Vector3d seed_rest = truth.organ_surface.positions_World_mm.col(seed_v);

  std::mt19937 het_rng(o.seed + 100);
  const SimProblem het = heterogeneous_problem(truth, het_rng);
  std::shared_ptr<const LoadBasis> basis;
  if (o.prebuilt_basis) {
    LoadBasisOptions bo;
    if (o.basis_patches > 0) bo.patches = o.basis_patches;
    if (o.support_clusters >= 0) bo.support_clusters = o.support_clusters;
    bo.gravity_modes = !o.no_gravity_modes;
    basis = std::make_shared<const LoadBasis>(build_load_basis(reg, bo));
    std::cerr << "load basis built once: " << basis->modes() << " modes in " << basis->build_time_s << " s\n";
  }
  const int states = o.quick ? 1 : o.states;
  const std::vector<double> coverages = o.quick ? std::vector<double>{0.3} : o.coverages;
  const std::vector<double> noises = o.quick ? std::vector<double>{1.0} : o.noises_mm;
  for (int s = 0; s < states; ++s) {
    const auto ts = Clock::now();
    const TruthState state = solve_state(truth, het, s, seed_rest);
    std::cerr << "state " << s << " (" << state.description << "): solved in " << seconds_since(ts) << " s\n";
    const Eigen::Matrix3Xd surface_def = truth.organ_embedding.apply(truth.problem.mesh, state.x);
    Eigen::Matrix3Xd targets_def(3, 60);
    for (int k = 0; k < 60; ++k) {
      Eigen::Vector3d p = Eigen::Vector3d::Zero();
      const MaterialPoint& mp = target_points[static_cast<std::size_t>(k)];
      for (std::size_t j = 0; j < mp.vertices.size(); ++j) p += mp.weights[j] * state.x.col(mp.vertices[j]);
      targets_def.col(k) = p;
    }
    for (double coverage : coverages) {
      for (double noise : noises) {
        std::mt19937 case_rng(o.seed * 7919u + static_cast<unsigned>(s * 1000 + coverage * 100 + noise * 10));
        const Eigen::Isometry3d X_true = random_rigid(std::uniform_real_distribution<double>(20.0, 30.0)(case_rng), 100.0, case_rng);
        // A stylus swab: patch around the visible centre, 4 mm spacing; beyond 45 % the
        // patch wraps around the edges (no view restriction).
        const Eigen::Vector3d seed_def = surface_def.col(seed_v);
        SampledPatch patch = sample_patch(surface_def, truth.organ_surface.tris, seed_def, kViewDir, std::min(coverage, 0.45), 4.0, case_rng);
        if (coverage > 0.45) {  // the rest from the rims of the far side
          SampledPatch all = sample_patch(surface_def, truth.organ_surface.tris, seed_def, -kViewDir, coverage - patch.coverage, 4.0, case_rng);
          Eigen::Matrix3Xd both(3, patch.points_mm.cols() + all.points_mm.cols());
          both << patch.points_mm, all.points_mm;
          patch.points_mm = both;
          patch.coverage += all.coverage;
        }
        Eigen::Matrix3Xd data = patch.points_mm;
        add_noise(data, noise, case_rng);
        const int outliers = add_outliers(data, surface_def, 0.05, 20.0, 5.0, case_rng);
        const Eigen::Matrix3Xd data_Intraop = X_true * data;
        const Eigen::Matrix3Xd truth_Intraop = X_true * targets_def;
        std::vector<Landmark> landmarks;
        std::normal_distribution<double> g(0.0, 3.0 / std::sqrt(3.0));
        for (int v : landmark_vertices)
          landmarks.push_back({"lm" + std::to_string(v), truth.organ_surface.positions_World_mm.col(v),
                               X_true * surface_def.col(v) + Eigen::Vector3d(g(case_rng), g(case_rng), g(case_rng)), 0});
        const double max_def = [&] {
          std::vector<Eigen::Vector3d> a, b;
          for (int k = 0; k < 60; ++k) {
            a.push_back(targets_def.col(k));
            b.push_back(targets_rest.col(k));
          }
          const auto fit = calib::register_paired_points(a, b);
          return ((fit.X_AB * targets_rest).colwise().homogeneous() - targets_def.colwise().homogeneous()).colwise().norm().maxCoeff();
        }();
        auto row = [&](const std::string& method, const Eigen::Matrix3Xd& predicted, double surface_rms, double wall, const std::string& note) {
          RegisterBenchRow r;
          r.state = s;
          r.coverage = coverage;
          r.achieved_coverage = patch.coverage;
          r.noise_mm = noise;
          r.points = static_cast<int>(data.cols());
          r.outliers = outliers;
          r.max_deformation_mm = max_def;
          r.method = method;
          std::vector<double> e, ei;
          for (int k = 0; k < 60; ++k) {
            e.push_back((predicted.col(k) - truth_Intraop.col(k)).norm());
            if (interior[static_cast<std::size_t>(k)]) ei.push_back(e.back());
          }
          r.tre = stats_of(e);
          r.tre_interior = stats_of(ei);
          {
            std::vector<Eigen::Vector3d> a, b;
            for (int k = 0; k < 60; ++k) {
              a.push_back(truth_Intraop.col(k));
              b.push_back(predicted.col(k));
            }
            const auto fit = calib::register_paired_points(a, b);
            r.shape_error_mean_mm = ((fit.X_AB * predicted).colwise().homogeneous() - truth_Intraop.colwise().homogeneous()).colwise().norm().mean();
          }
          r.surface_rms_mm = surface_rms;
          r.wall_s = wall;
          r.note = note;
          rows.push_back(r);
          std::cerr << "  state " << s << " coverage " << coverage << " noise " << noise << " " << method << ": TRE mean " << r.tre.mean
                    << " median " << r.tre.median << " p90 " << r.tre.p90 << " max " << r.tre.max << " mm, " << wall << " s" << (note.empty() ? "" : " (" + note + ")") << "\n";
        };
        // Floor: the best rigid transform for the targets themselves.
        {
          std::vector<Eigen::Vector3d> a, b;
          for (int k = 0; k < 60; ++k) {
            a.push_back(truth_Intraop.col(k));
            b.push_back(targets_rest.col(k));
          }
          const auto fit = calib::register_paired_points(a, b);
          row("optimal_rigid", fit.X_AB * targets_rest, 0.0, 0.0, "");
        }
        if (!o.export_dir.empty() && rows.size() == 1) {
          // The case as arnav-register reads it, plus the truth (targets in Intraop).
          std::filesystem::create_directories(o.export_dir);
          std::ofstream pts(o.export_dir + "/surface.xyz");
          pts.precision(10);
          pts << "# arnav-bench register case: state " << s << ", coverage " << coverage << ", noise " << noise << " mm (Intraop, mm)\n";
          for (int i = 0; i < data_Intraop.cols(); ++i) pts << data_Intraop(0, i) << ' ' << data_Intraop(1, i) << ' ' << data_Intraop(2, i) << '\n';
          std::ofstream lm(o.export_dir + "/landmarks.csv");
          lm.precision(10);
          lm << "name,model_x,model_y,model_z,intraop_x,intraop_y,intraop_z\n";
          for (const auto& l : landmarks)
            lm << l.name << ',' << l.p_Model_mm.x() << ',' << l.p_Model_mm.y() << ',' << l.p_Model_mm.z() << ',' << l.p_Intraop_mm.x() << ','
               << l.p_Intraop_mm.y() << ',' << l.p_Intraop_mm.z() << '\n';
          std::vector<NamedPoint> rest, tru;
          for (int k = 0; k < 60; ++k) {
            const std::string name = (interior[static_cast<std::size_t>(k)] ? "interior" : "surface") + std::to_string(k);
            rest.push_back({name, targets_rest.col(k), 0});
            tru.push_back({name, truth_Intraop.col(k), 0});
          }
          write_targets(o.export_dir + "/targets.csv", rest);
          write_targets(o.export_dir + "/truth_targets.csv", tru);
        }
        RegistrationRequest rq;
        rq.points_Intraop_mm = data_Intraop;
        rq.landmarks = landmarks;
        rq.nonrigid.model_kind = o.model_kind;
        rq.nonrigid.scene_boundary = o.scene_boundary;
        rq.nonrigid.anchored_boundary = o.anchored_boundary;
        rq.nonrigid.estimate_gravity_change = o.gravity_change;
        rq.nonrigid.self_contact = !o.no_self_contact;
        rq.nonrigid.include_model_error = o.model_error;
        rq.nonrigid.noise_mm = std::max(0.3, 0.8 * noise);  // trimmed RMS of the normal noise component
        if (!o.schedule.empty()) rq.nonrigid.data_weight_schedule = o.schedule;
        if (o.updates_per_level > 0) rq.nonrigid.max_updates_per_level = o.updates_per_level;
        if (o.steps_per_update > 0) rq.nonrigid.steps_per_update = o.steps_per_update;
        if (o.basis_patches > 0) rq.basis.patches = o.basis_patches;
        if (o.support_clusters >= 0) rq.basis.support_clusters = o.support_clusters;
        rq.basis.gravity_modes = !o.no_gravity_modes;
        rq.loads.estimate_pose = !o.loads_fixed_pose;
        if (o.landmark_error_mm >= 0) rq.loads.landmark_error_mm = o.landmark_error_mm;
        if (o.prior_strain >= 0) rq.loads.prior_strain = o.prior_strain;
        rq.prebuilt_basis = basis;
        rq.prior.enabled = o.pose_prior;
        rq.estimate_noise = o.estimate_noise;
        bool rigid_rows = false;
        for (const std::string& method : o.methods) {
          rq.nonrigid_method = method;
          const RegistrationResult res = register_patient(reg, rq);
          if (!rigid_rows) {
            row("landmark_rigid", res.landmarks->X_IntraopModel * targets_rest, 0.0, 0.0, "");
            row("surface_rigid", res.icp.X_IntraopModel * targets_rest, res.icp.summary.final_rms_mm, res.icp.summary.wall_time_s,
                res.icp.summary.termination);
            rigid_rows = true;
          }
          std::string note = res.nonrigid->message;
          if (method == "loads") {
            const LoadFitResult& f = *res.loads;
            note += "; " + std::to_string(res.basis_modes) + " modes " + (basis ? std::string("prebuilt") : "built in " + std::to_string(res.basis_time_s).substr(0, 5) + " s") + "; " +
                    std::to_string(f.iterations.size()) + " iterations in " + std::to_string(f.wall_time_s).substr(0, 5) + " s";
            if (!f.iterations.empty())
              note += "; lambda " + std::to_string(f.iterations.back().lambda) + (f.prior_lambda > 0 ? " (prior " + std::to_string(f.prior_lambda) + ")" : std::string()) + "; predicted " + std::to_string(f.iterations.back().predicted_rms_mm).substr(0, 5) + " mm";
            const Eigen::AngleAxisd corr(f.D.linear());
            note += "; pose correction " + std::to_string(f.D.translation().norm()).substr(0, 5) + " mm / " +
                    std::to_string(corr.angle() * 180.0 / std::numbers::pi).substr(0, 5) + " deg; max displacement " +
                    std::to_string(f.max_displacement_mm).substr(0, 5) + " mm; gravity share " + std::to_string(f.gravity_fraction).substr(0, 4);
            if (f.landmarks_used > 0)
              note += "; landmarks " + std::to_string(f.landmarks_used) + " rms " + std::to_string(f.landmark_rigid_rms_mm).substr(0, 5) + " -> " +
                      std::to_string(f.landmark_final_rms_mm).substr(0, 5) + " mm";
          } else {
            for (const auto& l : res.nonrigid->levels)
              note += "; w" + std::to_string(static_cast<int>(l.data_weight)) + ": " + std::to_string(l.updates) + " updates " +
                      std::to_string(l.rms_mm).substr(0, 5) + " mm " + std::to_string(l.wall_time_s).substr(0, 4) + " s (model " + std::to_string(l.model_time_s).substr(0, 4) + ")";
            if (res.nonrigid->gravity_change_mm_s2.norm() > 0) {
              const Eigen::Vector3d gc = res.nonrigid->gravity_change_mm_s2 / 9810.0;
              note += "; gravity change (g) " + std::to_string(gc.x()).substr(0, 6) + " " + std::to_string(gc.y()).substr(0, 6) + " " +
                      std::to_string(gc.z()).substr(0, 6) + " in " + std::to_string(res.nonrigid->gravity_time_s).substr(0, 4) + " s";
            }
            note += "; contact search " + std::to_string(res.nonrigid->contact_time_s).substr(0, 5) + " s";
          }
          note += "; rigid rms " + std::to_string(res.nonrigid->rigid_rms_mm).substr(0, 5);
          note += "; crossed " + std::to_string(res.nonrigid->crossed_vertices);
          note += "; stop at " + std::to_string(res.nonrigid->discrepancy_mm).substr(0, 5) + " mm";
          row(method == "loads" ? "nonrigid_loads" : "nonrigid", carry_to_intraop(reg, reg_targets, res), res.nonrigid->final_rms_mm, res.wall_time_s, note);
        }
      }
    }
  }
  return rows;
}

std::vector<TrackBenchRow> run_track_bench(const RegisterBenchOptions& o, int frames, std::string& model_name) {
  const Scene truth = load_scene(o.data_dir + "/liver/" + o.truth_scene);
  const Scene reg = load_scene(o.data_dir + "/liver/" + o.registration_scene);
  std::mt19937 rng(o.seed);
  std::mt19937 het_rng(o.seed + 100);
  const SimProblem het = heterogeneous_problem(truth, het_rng);
  Eigen::Index seed_v = 0;
  (truth.organ_surface.positions_World_mm.transpose() * kViewDir).maxCoeff(&seed_v);
  const TruthState state = solve_state(truth, het, 1, truth.organ_surface.positions_World_mm.col(seed_v));
  const Eigen::Matrix3Xd& rest = truth.problem.mesh.rest_positions_World_mm;
  // targets: 45 interior tet points of the truth mesh at least 5 mm deep, as in 'register'
  const SurfaceIndex rest_surface(truth.organ_surface.positions_World_mm, truth.organ_surface.tris);
  std::uniform_int_distribution<int> pick_tet(0, truth.problem.mesh.num_tets() - 1);
  std::vector<std::array<int, 4>> tt;
  Eigen::Matrix3Xd t_rest(3, 45), t_def(3, 45);
  for (int k = 0; k < 45;) {
    const auto& t = truth.problem.mesh.tets[static_cast<std::size_t>(pick_tet(rng))];
    const Eigen::Vector3d c = (rest.col(t[0]) + rest.col(t[1]) + rest.col(t[2]) + rest.col(t[3])) / 4.0;
    if (rest_surface.closest(c).distance_mm < 5.0) continue;
    t_rest.col(k) = c;
    t_def.col(k) = (state.x.col(t[0]) + state.x.col(t[1]) + state.x.col(t[2]) + state.x.col(t[3])) / 4.0;
    ++k;
  }
  const Embedding reg_targets = embed_points(reg.problem.mesh, t_rest, 5.0, "tracking target");
  // features: 60 organ-surface vertices of the visible 30 % patch
  const Eigen::Matrix3Xd s_rest = truth.organ_surface.positions_World_mm;
  const Eigen::Matrix3Xd s_def = truth.organ_embedding.apply(truth.problem.mesh, state.x);
  const SampledPatch patch = sample_patch(s_rest, truth.organ_surface.tris, s_rest.col(seed_v), kViewDir, 0.3, 50.0, rng);
  std::vector<int> candidates;
  for (int t : patch.tris)
    for (int v : truth.organ_surface.tris[static_cast<std::size_t>(t)]) candidates.push_back(v);
  std::sort(candidates.begin(), candidates.end());
  candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  std::shuffle(candidates.begin(), candidates.end(), rng);
  candidates.resize(std::min<std::size_t>(60, candidates.size()));
  const Eigen::Isometry3d X_true = random_rigid(25.0, 100.0, rng);
  TrackingOptions topt;
  topt.realtime_model = !o.track_scene_model_settings;
  SurfaceTracker tracker(reg, reg.problem.mesh.rest_positions_World_mm, X_true, topt);
  model_name = tracker.model_name();
  std::normal_distribution<double> noise(0.0, 0.5);
  std::vector<long long> ids(candidates.begin(), candidates.end());
  std::vector<TrackBenchRow> rows;
  const double dt = 1.0 / 60.0;
  for (int f = 0; f < frames; ++f) {
    const double t = f * dt;
    const double sfac = 0.5 * (1.0 - std::cos(2.0 * std::numbers::pi * t / 4.0));
    Eigen::Matrix3Xd pts(3, static_cast<Eigen::Index>(candidates.size()));
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      const int v = candidates[i];
      pts.col(static_cast<Eigen::Index>(i)) =
          X_true * (s_rest.col(v) + sfac * (s_def.col(v) - s_rest.col(v))) + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    }
    const TrackingFrame tf = tracker.update(pts, ids, dt);
    const Eigen::Matrix3Xd truth_t = X_true * (t_rest + sfac * (t_def - t_rest));
    const Eigen::Matrix3Xd tracked = X_true * reg_targets.apply(reg.problem.mesh, tracker.positions_Model_mm());
    const Eigen::Matrix3Xd still = X_true * t_rest;
    TrackBenchRow r;
    r.frame = f;
    r.t_s = t;
    double sum = 0, mx = 0, sum_still = 0;
    for (int k = 0; k < truth_t.cols(); ++k) {
      const double d = (tracked.col(k) - truth_t.col(k)).norm();
      sum += d;
      mx = std::max(mx, d);
      sum_still += (still.col(k) - truth_t.col(k)).norm();
    }
    r.tre_tracked_mm = sum / static_cast<double>(truth_t.cols());
    r.tre_max_tracked_mm = mx;
    r.tre_static_mm = sum_still / static_cast<double>(truth_t.cols());
    r.frame_ms = tf.frame_ms;
    r.model_ms = tf.model_ms;
    r.tracked = tf.tracked;
    r.healthy = tf.healthy;
    rows.push_back(r);
  }
  return rows;
}

void write_register_csv(const std::string& path, const std::vector<RegisterBenchRow>& rows) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << "state,coverage,achieved_coverage,noise_mm,points,outliers,max_deformation_mm,method,tre_mean_mm,tre_median_mm,tre_p90_mm,tre_max_mm,"
         "interior_tre_mean_mm,interior_tre_max_mm,shape_error_mean_mm,surface_rms_mm,wall_s,note\n";
  for (const auto& r : rows) {
    std::string note = r.note;
    std::replace(note.begin(), note.end(), ',', ';');
    out << r.state << ',' << r.coverage << ',' << r.achieved_coverage << ',' << r.noise_mm << ',' << r.points << ',' << r.outliers << ','
        << r.max_deformation_mm << ',' << r.method << ',' << r.tre.mean << ',' << r.tre.median << ',' << r.tre.p90 << ',' << r.tre.max << ','
        << r.tre_interior.mean << ',' << r.tre_interior.max << ',' << r.shape_error_mean_mm << ',' << r.surface_rms_mm << ',' << r.wall_s << ",\"" << note << "\"\n";
  }
}

void write_register_plots(const std::string& dir, const std::vector<RegisterBenchRow>& rows) {
  calib::Chart chart;
  chart.title = "arnav-bench register: mean TRE per case against run time";
  chart.x_label = "run time (s)";
  chart.y_label = "mean TRE (mm)";
  chart.reference_y = 2.5;
  chart.reference_label = "goal 2.5 mm";
  const std::map<std::string, cv::Scalar> colours = {{"landmark_rigid", cv::Scalar(60, 60, 200)},
                                                     {"surface_rigid", cv::Scalar(200, 90, 20)},
                                                     {"nonrigid", cv::Scalar(40, 160, 40)},
                                                     {"nonrigid_loads", cv::Scalar(160, 40, 160)}};
  for (const auto& [method, colour] : colours) {
    calib::PlotSeries s;
    s.name = method;
    s.style = calib::SeriesStyle::Points;
    s.color = colour;
    for (const auto& r : rows)
      if (r.method == method) {
        s.x.push_back(r.wall_s);
        s.y.push_back(r.tre.mean);
      }
    chart.series.push_back(s);
  }
  calib::write_chart(dir + "/register_tre_time.png", chart);
  // Mean TRE per coverage for each method (averaged over states and noise).
  calib::Chart cov;
  cov.title = "mean TRE against surface coverage";
  cov.x_label = "coverage (fraction of the surface)";
  cov.y_label = "mean TRE (mm)";
  cov.reference_y = 2.5;
  cov.reference_label = "goal 2.5 mm";
  for (const std::string method : {"optimal_rigid", "landmark_rigid", "surface_rigid", "nonrigid", "nonrigid_loads"}) {
    std::map<double, std::pair<double, int>> acc;
    for (const auto& r : rows)
      if (r.method == method) {
        acc[r.coverage].first += r.tre.mean;
        acc[r.coverage].second += 1;
      }
    if (acc.empty()) continue;
    calib::PlotSeries s;
    s.name = method;
    s.color = method == "optimal_rigid" ? cv::Scalar(120, 120, 120) : colours.at(method);
    for (const auto& [c, v] : acc) {
      s.x.push_back(c);
      s.y.push_back(v.first / v.second);
    }
    cov.series.push_back(s);
  }
  calib::write_chart(dir + "/register_tre_coverage.png", cov);
}

void write_track_plot(const std::string& png, const std::vector<TrackBenchRow>& rows) {
  calib::Chart c;
  c.title = "tracking: mean target error per frame";
  c.x_label = "time (s)";
  c.y_label = "mean TRE (mm)";
  calib::PlotSeries tracked, still;
  tracked.name = "tracked";
  tracked.color = cv::Scalar(40, 160, 40);
  still.name = "static model (no tracking)";
  still.color = cv::Scalar(60, 60, 200);
  for (const auto& r : rows) {
    tracked.x.push_back(r.t_s);
    tracked.y.push_back(r.tre_tracked_mm);
    still.x.push_back(r.t_s);
    still.y.push_back(r.tre_static_mm);
  }
  c.series = {still, tracked};
  calib::write_chart(png, c);
}

}  // namespace arnav::host
