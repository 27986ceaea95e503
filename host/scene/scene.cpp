#include "host/scene/scene.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <filesystem>
#include <set>
#include <sstream>

#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/scene/scene_spec.hpp"
#include "host/mesh/surface_decimate.hpp"
#include "host/mesh/surface_shapes.hpp"
#include "host/mesh/tetgen_mesher.hpp"

namespace arnav::host {
namespace {

std::string resolve(const std::string& scene_path, const std::string& file) {
  const std::filesystem::path p(file);
  if (p.is_absolute()) return file;
  return (std::filesystem::path(scene_path).parent_path() / p).lexically_normal().string();
}

void transform(Eigen::Matrix3Xd& x, const FileSpec& f) {
  x *= f.scale;
  x.colwise() += f.translate_mm;
}

// Volume-weighted centroid of a closed outward surface (divergence theorem).
Eigen::Vector3d surface_centroid(const TriMesh& s) {
  double volume = 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& t : s.tris) {
    const Eigen::Vector3d a = s.positions_World_mm.col(t[0]), b = s.positions_World_mm.col(t[1]), d = s.positions_World_mm.col(t[2]);
    const double v = a.dot(b.cross(d)) / 6.0;
    volume += v;
    c += v * (a + b + d) / 4.0;
  }
  return c / volume;
}

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

}  // namespace

void check_scene_text(const std::string& yaml_text, const std::string& source) { parse_scene_spec(yaml_text, source); }

Scene load_scene(const std::string& path) {
  const SceneSpec spec = parse_scene_spec(read_text_file(path), path);
  Scene scene;
  scene.source = path;
  auto at = [&](int line, const std::string& what, const std::string& fix) { throw_load_error(path, line, what, fix); };

  // Organ surface (display, and the TetGen input when the volume is generated).
  const std::string organ_path = resolve(path, spec.organ.path);
  SurfaceCheck organ_check;
  scene.organ_surface = load_surface(organ_path, &organ_check);
  transform(scene.organ_surface.positions_World_mm, spec.organ);
  if (organ_check.components > 1) {
    if (!spec.keep_largest_component) {
      at(spec.organ.line, organ_path + " has " + std::to_string(organ_check.components) +
                              " separate closed components (an organ is one; small ones are usually segmentation bubbles)",
         "remove the extra components, or set organ.keep_largest_component: true to drop all but the largest");
    }
    const int before = static_cast<int>(scene.organ_surface.positions_World_mm.cols());
    const int removed = keep_largest_component(scene.organ_surface);
    scene.notes.push_back(organ_path + ": kept the largest of " + std::to_string(organ_check.components) + " components (" +
                          std::to_string(before - removed) + " vertices; dropped " + std::to_string(removed) + ")");
  }
  if (organ_check.flipped) scene.notes.push_back(organ_path + ": surface was oriented inward; flipped to outward");
  if (organ_check.removed_unused_vertices > 0)
    scene.notes.push_back(organ_path + ": dropped " + std::to_string(organ_check.removed_unused_vertices) + " unused vertices");

  // Volume mesh.
  TetMesh& mesh = scene.problem.mesh;
  if (spec.volume.file) {
    const std::string vpath = resolve(path, spec.volume.file->path);
    TetMeshCheck check;
    mesh = load_volume(vpath, &check);
    transform(mesh.rest_positions_World_mm, *spec.volume.file);
    scene.notes.push_back(vpath + ": " + std::to_string(mesh.num_vertices()) + " vertices, " + std::to_string(mesh.num_tets()) +
                          " tetrahedra, min quality " + fmt(check.min_quality));
  } else {
    TriMesh input = scene.organ_surface;
    if (spec.volume.decimate_surface_to > 0 && spec.volume.decimate_surface_to < input.positions_World_mm.cols()) {
      const DecimationReport rep = decimate_surface(input, spec.volume.decimate_surface_to);
      scene.notes.push_back("organ surface decimated from " + std::to_string(rep.input_vertices) + " to " +
                            std::to_string(rep.output_vertices) + " vertices (max quadric error " + fmt(std::sqrt(rep.max_error_mm2)) + " mm)");
      validate_closed_surface(input, organ_path + " (decimated)");
    }
    TetGenReport rep;
    mesh = tetrahedralize_surface(input, *spec.volume.tetgen, organ_path, &rep);
    scene.notes.push_back("TetGen " + rep.switches + ": " + std::to_string(mesh.num_vertices()) + " vertices, " +
                          std::to_string(mesh.num_tets()) + " tetrahedra in " + fmt(rep.wall_time_ms) + " ms");
  }
  if (spec.volume.peel_boundary_slivers_deg > 0) {
    double thickness_mm = 0.0;
    const int peeled = peel_boundary_slivers(mesh, spec.volume.peel_boundary_slivers_deg, &thickness_mm);
    if (peeled > 0) {
      validate_tet_mesh(mesh, organ_path + " (volume after peeling boundary slivers)");
      scene.notes.push_back("peeled " + std::to_string(peeled) + " boundary slivers (dihedral angle below " +
                            fmt(spec.volume.peel_boundary_slivers_deg) + " deg): the boundary moved by at most " + fmt(thickness_mm) +
                            " mm; " + std::to_string(mesh.num_tets()) + " tetrahedra");
    }
  }
  scene.mesh_quality = tet_mesh_quality(mesh);
  scene.notes.push_back("rest mesh quality: " + describe(scene.mesh_quality));
  if (spec.volume.min_dihedral_required_deg > 0 && scene.mesh_quality.min_dihedral_deg < spec.volume.min_dihedral_required_deg) {
    const auto& w = mesh.tets[scene.mesh_quality.worst_tet];
    const Eigen::Vector3d c = 0.25 * (mesh.rest_positions_World_mm.col(w[0]) + mesh.rest_positions_World_mm.col(w[1]) +
                                      mesh.rest_positions_World_mm.col(w[2]) + mesh.rest_positions_World_mm.col(w[3]));
    at(spec.volume.min_dihedral_required_line,
       "the volume mesh has a dihedral angle of " + fmt(scene.mesh_quality.min_dihedral_deg) + " degrees (tet near (" + fmt(c.x()) +
           ", " + fmt(c.y()) + ", " + fmt(c.z()) + ") mm), below volume.min_dihedral_required_deg " +
           fmt(spec.volume.min_dihedral_required_deg) + " (" + std::to_string(scene.mesh_quality.slivers) + " slivers)",
       "improve the mesh: volume.tetgen.min_dihedral_deg (e.g. 10) and optimisation_level (e.g. 7), or lower the requirement");
  }
  const int nv = mesh.num_vertices();

  // Tumours: closed surfaces that must lie inside the volume.
  for (const auto& t : spec.tumours) {
    EmbeddedSurface e;
    e.name = t.name;
    std::string where = path + ":" + std::to_string(t.line) + " (tumour '" + t.name + "')";
    if (t.surface) {
      where = resolve(path, t.surface->path);
      e.rest = load_surface(where);
      transform(e.rest.positions_World_mm, *t.surface);
    } else {
      e.rest = make_ellipsoid_surface(t.center_mm, t.radii_mm, t.subdivisions);
    }
    e.embedding = embed_points(mesh, e.rest.positions_World_mm, 1e-6, where);
    e.rest_centroid_World_mm = surface_centroid(e.rest);
    scene.tumours.push_back(std::move(e));
  }

  // Regions: every tet starts in "default"; rules apply in order, later rules win.
  mesh.region_names = {"default"};
  mesh.tet_region.assign(mesh.tets.size(), 0);
  for (const auto& rule : spec.regions) {
    int index = -1;
    for (std::size_t i = 0; i < mesh.region_names.size(); ++i)
      if (mesh.region_names[i] == rule.name) index = static_cast<int>(i);
    if (index < 0) {
      index = static_cast<int>(mesh.region_names.size());
      mesh.region_names.push_back(rule.name);
    }
    const TriMesh* inside = nullptr;
    for (const auto& t : scene.tumours)
      if (t.name == rule.inside) inside = &t.rest;
    int count = 0;
    BoxSpec bounds;  // the tumour's bounding box: cheap rejection before the winding number
    if (inside) bounds = {inside->positions_World_mm.rowwise().minCoeff(), inside->positions_World_mm.rowwise().maxCoeff()};
    for (int k = 0; k < mesh.num_tets(); ++k) {
      Eigen::Vector3d c = Eigen::Vector3d::Zero();
      for (int v : mesh.tets[k]) c += mesh.rest_positions_World_mm.col(v) / 4.0;
      const bool selected = rule.box ? rule.box->contains(c) : bounds.contains(c) && winding_number(*inside, c) > 0.5;
      if (selected) {
        mesh.tet_region[k] = index;
        ++count;
      }
    }
    if (count == 0)
      at(rule.line, "region '" + rule.name + "' selects no tetrahedron", "move its box or tumour inside the organ, or refine the mesh");
    scene.notes.push_back("region '" + rule.name + "': " + std::to_string(count) + " tetrahedra");
  }
  scene.problem.region_materials.resize(mesh.region_names.size());
  for (std::size_t i = 0; i < mesh.region_names.size(); ++i) {
    bool found = false;
    for (const auto& m : spec.materials)
      if (m.name == mesh.region_names[i]) scene.problem.region_materials[i] = m.material, found = true;
    if (!found) at(0, "region '" + mesh.region_names[i] + "' has no material", "add materials." + mesh.region_names[i]);
  }

  // Vessels: display always; beams only when the scene asks for them.
  if (spec.vessels) {
    EmbeddedVessels v;
    std::string where = path + ":" + std::to_string(spec.vessels->line) + " (vessels)";
    if (spec.vessels->file) {
      where = resolve(path, spec.vessels->file->path);
      v.rest = parse_vessel_tree(read_text_file(where), where);
      transform(v.rest.nodes_World_mm, *spec.vessels->file);
    } else {
      v.rest = spec.vessels->inline_tree;
    }
    v.embedding = embed_points(mesh, v.rest.nodes_World_mm, 1e-6, where);
    if (spec.vessels->beams) {
      scene.problem.vessels = v.rest;
      bool found = false;
      for (const auto& m : spec.materials)
        if (m.name == "vessels") scene.problem.vessel_material = m.material, found = true;
      if (!found) at(spec.vessels->line, "vessels with mechanics: beams need a material", "add materials.vessels (vessel wall ~ 500 kPa)");
    }
    scene.vessels = std::move(v);
  }

  // Fixed vertices (ligaments, attachments to the body).
  std::vector<char> on_surface(nv, 0);
  for (const auto& f : mesh.surface_tris)
    for (int v : f) on_surface[v] = 1;
  std::set<int> fixed;
  for (const auto& rule : spec.fixed) {
    std::set<int> picked;
    if (rule.box) {
      for (int v = 0; v < nv; ++v)
        if (rule.box->contains(mesh.rest_positions_World_mm.col(v))) picked.insert(v);
    } else if (!rule.region.empty()) {
      for (int k = 0; k < mesh.num_tets(); ++k)
        if (mesh.region_names[mesh.tet_region[k]] == rule.region) picked.insert(mesh.tets[k].begin(), mesh.tets[k].end());
    } else {
      for (int v : rule.vertices) {
        if (v >= nv)
          at(rule.line, "fixed vertex " + std::to_string(v) + " is out of range: the volume mesh has " + std::to_string(nv) + " vertices",
             "use indices 0.." + std::to_string(nv - 1));
        picked.insert(v);
      }
    }
    if (rule.surface_only)
      for (auto it = picked.begin(); it != picked.end();) it = on_surface[*it] ? std::next(it) : picked.erase(it);
    if (picked.empty()) at(rule.line, "this fixed set selects no vertex", "enlarge the box or check the region");
    scene.notes.push_back("fixed set (line " + std::to_string(rule.line) + "): " + std::to_string(picked.size()) + " vertices");
    fixed.insert(picked.begin(), picked.end());
  }
  scene.problem.fixed_vertices.assign(fixed.begin(), fixed.end());
  scene.problem.gravity_World_mm_s2 = spec.gravity_mm_s2;
  scene.time_step_s = spec.time_step_s;
  scene.frames = spec.frames;
  scene.model = spec.model;
  scene.model_line = spec.model_line;
  scene.cutting = spec.cutting;

  // Display surface carried by the volume.
  scene.organ_embedding = embed_points(mesh, scene.organ_surface.positions_World_mm, spec.embed_tolerance_mm,
                                       organ_path + " (organ surface in the volume mesh; organ.embed_tolerance_mm " +
                                           fmt(spec.embed_tolerance_mm) + ")");
  return scene;
}

Eigen::Vector3d tumour_centroid_World_mm(const Scene& scene, int tumour, const Eigen::Matrix3Xd& x_World_mm) {
  const EmbeddedSurface& t = scene.tumours.at(static_cast<std::size_t>(tumour));
  TriMesh moved = t.rest;
  moved.positions_World_mm = t.embedding.apply(scene.problem.mesh, x_World_mm);
  return surface_centroid(moved);
}

std::vector<int> lowest_surface_patch(const Scene& scene, double radius_mm) {
  const Eigen::Matrix3Xd& p = scene.organ_surface.positions_World_mm;
  int lowest = 0;
  for (int i = 1; i < p.cols(); ++i)
    if (p(2, i) < p(2, lowest)) lowest = i;
  std::vector<int> patch;
  for (int i = 0; i < p.cols(); ++i)
    if ((p.col(i) - p.col(lowest)).norm() <= radius_mm) patch.push_back(i);
  return patch;
}

}  // namespace arnav::host
