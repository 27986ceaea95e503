#include "host/scene/scene_spec.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <initializer_list>
#include <set>

#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

// Typed access to YAML nodes with file:line errors.
class Reader {
 public:
  explicit Reader(std::string source) : source_(std::move(source)) {}

  // A value refused is quoted back (issue 28: "must be in (0, 0.5)" alone sends the reader
  // to the file to find what was given).
  [[noreturn]] void fail(const YAML::Node& at, const std::string& what, const std::string& fix) const {
    const bool quote = at.IsDefined() && at.IsScalar() && what.find("got ") == std::string::npos;
    throw_load_error(source_, at.IsDefined() ? at.Mark().line + 1 : 0, quote ? what + " (got " + at.Scalar() + ")" : what, fix);
  }

  // The node must be a map whose keys are all in `allowed`.
  void keys(const YAML::Node& map, std::initializer_list<const char*> allowed, const std::string& context) const {
    if (!map.IsMap()) fail(map, context + " must be a map of keys", "write it as 'key: value' lines");
    for (const auto& kv : map) {
      const std::string key = kv.first.Scalar();
      bool known = false;
      for (const char* a : allowed) known = known || key == a;
      if (!known) {
        std::string list;
        for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        fail(kv.first, "unknown key '" + key + "' in " + context, "use one of: " + list + " (see docs/scene.md)");
      }
    }
  }

  YAML::Node require(const YAML::Node& map, const char* key, const std::string& context) const {
    const YAML::Node n = map[key];
    if (!n) fail(map, context + " needs '" + key + "'", "add the key (see docs/scene.md)");
    return n;
  }

  double number(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " must be a number", "give a number");
    double v = 0;
    try {
      v = n.as<double>();
    } catch (const YAML::Exception&) {
      fail(n, what + " must be a number, found '" + n.Scalar() + "'", "give a number");
    }
    if (!std::isfinite(v)) fail(n, what + " is not finite", "give a finite number");
    return v;
  }
  double number(const YAML::Node& map, const char* key, double fallback, const std::string& context) const {
    const YAML::Node n = map[key];
    return n ? number(n, context + "." + key) : fallback;
  }
  double positive(const YAML::Node& map, const char* key, double fallback, const std::string& context) const {
    const YAML::Node n = map[key];
    if (!n) return fallback;
    const double v = number(n, context + "." + key);
    if (!(v > 0)) fail(n, context + "." + key + " must be positive, found " + n.Scalar(), "give a value > 0");
    return v;
  }
  long long integer(const YAML::Node& n, const std::string& what, long long lo, long long hi) const {
    long long v = 0;
    try {
      v = n.as<long long>();
    } catch (const YAML::Exception&) {
      fail(n, what + " must be an integer", "give a whole number");
    }
    if (v < lo || v > hi) fail(n, what + " = " + std::to_string(v) + " is out of range", "use " + std::to_string(lo) + ".." + std::to_string(hi));
    return v;
  }
  bool boolean(const YAML::Node& n, const std::string& what) const {
    try {
      return n.as<bool>();
    } catch (const YAML::Exception&) {
      fail(n, what + " must be true or false", "write true or false");
    }
  }
  std::string string(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar() || n.Scalar().empty()) fail(n, what + " must be a non-empty string", "give a name or path");
    return n.Scalar();
  }
  Eigen::Vector3d vec3(const YAML::Node& n, const std::string& what) const {
    if (!n.IsSequence() || n.size() != 3) fail(n, what + " must be a list of 3 numbers", "write [x, y, z]");
    return {number(n[0], what), number(n[1], what), number(n[2], what)};
  }
  BoxSpec box(const YAML::Node& n, const std::string& what) const {
    keys(n, {"min", "max"}, what);
    BoxSpec b{vec3(require(n, "min", what), what + ".min"), vec3(require(n, "max", what), what + ".max")};
    if (!(b.min_mm.array() <= b.max_mm.array()).all()) fail(n, what + " has min > max on some axis", "swap the bounds");
    return b;
  }
  FileSpec file(const YAML::Node& n, const std::string& what, std::initializer_list<const char*> extra = {}) const {
    FileSpec f;
    f.line = n.Mark().line + 1;
    if (n.IsScalar()) {
      f.path = string(n, what);
      return f;
    }
    std::vector<const char*> allowed = {"file", "scale", "translate_mm"};
    allowed.insert(allowed.end(), extra.begin(), extra.end());
    if (!n.IsMap()) fail(n, what + " must be a path or a map with 'file'", "write 'file: path'");
    for (const auto& kv : n) {
      const std::string key = kv.first.Scalar();
      bool ok = false;
      for (const char* a : allowed) ok = ok || key == a;
      if (!ok) fail(kv.first, "unknown key '" + key + "' in " + what, "use file, scale, translate_mm (see docs/scene.md)");
    }
    f.path = string(require(n, "file", what), what + ".file");
    f.scale = positive(n, "scale", 1.0, what);
    if (n["translate_mm"]) f.translate_mm = vec3(n["translate_mm"], what + ".translate_mm");
    return f;
  }
  Material material(const YAML::Node& n, const std::string& what) const {
    keys(n, {"youngs_modulus_kPa", "poisson_ratio", "density_kg_per_mm3", "damping_mass_per_s", "damping_stiffness_s"}, what);
    Material m;
    m.youngs_modulus_kPa = number(require(n, "youngs_modulus_kPa", what), what + ".youngs_modulus_kPa");
    m.poisson_ratio = number(require(n, "poisson_ratio", what), what + ".poisson_ratio");
    m.density_kg_per_mm3 = number(require(n, "density_kg_per_mm3", what), what + ".density_kg_per_mm3");
    m.damping_mass_per_s = number(n, "damping_mass_per_s", 0.0, what);
    m.damping_stiffness_s = number(n, "damping_stiffness_s", 0.0, what);
    if (!(m.youngs_modulus_kPa > 0)) fail(n["youngs_modulus_kPa"], what + ": Young's modulus must be positive (kPa)", "liver is ~2-10 kPa");
    if (!(m.poisson_ratio >= 0 && m.poisson_ratio < 0.5))
      fail(n["poisson_ratio"], what + ": Poisson ratio must be in [0, 0.5)", "soft tissue is ~0.45-0.49");
    if (!(m.density_kg_per_mm3 > 0 && m.density_kg_per_mm3 < 1e-4))
      fail(n["density_kg_per_mm3"], what + ": density must be in kg/mm^3 (liver 1.06e-6)", "convert kg/m^3 by multiplying by 1e-9");
    if (m.damping_mass_per_s < 0 || m.damping_stiffness_s < 0) fail(n, what + ": damping must not be negative", "use values >= 0");
    return m;
  }

 private:
  std::string source_;
};

VesselTree read_vessel_tree(const Reader& r, const YAML::Node& n, const std::string& what) {
  r.keys(n, {"nodes_mm", "radius_mm", "segments", "file", "mechanics"}, what);
  VesselTree tree;
  const YAML::Node nodes = r.require(n, "nodes_mm", what);
  const YAML::Node radii = r.require(n, "radius_mm", what);
  const YAML::Node segs = r.require(n, "segments", what);
  if (!nodes.IsSequence() || nodes.size() < 2) r.fail(nodes, what + ".nodes_mm must list at least 2 points", "write [[x,y,z], ...]");
  if (!radii.IsSequence() || radii.size() != nodes.size())
    r.fail(radii, what + ".radius_mm must have one radius per node (" + std::to_string(nodes.size()) + ")", "add or remove radii");
  if (!segs.IsSequence() || segs.size() < 1) r.fail(segs, what + ".segments must list node pairs", "write [[0,1], [1,2], ...]");
  tree.nodes_World_mm.resize(3, static_cast<int>(nodes.size()));
  for (std::size_t i = 0; i < nodes.size(); ++i) tree.nodes_World_mm.col(static_cast<int>(i)) = r.vec3(nodes[i], what + ".nodes_mm");
  for (std::size_t i = 0; i < radii.size(); ++i) {
    const double rad = r.number(radii[i], what + ".radius_mm");
    if (!(rad > 0)) r.fail(radii[i], what + ": radius of node " + std::to_string(i) + " must be positive (mm)", "fix the radius");
    tree.radius_mm.push_back(rad);
  }
  std::set<std::pair<int, int>> seen;
  for (const auto& s : segs) {
    if (!s.IsSequence() || s.size() != 2) r.fail(s, what + ": a segment is a pair of node indices", "write [a, b]");
    const int a = static_cast<int>(r.integer(s[0], what + " segment node", 0, static_cast<long long>(nodes.size()) - 1));
    const int b = static_cast<int>(r.integer(s[1], what + " segment node", 0, static_cast<long long>(nodes.size()) - 1));
    if (a == b) r.fail(s, what + ": segment joins node " + std::to_string(a) + " to itself", "remove it");
    if (!seen.insert(std::minmax(a, b)).second) r.fail(s, what + ": segment " + std::to_string(a) + "-" + std::to_string(b) + " is repeated", "remove the duplicate");
    if ((tree.nodes_World_mm.col(a) - tree.nodes_World_mm.col(b)).norm() <= 0)
      r.fail(s, what + ": segment " + std::to_string(a) + "-" + std::to_string(b) + " has zero length", "separate the nodes");
    tree.segments.push_back({a, b});
  }
  return tree;
}

YAML::Node load_yaml(const std::string& text, const std::string& source) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw_load_error(source, e.mark.line + 1, "YAML syntax error: " + e.msg, "fix the indentation or quoting on that line");
  }
}

}  // namespace

VesselTree parse_vessel_tree(const std::string& yaml_text, const std::string& source) {
  const Reader r(source);
  const YAML::Node root = load_yaml(yaml_text, source);
  return read_vessel_tree(r, root, "vessel tree");
}

SceneSpec parse_scene_spec(const std::string& yaml_text, const std::string& source) {
  const Reader r(source);
  const YAML::Node root = load_yaml(yaml_text, source);
  if (!root.IsMap()) r.fail(root, "a scene file is a map of sections", "start from data/liver/liver.scene.yaml");
  r.keys(root, {"organ", "volume", "structures", "regions", "materials", "boundary", "gravity_mm_s2", "time_step_s", "frames", "model", "cutting"},
         "the scene");
  SceneSpec s;
  s.source = source;

  const YAML::Node organ = r.require(root, "organ", "the scene");
  r.keys(organ, {"surface", "embed_tolerance_mm", "keep_largest_component"}, "organ");
  if (organ["keep_largest_component"]) s.keep_largest_component = r.boolean(organ["keep_largest_component"], "organ.keep_largest_component");
  s.organ = r.file(r.require(organ, "surface", "organ"), "organ.surface");
  s.embed_tolerance_mm = r.positive(organ, "embed_tolerance_mm", 1.0, "organ");

  const YAML::Node volume = r.require(root, "volume", "the scene");
  r.keys(volume, {"file", "tetgen", "min_dihedral_required_deg", "peel_boundary_slivers_deg"}, "volume");
  if (volume["peel_boundary_slivers_deg"]) {
    s.volume.peel_boundary_slivers_deg = r.number(volume, "peel_boundary_slivers_deg", 0.0, "volume");
    if (s.volume.peel_boundary_slivers_deg < 0 || s.volume.peel_boundary_slivers_deg > 30)
      r.fail(volume["peel_boundary_slivers_deg"], "volume.peel_boundary_slivers_deg must be in [0, 30]",
             "5-10 removes flat tets lying on the surface; 0 keeps them");
  }
  s.volume.line = volume.Mark().line + 1;
  if (volume["min_dihedral_required_deg"]) {
    s.volume.min_dihedral_required_deg = r.number(volume, "min_dihedral_required_deg", 0.0, "volume");
    s.volume.min_dihedral_required_line = volume["min_dihedral_required_deg"].Mark().line + 1;
    if (s.volume.min_dihedral_required_deg < 0 || s.volume.min_dihedral_required_deg >= 70.5)
      r.fail(volume["min_dihedral_required_deg"], "volume.min_dihedral_required_deg must be in [0, 70.5)",
             "a regular tet has 70.5 degrees; 5-10 rules out slivers");
  }
  if (volume["file"] && volume["tetgen"]) r.fail(volume, "volume has both 'file' and 'tetgen'", "keep one: load a mesh or generate one");
  if (volume["file"]) {
    s.volume.file = r.file(volume["file"], "volume.file");
  } else if (volume["tetgen"]) {
    const YAML::Node t = volume["tetgen"];
    r.keys(t, {"max_radius_edge_ratio", "min_dihedral_deg", "max_volume_mm3", "decimate_surface_to", "optimisation_level", "keep_surface"}, "volume.tetgen");
    TetGenSettings ts;
    ts.max_radius_edge_ratio = r.number(t, "max_radius_edge_ratio", 2.0, "volume.tetgen");
    if (ts.max_radius_edge_ratio < 1.1)
      r.fail(t["max_radius_edge_ratio"], "volume.tetgen.max_radius_edge_ratio must be >= 1.1", "use 1.2-2.0");
    ts.min_dihedral_deg = r.number(t, "min_dihedral_deg", 0.0, "volume.tetgen");
    if (ts.min_dihedral_deg < 0 || ts.min_dihedral_deg > 18) r.fail(t["min_dihedral_deg"], "volume.tetgen.min_dihedral_deg must be in [0, 18]", "TetGen may not terminate above ~18 degrees");
    ts.max_volume_mm3 = r.number(t, "max_volume_mm3", 0.0, "volume.tetgen");
    if (ts.max_volume_mm3 < 0) r.fail(t["max_volume_mm3"], "volume.tetgen.max_volume_mm3 must be >= 0", "0 means no size bound");
    if (t["keep_surface"]) ts.keep_surface = r.boolean(t["keep_surface"], "volume.tetgen.keep_surface");
    if (t["optimisation_level"]) ts.optimisation_level = static_cast<int>(r.integer(t["optimisation_level"], "volume.tetgen.optimisation_level", 0, 10));
    if (t["decimate_surface_to"]) s.volume.decimate_surface_to = static_cast<int>(r.integer(t["decimate_surface_to"], "volume.tetgen.decimate_surface_to", 8, 10000000));
    s.volume.tetgen = ts;
  } else {
    r.fail(volume, "volume needs 'file' or 'tetgen'", "load a mesh (file: liver.msh) or generate one (tetgen: {...})");
  }

  if (const YAML::Node st = root["structures"]) {
    r.keys(st, {"tumours", "vessels"}, "structures");
    if (const YAML::Node tl = st["tumours"]) {
      if (!tl.IsSequence()) r.fail(tl, "structures.tumours must be a list", "write '- name: ...' entries");
      std::set<std::string> names;
      for (const auto& t : tl) {
        r.keys(t, {"name", "surface", "ellipsoid"}, "a tumour");
        TumourSpec ts;
        ts.line = t.Mark().line + 1;
        ts.name = r.string(r.require(t, "name", "a tumour"), "tumour name");
        if (!names.insert(ts.name).second) r.fail(t["name"], "tumour name '" + ts.name + "' is used twice", "give each tumour its own name");
        if (t["surface"] && t["ellipsoid"]) r.fail(t, "tumour '" + ts.name + "' has both surface and ellipsoid", "keep one");
        if (t["surface"]) {
          ts.surface = r.file(t["surface"], "tumour surface");
        } else if (const YAML::Node e = t["ellipsoid"]) {
          r.keys(e, {"center_mm", "radii_mm", "subdivisions"}, "tumour ellipsoid");
          ts.center_mm = r.vec3(r.require(e, "center_mm", "tumour ellipsoid"), "center_mm");
          ts.radii_mm = r.vec3(r.require(e, "radii_mm", "tumour ellipsoid"), "radii_mm");
          if (!(ts.radii_mm.array() > 0).all()) r.fail(e["radii_mm"], "ellipsoid radii must be positive (mm)", "fix the radii");
          if (e["subdivisions"]) ts.subdivisions = static_cast<int>(r.integer(e["subdivisions"], "subdivisions", 0, 5));
        } else {
          r.fail(t, "tumour '" + ts.name + "' needs 'surface' or 'ellipsoid'", "give its closed surface file or an ellipsoid");
        }
        s.tumours.push_back(ts);
      }
    }
    if (const YAML::Node v = st["vessels"]) {
      VesselSpec vs;
      vs.line = v.Mark().line + 1;
      if (!v.IsMap()) r.fail(v, "structures.vessels must be a map", "give 'file:' or inline nodes_mm/radius_mm/segments");
      if (const YAML::Node m = v["mechanics"]) {
        const std::string mech = r.string(m, "vessels.mechanics");
        if (mech != "beams" && mech != "display") r.fail(m, "vessels.mechanics must be 'beams' or 'display'", "beams couple stiff vessels to the volume");
        vs.beams = mech == "beams";
      }
      if (v["file"]) {
        r.keys(v, {"file", "scale", "translate_mm", "mechanics"}, "structures.vessels");
        YAML::Node f(YAML::NodeType::Map);
        f["file"] = v["file"];
        if (v["scale"]) f["scale"] = v["scale"];
        if (v["translate_mm"]) f["translate_mm"] = v["translate_mm"];
        vs.file = r.file(f, "structures.vessels");
        vs.file->line = vs.line;
      } else {
        vs.inline_tree = read_vessel_tree(r, v, "structures.vessels");
      }
      s.vessels = vs;
    }
  }

  if (const YAML::Node regions = root["regions"]) {
    if (!regions.IsSequence()) r.fail(regions, "regions must be a list", "write '- name: ...' entries");
    for (const auto& g : regions) {
      r.keys(g, {"name", "box_mm", "inside"}, "a region");
      RegionRule rule;
      rule.line = g.Mark().line + 1;
      rule.name = r.string(r.require(g, "name", "a region"), "region name");
      if (rule.name == "default") r.fail(g["name"], "'default' is the region of all tets no rule selects", "choose another name");
      if (g["box_mm"] && g["inside"]) r.fail(g, "region '" + rule.name + "' has both box_mm and inside", "keep one");
      if (g["box_mm"]) {
        rule.box = r.box(g["box_mm"], "region box_mm");
      } else if (g["inside"]) {
        rule.inside = r.string(g["inside"], "region inside");
        bool found = false;
        for (const auto& t : s.tumours) found = found || t.name == rule.inside;
        if (!found) r.fail(g["inside"], "region '" + rule.name + "' refers to unknown tumour '" + rule.inside + "'", "declare it under structures.tumours");
      } else {
        r.fail(g, "region '" + rule.name + "' needs 'box_mm' or 'inside'", "select its tets by a box or a tumour surface");
      }
      s.regions.push_back(rule);
    }
  }

  const YAML::Node materials = r.require(root, "materials", "the scene");
  if (!materials.IsMap()) r.fail(materials, "materials must be a map from region name to material", "write 'default: {...}'");
  for (const auto& kv : materials) {
    MaterialSpec m;
    m.name = kv.first.Scalar();
    m.line = kv.first.Mark().line + 1;
    bool known = m.name == "default" || m.name == "vessels";
    for (const auto& g : s.regions) known = known || g.name == m.name;
    if (!known) r.fail(kv.first, "material for unknown region '" + m.name + "'", "declare the region under 'regions' or fix the name");
    m.material = r.material(kv.second, "materials." + m.name);
    s.materials.push_back(m);
  }
  if (!materials["default"]) r.fail(materials, "materials needs 'default' (tets no region rule selects)", "add materials.default");

  if (const YAML::Node b = root["boundary"]) {
    r.keys(b, {"fixed"}, "boundary");
    const YAML::Node fixed = r.require(b, "fixed", "boundary");
    if (!fixed.IsSequence()) r.fail(fixed, "boundary.fixed must be a list", "write '- box_mm: ...' entries");
    for (const auto& f : fixed) {
      r.keys(f, {"box_mm", "region", "vertices", "surface_only", "name"}, "a fixed set");
      FixedRule rule;
      rule.line = f.Mark().line + 1;
      const int kinds = (f["box_mm"] ? 1 : 0) + (f["region"] ? 1 : 0) + (f["vertices"] ? 1 : 0);
      if (kinds != 1) r.fail(f, "a fixed set needs exactly one of box_mm, region, vertices", "split it into separate entries");
      if (f["box_mm"]) rule.box = r.box(f["box_mm"], "fixed box_mm");
      if (f["region"]) {
        rule.region = r.string(f["region"], "fixed region");
        bool found = rule.region == "default";
        for (const auto& g : s.regions) found = found || g.name == rule.region;
        if (!found) r.fail(f["region"], "fixed set refers to unknown region '" + rule.region + "'", "declare it under 'regions'");
      }
      if (const YAML::Node v = f["vertices"]) {
        if (!v.IsSequence() || v.size() == 0) r.fail(v, "fixed vertices must be a non-empty list of indices", "write [0, 5, 9]");
        for (const auto& i : v) rule.vertices.push_back(static_cast<int>(r.integer(i, "fixed vertex", 0, 1 << 30)));
      }
      if (f["surface_only"]) rule.surface_only = r.boolean(f["surface_only"], "surface_only");
      s.fixed.push_back(rule);
    }
  }

  if (root["gravity_mm_s2"]) s.gravity_mm_s2 = r.vec3(root["gravity_mm_s2"], "gravity_mm_s2");
  if (root["time_step_s"]) {
    s.time_step_s = r.number(root["time_step_s"], "time_step_s");
    if (!(s.time_step_s > 0 && s.time_step_s <= 0.1)) r.fail(root["time_step_s"], "time_step_s must be in (0, 0.1] s", "1/60 s = 0.0166667 is one display frame");
  }
  if (root["frames"]) s.frames = static_cast<int>(r.integer(root["frames"], "frames", 1, 1000000));

  const YAML::Node model = r.require(root, "model", "the scene");
  r.keys(model, {"kind", "integrator", "energy", "linear_solver", "iterations", "substeps", "tolerance", "refactor_every", "threads",
                  "refactor_in_background", "blas_threads", "single_precision_preconditioner", "material_model"}, "model");
  s.model_line = model.Mark().line + 1;
  s.model.kind = r.string(r.require(model, "kind", "model"), "model.kind");
  if (s.model.kind != "mass_spring" && s.model.kind != "xpbd" && s.model.kind != "corotational_fem")
    r.fail(model["kind"], "unknown model kind '" + s.model.kind + "'", "use mass_spring, xpbd or corotational_fem");
  if (model["integrator"]) s.model.integrator = r.string(model["integrator"], "model.integrator");
  if (model["energy"]) {
    s.model.energy = r.string(model["energy"], "model.energy");
    if (s.model.kind != "xpbd") r.fail(model["energy"], "model.energy applies to kind xpbd only", "remove it or use kind: xpbd");
    if (s.model.energy != "corotated" && s.model.energy != "neo_hookean")
      r.fail(model["energy"], "unknown model.energy '" + s.model.energy + "'", "use corotated or neo_hookean (one sweep per substep: iterations: 1)");
  }
  if (model["material_model"]) {
    s.model.material_model = r.string(model["material_model"], "model.material_model");
    if (s.model.kind != "corotational_fem")
      r.fail(model["material_model"], "model.material_model applies to kind corotational_fem only", "remove it or use kind: corotational_fem");
    if (s.model.material_model != "corotational_linear" && s.model.material_model != "stable_neo_hookean")
      r.fail(model["material_model"], "unknown model.material_model '" + s.model.material_model + "'",
             "use corotational_linear (default) or stable_neo_hookean (projected Newton; iterations = Newton iterations)");
  }
  if (model["linear_solver"]) s.model.linear_solver = r.string(model["linear_solver"], "model.linear_solver");
  if (model["iterations"]) s.model.iterations = static_cast<int>(r.integer(model["iterations"], "model.iterations", 1, 100000));
  if (model["substeps"]) s.model.substeps = static_cast<int>(r.integer(model["substeps"], "model.substeps", 1, 10000));
  if (model["tolerance"]) {
    s.model.tolerance = r.number(model["tolerance"], "model.tolerance");
    if (!(s.model.tolerance > 0 && s.model.tolerance < 1)) r.fail(model["tolerance"], "model.tolerance must be in (0, 1)", "e.g. 1e-6");
  }
  if (model["threads"]) s.model.threads = static_cast<int>(r.integer(model["threads"], "model.threads", 1, 256));
  if (model["refactor_every"]) s.model.refactor_every = static_cast<int>(r.integer(model["refactor_every"], "model.refactor_every", 1, 100000));
  if (model["refactor_in_background"]) s.model.refactor_in_background = r.boolean(model["refactor_in_background"], "model.refactor_in_background");
  if (model["blas_threads"]) s.model.blas_threads = static_cast<int>(r.integer(model["blas_threads"], "model.blas_threads", 0, 256));
  if (model["single_precision_preconditioner"])
    s.model.single_precision_preconditioner = r.boolean(model["single_precision_preconditioner"], "model.single_precision_preconditioner");

  if (const YAML::Node c = root["cutting"]) {
    CuttingSpec cs;
    for (const auto& kv : root)
      if (kv.first.Scalar() == "cutting") cs.line = kv.first.Mark().line + 1;
    if (!c.IsNull()) {
      r.keys(c, {"blade", "tumour_margin_mm", "snap_fraction", "path_tolerance_mm", "chord_sagitta_mm", "min_refined_edge_mm", "sweep_strips", "push_stiffness_mN_per_mm", "min_dihedral_deg"},
             "cutting");
      if (const YAML::Node b = c["blade"]) {
        r.keys(b, {"tip_mm", "heel_mm"}, "cutting.blade");
        if (b["tip_mm"]) cs.blade_tip_Tool_mm = r.vec3(b["tip_mm"], "cutting.blade.tip_mm");
        if (b["heel_mm"]) cs.blade_heel_Tool_mm = r.vec3(b["heel_mm"], "cutting.blade.heel_mm");
        if ((cs.blade_tip_Tool_mm - cs.blade_heel_Tool_mm).norm() <= 0.0)
          r.fail(b, "cutting.blade: tip and heel are the same point", "give the tip (pivot) and a second point along the blade edge (arnav-calib)");
      }
      if (c["tumour_margin_mm"]) {
        cs.tumour_margin_mm = r.number(c["tumour_margin_mm"], "cutting.tumour_margin_mm");
        if (cs.tumour_margin_mm < 0) r.fail(c["tumour_margin_mm"], "cutting.tumour_margin_mm must be >= 0", "10 mm is the usual resection margin");
      }
      if (c["snap_fraction"]) {
        cs.snap_fraction = r.number(c["snap_fraction"], "cutting.snap_fraction");
        if (!(cs.snap_fraction > 0 && cs.snap_fraction < 0.5))
          r.fail(c["snap_fraction"], "cutting.snap_fraction must be in (0, 0.5)", "0.1: no piece below a tenth of its tet per split edge");
      }
      if (c["path_tolerance_mm"]) {
        cs.path_tolerance_mm = r.number(c["path_tolerance_mm"], "cutting.path_tolerance_mm");
        if (!(cs.path_tolerance_mm >= 0))
          r.fail(c["path_tolerance_mm"], "cutting.path_tolerance_mm must be >= 0", "0.1: a vertex snaps onto the cut only within 0.1 mm of it");
      }
      if (c["chord_sagitta_mm"]) {
        cs.chord_sagitta_mm = r.number(c["chord_sagitta_mm"], "cutting.chord_sagitta_mm");
        if (!(cs.chord_sagitta_mm >= 0 && cs.chord_sagitta_mm <= 100))
          r.fail(c["chord_sagitta_mm"], "cutting.chord_sagitta_mm must be in [0, 100] mm",
                 "1: where the cut curves, tets ahead of the blade are refined until a chord across them lies within 1 mm of the cut (0: off)");
      }
      if (c["min_refined_edge_mm"]) {
        cs.min_refined_edge_mm = r.number(c["min_refined_edge_mm"], "cutting.min_refined_edge_mm");
        if (!(cs.min_refined_edge_mm >= 1 && cs.min_refined_edge_mm <= 1000))
          r.fail(c["min_refined_edge_mm"], "cutting.min_refined_edge_mm must be in [1, 1000] mm", "6: refinement ahead of the blade stops at 6 mm edges");
      }
      if (c["sweep_strips"]) cs.sweep_strips = static_cast<int>(r.integer(c["sweep_strips"], "cutting.sweep_strips", 1, 256));
      cs.push_stiffness_mN_per_mm = r.positive(c, "push_stiffness_mN_per_mm", cs.push_stiffness_mN_per_mm, "cutting");
      if (c["min_dihedral_deg"]) {
        cs.min_dihedral_deg = r.number(c["min_dihedral_deg"], "cutting.min_dihedral_deg");
        if (!(cs.min_dihedral_deg >= 0 && cs.min_dihedral_deg <= 30))
          r.fail(c["min_dihedral_deg"], "cutting.min_dihedral_deg must be in [0, 30]",
                 "5: tets flatter than 5 degrees carry no elastic term (0 switches the treatment off)");
      }
    }
    s.cutting = cs;
  }
  return s;
}

}  // namespace arnav::host
