#include "host/tools/sim_run.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <vector>

#include "host/cut/cut_session.hpp"
#include "host/cut/mesh_checks.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/mesh/surface_shapes.hpp"
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

SimRunResult run_scene_with_scalpel(const Scene& scene, const SimRunOptions& o, std::ostream& csv) {
  using namespace cut;
  const CuttingSpec& spec = *scene.cutting;
  CutSessionSettings settings = cut_settings_from(spec);
  const std::unique_ptr<CutSession> session_ptr = make_cut_session(scene, scene.model, settings);
  CutSession& session = *session_ptr;
  std::ofstream events;
  if (!o.out_dir.empty()) {
    events.open(o.out_dir + "/cut_events.csv");
    events << "frame,time_s,kind,structure,distance_mm,x_mm,y_mm,z_mm\n";
  }
  auto write = [&](int frame) {
    if (o.out_dir.empty()) return;
    const Eigen::Matrix3Xd& x = session.positions_World_mm();
    const TetMesh& mesh = session.mesh();
    const auto& surface = session.surface_tris();
    if (o.format == "obj") {
      write_obj(numbered(o.out_dir, "organ", frame, "obj"), x, surface);
    } else {
      write_vtk_volume(numbered(o.out_dir, "volume", frame, "vtk"), mesh, x);
      write_vtk_surface(numbered(o.out_dir, "organ", frame, "vtk"), x, surface);
    }
    for (std::size_t k = 0; k < session.tumours().size(); ++k) {
      const Eigen::Matrix3Xd p = session.tumours()[k].embedding.apply(mesh, x);
      const std::string stem = "tumour_" + session.tumours()[k].name;
      if (o.format == "obj") write_obj(numbered(o.out_dir, stem, frame, "obj"), p, session.tumour_tris()[k]);
      else write_vtk_surface(numbered(o.out_dir, stem, frame, "vtk"), p, session.tumour_tris()[k]);
    }
    if (session.vessels() && o.format != "obj") {
      std::vector<double> radius;  // split nodes take the radius of the node they came from
      for (int src : session.vessel_node_source()) radius.push_back(scene.vessels->rest.radius_mm[static_cast<std::size_t>(src)]);
      write_vtk_lines(numbered(o.out_dir, "vessels", frame, "vtk"), session.vessels()->embedding.apply(mesh, x), session.vessel_segments(), radius);
    }
  };
  const bool has_tumour = !scene.tumours.empty();
  auto tumour_centroid = [&]() {
    return closed_surface_centroid(session.tumours()[0].embedding.apply(session.mesh(), session.positions_World_mm()), session.tumour_tris()[0]);
  };
  const Eigen::Vector3d tumour0 = has_tumour ? tumour_centroid() : Eigen::Vector3d::Zero();
  csv << "frame,time_s,wall_ms,iterations,initial_residual,final_residual,termination,kinetic_energy,elastic_energy,"
         "healthy,max_displacement_mm,tumour_dx_mm,tumour_dy_mm,tumour_dz_mm,warning,"
         "cutting,contact_depth_mm,topology_update_ms,model_rebuild_ms,tets,vertices,tets_cut,tets_added,pieces,events\n";
  write(0);
  SimRunResult result;
  std::vector<double> wall;
  int pieces = 1;
  for (int f = 1; f <= o.frames; ++f) {
    const ScalpelSample blade = o.scalpel->at(f * scene.time_step_s);
    const CutFrameReport cr = session.apply_blade(blade.blade, blade.cutting);
    if (cr.cut.topology_changed) pieces = static_cast<int>(check_cut_mesh(session.mesh()).piece_volume_mm3.size());
    for (const auto& e : cr.events) {
      ++result.cut_events;
      if (events.is_open())
        events << f << ',' << f * scene.time_step_s << ',' << e.kind << ',' << e.structure << ',' << e.distance_mm << ','
               << e.location_World_mm.x() << ',' << e.location_World_mm.y() << ',' << e.location_World_mm.z() << '\n';
    }
    const StepSummary s = session.step(scene.time_step_s);
    const Eigen::Matrix3Xd& x = session.positions_World_mm();
    const Eigen::Matrix3Xd& rest = session.mesh().rest_positions_World_mm;
    wall.push_back(s.wall_time_ms + cr.cut.update_ms + cr.rebuild_ms + cr.reembed_ms);
    result.frames_run = f;
    result.max_displacement_mm = (x - rest).colwise().norm().maxCoeff();
    result.max_topology_update_ms = std::max(result.max_topology_update_ms, cr.cut.update_ms);
    if (has_tumour) result.tumour_displacement_mm = tumour_centroid() - tumour0;
    std::string warning = s.warning;
    std::replace(warning.begin(), warning.end(), ',', ';');
    csv << f << ',' << f * scene.time_step_s << ',' << wall.back() << ',' << s.iterations << ',' << s.initial_residual << ','
        << s.final_residual << ',' << s.termination << ',' << s.kinetic_energy << ',' << s.elastic_energy << ',' << (s.healthy ? 1 : 0)
        << ',' << result.max_displacement_mm << ',' << result.tumour_displacement_mm.x() << ',' << result.tumour_displacement_mm.y()
        << ',' << result.tumour_displacement_mm.z() << ',' << warning << ',' << (blade.cutting ? 1 : 0) << ','
        << (cr.contact.tip_inside ? cr.contact.depth_mm : 0.0) << ',' << cr.cut.update_ms << ',' << cr.rebuild_ms << ','
        << session.mesh().num_tets() << ',' << session.mesh().num_vertices() << ',' << cr.cut.tets_cut << ',' << cr.cut.tets_added << ','
        << pieces << ',' << cr.events.size() << '\n';
    if (f == o.frames || f % std::max(1, o.write_every) == 0 || !s.healthy) write(f);
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
  result.tets = session.mesh().num_tets();
  result.vertices = session.mesh().num_vertices();
  result.pieces = pieces;
  return result;
}

}  // namespace

SimRunResult run_scene(const Scene& scene, const SimRunOptions& o, std::ostream& csv) {
  if (!o.out_dir.empty()) std::filesystem::create_directories(o.out_dir);
  if (o.scalpel) {
    if (!scene.cutting) throw std::invalid_argument("a scalpel path needs the scene to declare a 'cutting:' section (docs/cut.md)");
    return run_scene_with_scalpel(scene, o, csv);
  }
  check_setting_holds(scene.problem, scene.model, scene.time_step_s);  // refused at load, not stopped mid-run
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
    if (s.warning.find("step control") != std::string::npos) ++result.step_control_frames;
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
