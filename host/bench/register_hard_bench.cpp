#include "host/bench/register_hard_bench.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <numbers>
#include <random>
#include <stdexcept>

#include "host/register/registration.hpp"
#include "host/register/surface_index.hpp"
#include "host/register/synthetic_data.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
const Eigen::Vector3d kViewDir(0.0, -1.0, 0.0);  // the anterior side the pointer reaches

TreStats tre_stats(const Eigen::Matrix3Xd& predicted, const Eigen::Matrix3Xd& truth) {
  std::vector<double> e;
  for (Eigen::Index k = 0; k < truth.cols(); ++k) e.push_back((predicted.col(k) - truth.col(k)).norm());
  std::sort(e.begin(), e.end());
  TreStats s;
  if (e.empty()) return s;
  double sum = 0;
  for (double v : e) sum += v;
  s.mean = sum / static_cast<double>(e.size());
  s.median = e[e.size() / 2];
  s.p90 = e[std::min(e.size() - 1, static_cast<std::size_t>(std::ceil(0.9 * static_cast<double>(e.size()))) - 1)];
  s.max = e.back();
  return s;
}

// Supports unlike the scene's fixed set: the part of the top band (within 15 mm of the
// highest volume surface vertex) at x below the middle + 10 mm, and a posterior patch
// (within 12 mm of the most posterior surface point, mid-height).
std::vector<int> truth_supports(const TetMesh& mesh) {
  const Eigen::Matrix3Xd& x = mesh.rest_positions_World_mm;
  std::vector<char> surf(static_cast<std::size_t>(mesh.num_vertices()), 0);
  for (const auto& f : mesh.surface_tris)
    for (int v : f) surf[static_cast<std::size_t>(v)] = 1;
  const Eigen::Vector3d lo = x.rowwise().minCoeff(), hi = x.rowwise().maxCoeff();
  const double xmid = 0.5 * (lo.x() + hi.x()), zmid = 0.5 * (lo.z() + hi.z());
  std::vector<int> fixed;
  for (int v = 0; v < mesh.num_vertices(); ++v) {
    if (!surf[static_cast<std::size_t>(v)]) continue;
    const Eigen::Vector3d p = x.col(v);
    const bool band = p.z() > hi.z() - 15.0 && p.x() < xmid + 10.0;
    const bool bare = p.y() > hi.y() - 12.0 && std::abs(p.z() - zmid) < 20.0;
    if (band || bare) fixed.push_back(v);
  }
  return fixed;
}

// A smooth random field of largest amplitude amp_mm over the points (three plane waves of
// 80-160 mm wavelength in random directions).
Eigen::Matrix3Xd smooth_field(const Eigen::Matrix3Xd& x, double amp_mm, std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::Matrix3Xd f = Eigen::Matrix3Xd::Zero(3, x.cols());
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    const Eigen::Vector3d w = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized() * (2.0 * std::numbers::pi / (80.0 + 80.0 * u(rng)));
    const double phase = 2.0 * std::numbers::pi * u(rng);
    for (Eigen::Index i = 0; i < x.cols(); ++i) f.col(i) += d * std::sin(w.dot(x.col(i)) + phase);
  }
  const double mx = f.colwise().norm().maxCoeff();
  return mx > 0 ? Eigen::Matrix3Xd(f * (amp_mm / mx)) : f;
}

struct HardTruth {
  Eigen::Matrix3Xd x;          // deformed truth positions (fine mesh)
  double preop_error_mm = 0;   // largest rest-shape difference to the scene
  double push_mm = 0, achieved_push_mm = 0;
  int site = 0;                // organ-surface vertex pushed
};

HardTruth solve_truth(const Scene& truth, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  SimProblem p = truth.problem;
  // heterogeneous parenchyma: four bands of a smooth random field, 3.5-10 kPa
  const double a = 6.283 * u(rng), b = 6.283 * u(rng), c = 6.283 * u(rng);
  const int first = static_cast<int>(p.region_materials.size());
  const double moduli[4] = {3.5, 5.0, 7.0, 10.0};
  for (int k = 0; k < 4; ++k) {
    Material m = p.region_materials.at(0);
    m.youngs_modulus_kPa = moduli[k];
    m.damping_mass_per_s = m.damping_stiffness_s = 0.0;
    p.region_materials.push_back(m);
    p.mesh.region_names.push_back("band" + std::to_string(k));
  }
  for (int t = 0; t < p.mesh.num_tets(); ++t) {
    if (p.mesh.tet_region[static_cast<std::size_t>(t)] != 0) continue;
    const Eigen::Vector3d ctr = p.mesh.rest_positions_World_mm.col(p.mesh.tets[static_cast<std::size_t>(t)][0]);
    const double f = std::sin(ctr.x() / 40.0 + a) + std::sin(ctr.y() / 35.0 + b) + std::sin(ctr.z() / 45.0 + c);
    p.mesh.tet_region[static_cast<std::size_t>(t)] = first + std::clamp(static_cast<int>(std::floor((f + 3.0) / 1.5)), 0, 3);
  }
  for (auto& m : p.region_materials) m.damping_mass_per_s = m.damping_stiffness_s = 0.0;
  p.fixed_vertices = truth_supports(p.mesh);
  p.gravity_World_mm_s2.setZero();  // the preoperative shape already carries gravity; the patient is not tilted
  HardTruth h;
  const double amp = 2.0 + 2.0 * u(rng);
  const Eigen::Matrix3Xd field = smooth_field(p.mesh.rest_positions_World_mm, amp, rng);
  p.mesh.rest_positions_World_mm += field;
  h.preop_error_mm = amp;
  // the push site: an anterior organ-surface vertex at least 35 mm from every support
  const Eigen::Matrix3Xd& s = truth.organ_surface.positions_World_mm;
  Eigen::Matrix3Xd normal = Eigen::Matrix3Xd::Zero(3, s.cols());
  for (const auto& f : truth.organ_surface.tris) {
    const Eigen::Vector3d n = (s.col(f[1]) - s.col(f[0])).cross(s.col(f[2]) - s.col(f[0]));
    for (int v : f) normal.col(v) += n;
  }
  std::vector<int> sites;
  for (Eigen::Index v = 0; v < s.cols(); ++v) {
    if (normal.col(v).normalized().dot(kViewDir) < 0.6) continue;
    double dmin = 1e300;
    for (int f : p.fixed_vertices) dmin = std::min(dmin, (truth.problem.mesh.rest_positions_World_mm.col(f) - s.col(v)).norm());
    if (dmin > 35.0) sites.push_back(static_cast<int>(v));
  }
  if (sites.empty()) throw std::runtime_error("hard register bench: no anterior push site 35 mm from the supports");
  h.site = sites[std::uniform_int_distribution<std::size_t>(0, sites.size() - 1)(rng)];
  h.push_mm = 20.0 + 20.0 * u(rng);
  const double radius = 10.0 + 5.0 * u(rng);
  ModelConfig cfg;
  cfg.kind = "corotational_fem";
  cfg.integrator = "implicit_euler";
  cfg.linear_solver = "cholmod";
  cfg.refactor_every = 1;
  std::unique_ptr<TissueModel> model = make_tissue_model(p, cfg);
  const Eigen::Vector3d inward = -normal.col(h.site).normalized();
  // the surface's rest positions on the perturbed truth
  const Eigen::Matrix3Xd s_truth = truth.organ_embedding.apply(p.mesh, p.mesh.rest_positions_World_mm);
  struct Ramp {
    AttachmentId id;
    Eigen::Vector3d from, to;
  };
  std::vector<Ramp> ramps;
  int n = 0;
  for (Eigen::Index v = 0; v < s.cols(); ++v) n += (s.col(v) - s.col(h.site)).norm() < radius ? 1 : 0;
  for (Eigen::Index v = 0; v < s.cols(); ++v) {
    if ((s.col(v) - s.col(h.site)).norm() >= radius) continue;
    const Eigen::Vector3d p0 = s_truth.col(v);
    ramps.push_back({model->add_attachment({truth.organ_embedding.material_point(truth.problem.mesh, static_cast<int>(v)), p0, 600.0 / n}), p0,
                     p0 + h.push_mm * inward});
  }
  const Eigen::Matrix3Xd zero = Eigen::Matrix3Xd::Zero(3, model->positions_World_mm().cols());
  constexpr int kRampSteps = 12;
  for (int it = 0; it < 200; ++it) {
    const double f = std::min(1.0, (it + 1.0) / kRampSteps);
    for (const Ramp& r : ramps) model->set_attachment_target(r.id, r.from + f * (r.to - r.from));
    const Eigen::Matrix3Xd before = model->positions_World_mm();
    const StepSummary st = model->step(0.1);
    if (!st.healthy) throw std::runtime_error("hard register bench: the truth solve failed at step " + std::to_string(it) + ": " + st.warning);
    model->set_state(model->positions_World_mm(), zero);
    if (it >= kRampSteps && (model->positions_World_mm() - before).colwise().norm().maxCoeff() < 1e-3) break;
  }
  h.x = model->positions_World_mm();
  h.achieved_push_mm = (h.x - p.mesh.rest_positions_World_mm).colwise().norm().maxCoeff();
  return h;
}

}  // namespace

std::vector<RegisterHardRow> run_register_hard_bench(const RegisterHardOptions& o) {
  const Scene truth = load_scene(o.data_dir + "/" + o.scene_dir + "/" + o.truth_scene);
  const Scene reg = load_scene(o.data_dir + "/" + o.scene_dir + "/" + o.registration_scene);
  const auto tb = Clock::now();
  const auto basis = std::make_shared<const LoadBasis>(build_load_basis(reg, LoadBasisOptions{}));
  std::cerr << "load basis: " << basis->modes() << " modes in " << seconds_since(tb) << " s (built once, not in the case times)\n";
  std::vector<RegisterHardRow> rows;
  const TetMesh& tm = truth.problem.mesh;
  struct Split {
    std::string name;
    unsigned seed0;
    int cases;
  };
  const std::vector<Split> splits = o.quick ? std::vector<Split>{{"dev", 1, 1}} : std::vector<Split>{{"dev", 1, o.dev_cases}, {"held-out", 1001, o.heldout_cases}};
  for (const Split& split : splits)
    for (int c = 0; c < split.cases; ++c) {
      std::mt19937 rng(split.seed0 + static_cast<unsigned>(c));
      std::uniform_real_distribution<double> u(0.0, 1.0);
      const auto ts = Clock::now();
      const HardTruth h = solve_truth(truth, rng);
      std::cerr << split.name << " case " << c << ": push " << h.push_mm << " mm (achieved " << h.achieved_push_mm << "), preop error " << h.preop_error_mm
                << " mm, solved in " << seconds_since(ts) << " s\n";
      // targets: 50 interior points >= 5 mm deep and 10 organ-surface vertices, in the scene's (preoperative) shape
      const SurfaceIndex rest_surface(truth.organ_surface.positions_World_mm, truth.organ_surface.tris);
      Eigen::Matrix3Xd t_rest(3, 60), t_truth(3, 60);
      std::uniform_int_distribution<int> pick_tet(0, tm.num_tets() - 1);
      for (int k = 0; k < 50;) {
        const auto& t = tm.tets[static_cast<std::size_t>(pick_tet(rng))];
        Eigen::Vector4d w(u(rng) + 0.05, u(rng) + 0.05, u(rng) + 0.05, u(rng) + 0.05);
        w /= w.sum();
        Eigen::Vector3d pr = Eigen::Vector3d::Zero(), pt = Eigen::Vector3d::Zero();
        for (int j = 0; j < 4; ++j) {
          pr += w[j] * tm.rest_positions_World_mm.col(t[static_cast<std::size_t>(j)]);
          pt += w[j] * h.x.col(t[static_cast<std::size_t>(j)]);
        }
        if (rest_surface.closest(pr).distance_mm < 5.0) continue;
        t_rest.col(k) = pr;
        t_truth.col(k) = pt;
        ++k;
      }
      const Eigen::Matrix3Xd s_def = truth.organ_embedding.apply(tm, h.x);
      std::uniform_int_distribution<int> pick_v(0, static_cast<int>(s_def.cols()) - 1);
      for (int k = 50; k < 60; ++k) {
        const int v = pick_v(rng);
        t_rest.col(k) = truth.organ_surface.positions_World_mm.col(v);
        t_truth.col(k) = s_def.col(v);
      }
      const Embedding reg_targets = embed_points(reg.problem.mesh, t_rest, 5.0, "hard benchmark target");
      // the swab: 15-25 % around the push (the seed up to 15 mm off it), noise not told
      const double coverage = 0.15 + 0.10 * u(rng);
      const double noise = 0.5 + 1.0 * u(rng);
      std::normal_distribution<double> g(0.0, 1.0);
      const Eigen::Vector3d seed = s_def.col(h.site) + 15.0 * u(rng) * Eigen::Vector3d(g(rng), 0.0, g(rng)).normalized();
      SampledPatch patch = sample_patch(s_def, truth.organ_surface.tris, seed, kViewDir, coverage, 3.5, rng);
      Eigen::Matrix3Xd data = patch.points_mm;
      add_noise(data, noise, rng);
      add_outliers(data, s_def, 0.03, 20.0, 5.0, rng);
      for (const bool aligned : {true, false}) {
        const Eigen::Isometry3d X_true = aligned ? Eigen::Isometry3d::Identity() : random_rigid(15.0 + 15.0 * u(rng), 80.0, rng);
        const Eigen::Matrix3Xd truth_Intraop = X_true * t_truth;
        RegistrationRequest rq;
        rq.points_Intraop_mm = X_true * data;
        rq.prebuilt_basis = basis;
        rq.estimate_noise = true;
        if (aligned) {
          rq.X_IntraopModel_initial = Eigen::Isometry3d::Identity();
          rq.initial_pose_name = "identity";
        } else {
          const Eigen::Matrix3Xd& sr = truth.organ_surface.positions_World_mm;
          Eigen::Index i0 = 0, i1 = 0, i2 = 0, i3 = 0;
          sr.row(0).minCoeff(&i0);
          sr.row(0).maxCoeff(&i1);
          sr.row(1).minCoeff(&i2);
          sr.row(2).maxCoeff(&i3);
          const double e = 3.0 / std::sqrt(3.0);
          for (const Eigen::Index v : {i0, i1, i2, i3})
            rq.landmarks.push_back({"lm" + std::to_string(v), sr.col(v), X_true * s_def.col(v) + e * Eigen::Vector3d(g(rng), g(rng), g(rng)), 0});
        }
        auto add = [&](const std::string& method, const Eigen::Matrix3Xd& predicted, double wall, double noise_est, const std::string& note) {
          RegisterHardRow r;
          r.split = split.name;
          r.case_id = c;
          r.aligned = aligned;
          r.push_mm = h.push_mm;
          r.achieved_push_mm = h.achieved_push_mm;
          r.coverage = patch.coverage;
          r.noise_mm = noise;
          r.preop_error_mm = h.preop_error_mm;
          r.points = static_cast<int>(data.cols());
          r.method = method;
          r.tre = tre_stats(predicted, truth_Intraop);
          r.noise_estimated_mm = noise_est;
          r.wall_s = wall;
          r.note = note;
          rows.push_back(r);
          std::cerr << "  " << (aligned ? "aligned   " : "misaligned") << " " << method << ": TRE mean " << r.tre.mean << " max " << r.tre.max << " mm, "
                    << wall << " s" << (note.empty() ? "" : " (" + note + ")") << "\n";
          return r.tre.mean;
        };
        double reference = 0.0;
        if (aligned) {
          reference = add("none", t_rest, 0.0, 0.0, "no registration");
        } else {
          const LandmarkFit lf = register_landmarks(rq.landmarks);
          reference = add("landmark_rigid", lf.X_IntraopModel * t_rest, 0.0, 0.0, "");
        }
        for (const bool prior : {false, true}) {
          rq.prior.enabled = prior;
          const RegistrationResult res = register_patient(reg, rq);
          const std::string sfx = prior ? "_prior" : "";
          add("surface_rigid" + sfx, res.icp.X_IntraopModel * t_rest, res.icp.summary.wall_time_s,
              res.noise_mm, res.icp.summary.termination + (res.icp.start_kept ? "; start kept" : ""));
          std::string note = "kept " + res.kept_stage + ": " + res.kept_reason;
          for (const auto& t : res.posterior.unconstrained_text) note += "; unconstrained: " + t;
          add("loads" + sfx, carry_to_intraop(reg, reg_targets, res), res.wall_time_s, res.noise_mm, note);
        }
        for (auto it = rows.end() - 5; it != rows.end(); ++it) it->reference_mean_mm = reference;
      }
    }
  return rows;
}

void write_register_hard_csv(const std::string& path, const std::vector<RegisterHardRow>& rows) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error(path + ": cannot open for writing");
  out << "split,case,aligned,push_mm,achieved_push_mm,coverage,noise_mm,noise_estimated_mm,preop_error_mm,points,method,tre_mean_mm,tre_median_mm,"
         "tre_p90_mm,tre_max_mm,reference_mean_mm,worse_than_reference,wall_s,note\n";
  for (const auto& r : rows) {
    std::string note = r.note;
    std::replace(note.begin(), note.end(), ',', ';');
    std::replace(note.begin(), note.end(), '"', '\'');
    out << r.split << ',' << r.case_id << ',' << (r.aligned ? 1 : 0) << ',' << r.push_mm << ',' << r.achieved_push_mm << ',' << r.coverage << ','
        << r.noise_mm << ',' << r.noise_estimated_mm << ',' << r.preop_error_mm << ',' << r.points << ',' << r.method << ',' << r.tre.mean << ','
        << r.tre.median << ',' << r.tre.p90 << ',' << r.tre.max << ',' << r.reference_mean_mm << ',' << (r.tre.mean > r.reference_mean_mm ? 1 : 0)
        << ',' << r.wall_s << ",\"" << note << "\"\n";
  }
}

}  // namespace arnav::host
