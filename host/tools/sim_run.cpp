#include "host/tools/sim_run.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <vector>

#include "host/scene/mesh_io.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

std::string numbered(const std::string& dir, const std::string& stem, int frame, const std::string& ext) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "_%04d.", frame);
  return dir + "/" + stem + buf + ext;
}

void write_frame(const Scene& scene, const SimRunOptions& o, int frame, const Eigen::Matrix3Xd& x) {
  if (o.out_dir.empty()) return;
  const Eigen::Matrix3Xd surface = scene.organ_embedding.apply(scene.problem.mesh, x);
  if (o.format == "obj") {
    write_obj(numbered(o.out_dir, "organ", frame, "obj"), surface, scene.organ_surface.tris);
    for (const auto& t : scene.tumours)
      write_obj(numbered(o.out_dir, "tumour_" + t.name, frame, "obj"), t.embedding.apply(scene.problem.mesh, x), t.rest.tris);
  } else {
    write_vtk_volume(numbered(o.out_dir, "volume", frame, "vtk"), scene.problem.mesh, x);
    write_vtk_surface(numbered(o.out_dir, "organ", frame, "vtk"), surface, scene.organ_surface.tris);
    for (const auto& t : scene.tumours)
      write_vtk_surface(numbered(o.out_dir, "tumour_" + t.name, frame, "vtk"), t.embedding.apply(scene.problem.mesh, x), t.rest.tris);
    if (scene.vessels)
      write_vtk_lines(numbered(o.out_dir, "vessels", frame, "vtk"), scene.vessels->embedding.apply(scene.problem.mesh, x),
                      scene.vessels->rest.segments, scene.vessels->rest.radius_mm);
  }
}

}  // namespace

SimRunResult run_scene(const Scene& scene, const SimRunOptions& o, std::ostream& csv) {
  if (!o.out_dir.empty()) std::filesystem::create_directories(o.out_dir);
  std::unique_ptr<TissueModel> model = make_tissue_model(scene.problem, scene.model);
  const Eigen::Matrix3Xd& rest = scene.problem.mesh.rest_positions_World_mm;
  const bool has_tumour = !scene.tumours.empty();
  const Eigen::Vector3d tumour0 = has_tumour ? tumour_centroid_World_mm(scene, 0, rest) : Eigen::Vector3d::Zero();
  csv << "frame,time_s,wall_ms,iterations,initial_residual,final_residual,termination,kinetic_energy,elastic_energy,"
         "healthy,max_displacement_mm,tumour_dx_mm,tumour_dy_mm,tumour_dz_mm,inverted_elements,warning\n";
  write_frame(scene, o, 0, rest);
  SimRunResult result;
  std::vector<double> wall;
  double inverted_run_s = 0.0;
  for (int f = 1; f <= o.frames; ++f) {
    const StepSummary s = model->step(scene.time_step_s);
    const Eigen::Matrix3Xd& x = model->positions_World_mm();
    wall.push_back(s.wall_time_ms);
    result.frames_run = f;
    result.max_displacement_mm = (x - rest).colwise().norm().maxCoeff();
    if (has_tumour) result.tumour_displacement_mm = tumour_centroid_World_mm(scene, 0, x) - tumour0;
    std::string warning = s.warning;
    std::replace(warning.begin(), warning.end(), ',', ';');
    csv << f << ',' << f * scene.time_step_s << ',' << s.wall_time_ms << ',' << s.iterations << ',' << s.initial_residual << ','
        << s.final_residual << ',' << s.termination << ',' << s.kinetic_energy << ',' << s.elastic_energy << ',' << (s.healthy ? 1 : 0)
        << ',' << result.max_displacement_mm << ',' << result.tumour_displacement_mm.x() << ',' << result.tumour_displacement_mm.y()
        << ',' << result.tumour_displacement_mm.z() << ',' << s.inverted_elements << ',' << warning << '\n';
    if (s.inverted_elements > 0) {
      ++result.frames_with_inverted;
      inverted_run_s += scene.time_step_s;
      result.worst_inverted_run_s = std::max(result.worst_inverted_run_s, inverted_run_s);
      result.peak_inverted = std::max(result.peak_inverted, s.inverted_elements);
    } else {
      inverted_run_s = 0.0;
    }
    if (f % 10 == 0 || f == o.frames || !s.healthy)
      for (const ElementMeasure& m : model->element_measures()) result.peak_strain = std::max(result.peak_strain, m.max_principal_strain);
    if (f == o.frames || f % std::max(1, o.write_every) == 0 || !s.healthy) write_frame(scene, o, f, x);
    if (!s.healthy) {
      result.healthy = false;
      result.warning = s.warning.empty() ? "unhealthy step" : s.warning;
      break;
    }
  }
  if (!wall.empty()) {
    std::nth_element(wall.begin(), wall.begin() + wall.size() / 2, wall.end());
    result.median_step_ms = wall[wall.size() / 2];
  }
  return result;
}

}  // namespace arnav::host
