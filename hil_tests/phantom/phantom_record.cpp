#include "hil_tests/phantom/phantom_record.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "host/scene/embedding.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::hil {

double PhantomScript::pull_fraction(double t_s) const {
  const double period = ramp_s + hold_s + ramp_s + rest_s;
  if (t_s < start_s) return 0.0;
  const double u = std::fmod(t_s - start_s, period);
  const auto smooth = [](double x) { return 0.5 - 0.5 * std::cos(std::numbers::pi * std::clamp(x, 0.0, 1.0)); };
  if (u < ramp_s) return smooth(u / ramp_s);
  if (u < ramp_s + hold_s) return 1.0;
  if (u < 2 * ramp_s + hold_s) return 1.0 - smooth((u - ramp_s - hold_s) / ramp_s);
  return 0.0;
}

camera_sim::PhantomRecording record_phantom(const std::string& scene_path, const PhantomScript& script, PhantomRecordStats& stats,
                                            const std::function<void(int, int)>& progress) {
  if (!(script.fps > 0 && script.fps <= 240)) throw std::invalid_argument("phantom script: fps must be in (0, 240]");
  if (!(script.duration_s > 0 && script.duration_s <= 600)) throw std::invalid_argument("phantom script: duration must be in (0, 600] s");
  if (!(script.grasp_radius_mm > 0)) throw std::invalid_argument("phantom script: grasp radius must be > 0 mm");
  if (!(script.ramp_s > 0) || script.hold_s < 0 || script.rest_s < 0 || script.start_s < 0)
    throw std::invalid_argument("phantom script: ramp must be > 0 s, hold/rest/start >= 0 s");
  if (script.substeps < 1 || script.substeps > 100) throw std::invalid_argument("phantom script: substeps must be in [1, 100]");

  host::Scene scene = host::load_scene(scene_path);
  if (scene.tumours.empty()) throw std::runtime_error(scene_path + ": the phantom's scene needs a tumour (its centroid is the ground truth)");
  if (!script.gravity) scene.problem.gravity_World_mm_s2.setZero();
  auto model = host::make_tissue_model(scene.problem, scene.model);
  const host::TetMesh& mesh = scene.problem.mesh;
  const Eigen::Matrix3Xd& rest = mesh.rest_positions_World_mm;
  const Eigen::Matrix3Xd surface_rest = scene.organ_embedding.apply(mesh, rest);
  stats.model = model->name();
  stats.volume_vertices = static_cast<int>(rest.cols());
  stats.volume_tets = static_cast<int>(mesh.tets.size());
  stats.surface_vertices = static_cast<int>(surface_rest.cols());

  // Grasp: surface vertices near the surface point closest to grasp_near_mm.
  Eigen::Index nearest = 0;
  (surface_rest.colwise() - script.grasp_near_mm).colwise().squaredNorm().minCoeff(&nearest);
  const Eigen::Vector3d grasp_centre = surface_rest.col(nearest);
  std::vector<int> grasped;
  for (Eigen::Index i = 0; i < surface_rest.cols(); ++i)
    if ((surface_rest.col(i) - grasp_centre).norm() <= script.grasp_radius_mm) grasped.push_back(static_cast<int>(i));
  stats.grasped_vertices = static_cast<int>(grasped.size());
  stats.grasp_centre_mm = grasp_centre;
  stats.surface_min_mm = surface_rest.rowwise().minCoeff();
  stats.surface_max_mm = surface_rest.rowwise().maxCoeff();
  // Outward normal of the patch (area-weighted triangle normals touching it) orients the tool.
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  for (const auto& t : scene.organ_surface.tris) {
    const Eigen::Vector3d a = surface_rest.col(t[0]), b = surface_rest.col(t[1]), c = surface_rest.col(t[2]);
    if ((a - grasp_centre).norm() <= script.grasp_radius_mm) normal += (b - a).cross(c - a);
  }
  if (!(normal.norm() > 0)) normal = -Eigen::Vector3d::UnitZ();
  normal.normalize();
  std::vector<host::AttachmentId> ids;
  for (int v : grasped) {
    host::AttachmentSpec spec;
    spec.point = scene.organ_embedding.material_point(mesh, v);
    spec.target_World_mm = surface_rest.col(v);
    spec.stiffness_mN_per_mm = script.grasp_stiffness_mN_per_mm;
    ids.push_back(model->add_attachment(spec));
  }
  // Tool frame: origin (the jaws / blade tip) at the grasp centre + pull, z along the
  // patch's outward normal (the shaft points away from the tissue).
  Eigen::Isometry3d X_ModelToolRest = Eigen::Isometry3d::Identity();
  {
    const Eigen::Vector3d z = normal;
    const Eigen::Vector3d helper = std::abs(z.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
    const Eigen::Vector3d x = helper.cross(z).normalized();
    X_ModelToolRest.linear().col(0) = x;
    X_ModelToolRest.linear().col(1) = z.cross(x);
    X_ModelToolRest.linear().col(2) = z;
    X_ModelToolRest.translation() = grasp_centre;
  }

  // Targets: the tumour centroid and interior points around it (kept when inside the volume).
  camera_sim::PhantomRecording rec;
  rec.tool_names = {"grasper"};
  rec.target_names = {"tumour_centroid"};
  const Eigen::Vector3d c0 = host::tumour_centroid_World_mm(scene, 0, rest);
  stats.tumour_rest_mm = c0;
  std::vector<Eigen::Vector3d> extra;
  const char* axis_names[3] = {"x", "y", "z"};
  std::vector<std::string> extra_names;
  for (int a = 0; a < 3; ++a) {
    for (int sgn : {-1, 1}) {
      const Eigen::Vector3d p = c0 + sgn * script.interior_offset_mm * Eigen::Vector3d::Unit(a);
      try {
        host::embed_points(mesh, p, 0.0, "interior target");
        extra.push_back(p);
        extra_names.push_back(std::string("tumour_") + (sgn < 0 ? "minus_" : "plus_") + axis_names[a]);
      } catch (const std::exception&) {
        // outside the volume: not an interior target
      }
    }
  }
  host::Embedding extra_embedding;
  if (!extra.empty()) {
    Eigen::Matrix3Xd pts(3, static_cast<Eigen::Index>(extra.size()));
    for (std::size_t i = 0; i < extra.size(); ++i) pts.col(static_cast<Eigen::Index>(i)) = extra[i];
    extra_embedding = host::embed_points(mesh, pts, 0.0, "interior target");
    for (const auto& n : extra_names) rec.target_names.push_back(n);
  }
  rec.vertex_count = static_cast<int>(surface_rest.cols());
  for (const auto& t : scene.organ_surface.tris) rec.faces.emplace_back(t[0], t[1], t[2]);

  const int frames = static_cast<int>(std::floor(script.duration_s * script.fps + 1e-9)) + 1;
  const double dt = 1.0 / script.fps / script.substeps;
  std::vector<double> step_ms;
  int written = 0;
  for (int k = 0; k < frames; ++k) {
    const double t = k / script.fps;
    if (script.skip_rest_frames && k > 0 && k + 1 < frames && (k + 1) / script.fps <= script.start_s) continue;  // at rest, and the next one too
    if (k > 0) {
      for (int s = 1; s <= script.substeps; ++s) {
        const double ts = (k - 1) / script.fps + s * dt;
        const Eigen::Vector3d pull = script.pull_fraction(ts) * script.pull_mm;
        for (std::size_t i = 0; i < ids.size(); ++i)
          model->set_attachment_target(ids[i], surface_rest.col(grasped[i]) + pull);
        const auto t0 = std::chrono::steady_clock::now();
        const host::StepSummary sum = model->step(dt);
        step_ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        if (!sum.healthy && stats.healthy) {
          stats.healthy = false;
          stats.warning = "t=" + std::to_string(ts) + " s: " + sum.warning;
        }
      }
    }
    const Eigen::Matrix3Xd& x = model->positions_World_mm();
    camera_sim::PhantomFrame f;
    f.t_s = t;
    Eigen::Isometry3d X = X_ModelToolRest;
    X.translation() += script.pull_fraction(t) * script.pull_mm;
    f.X_ModelTool.push_back(X);
    const Eigen::Vector3d c = host::tumour_centroid_World_mm(scene, 0, x);
    f.targets_Model_mm.push_back(c);
    if (!extra.empty()) {
      const Eigen::Matrix3Xd e = extra_embedding.apply(mesh, x);
      for (Eigen::Index i = 0; i < e.cols(); ++i) f.targets_Model_mm.push_back(e.col(i));
    }
    f.vertices_Model_mm = scene.organ_embedding.apply(mesh, x);
    stats.max_tumour_displacement_mm = std::max(stats.max_tumour_displacement_mm, (c - c0).norm());
    stats.max_surface_displacement_mm =
        std::max(stats.max_surface_displacement_mm, (f.vertices_Model_mm - surface_rest).colwise().norm().maxCoeff());
    rec.frames.push_back(std::move(f));
    ++written;
    if (progress) progress(k, frames);
  }
  stats.frames = written;
  if (!step_ms.empty()) {
    std::nth_element(step_ms.begin(), step_ms.begin() + static_cast<std::ptrdiff_t>(step_ms.size() / 2), step_ms.end());
    stats.median_step_ms = step_ms[step_ms.size() / 2];
  }
  return rec;
}

CentroidComparison compare_tumour_centroids(const camera_sim::PhantomRecording& reference, const camera_sim::PhantomRecording& model) {
  if (reference.frames.size() != model.frames.size() || reference.frames.empty())
    throw std::invalid_argument("compare: the recordings have different frame counts");
  std::vector<double> m, r;
  const Eigen::Vector3d rest = reference.frames.front().targets_Model_mm.at(0);
  for (std::size_t k = 0; k < reference.frames.size(); ++k) {
    if (std::abs(reference.frames[k].t_s - model.frames[k].t_s) > 1e-9) throw std::invalid_argument("compare: frame times differ");
    const Eigen::Vector3d truth = reference.frames[k].targets_Model_mm.at(0);
    m.push_back((model.frames[k].targets_Model_mm.at(0) - truth).norm());
    r.push_back((rest - truth).norm());
  }
  const auto summarise = [](std::vector<double> v, double& mean, double& p95, double& max) {
    double sum = 0;
    for (double x : v) sum += x;
    mean = sum / static_cast<double>(v.size());
    std::sort(v.begin(), v.end());
    p95 = v[std::min(v.size() - 1, static_cast<std::size_t>(0.95 * static_cast<double>(v.size() - 1) + 0.5))];
    max = v.back();
  };
  CentroidComparison c;
  summarise(m, c.model_mean_mm, c.model_p95_mm, c.model_max_mm);
  summarise(r, c.rigid_mean_mm, c.rigid_p95_mm, c.rigid_max_mm);
  return c;
}

}  // namespace arnav::hil
