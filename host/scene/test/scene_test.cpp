// Scene files: the bundled liver scenes build as documented; every schema error names the
// file and line; only what a scene declares is built.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>


#include "host/mesh/box_mesh.hpp"
#include "host/mesh/load_error.hpp"
#include "host/mesh/mesh_io.hpp"
#include "host/scene/scene.hpp"
#include "host/scene/scene_spec.hpp"
#include "host/mesh/surface_shapes.hpp"
#include "host/mesh/test/test_paths.hpp"
#include "protocol/testing/error_of.hpp"

namespace arnav::host {
namespace {

using arnav::testing::error_of;

using test::scratch;
using test::write_file;

// A 40 x 20 x 20 mm box block: volume as legacy VTK, surface as OBJ.
std::string make_box_files(const std::string& dir) {
  const TetMesh box = make_box_tet_mesh(8, 4, 4, Eigen::Vector3d(40, 20, 20));
  write_vtk_volume(dir + "/block.vtk", box, box.rest_positions_World_mm);
  write_obj(dir + "/block.obj", box.rest_positions_World_mm, box.surface_tris);
  return dir;
}

const std::string kBase =
    "organ:\n"
    "  surface: block.obj\n"
    "volume:\n"
    "  file: block.vtk\n"
    "materials:\n"
    "  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, density_kg_per_mm3: 1.06e-6}\n"
    "model:\n"
    "  kind: xpbd\n";

TEST(SceneFile, MinimalSceneBuildsOnlyWhatItDeclares) {
  const std::string dir = make_box_files(scratch("minimal"));
  const Scene s = load_scene(write_file(dir, "min.scene.yaml", kBase));
  EXPECT_EQ(s.problem.mesh.num_tets(), 6 * 8 * 4 * 4);
  EXPECT_FALSE(s.problem.vessels.has_value());
  EXPECT_FALSE(s.vessels.has_value());
  EXPECT_TRUE(s.tumours.empty());
  EXPECT_TRUE(s.problem.fixed_vertices.empty());
  EXPECT_EQ(s.problem.region_materials.size(), 1u);
  EXPECT_DOUBLE_EQ(s.time_step_s, 1.0 / 60.0);
  EXPECT_EQ(s.model.kind, "xpbd");
  EXPECT_EQ(s.problem.gravity_World_mm_s2, Eigen::Vector3d(0, 0, -9810));
  // The display surface is the volume's boundary: embedded exactly.
  EXPECT_EQ(s.organ_embedding.max_outside_mm, 0.0);
}

TEST(SceneFile, RegionsMaterialsFixedSetsTumourAndVessels) {
  const std::string dir = make_box_files(scratch("full"));
  const std::string text =
      "organ: {surface: block.obj}\n"
      "volume: {file: block.vtk}\n"
      "structures:\n"
      "  tumours:\n"
      "    - name: lesion\n"
      "      ellipsoid: {center_mm: [30, 10, 10], radii_mm: [5, 5, 5], subdivisions: 2}\n"
      "  vessels:\n"
      "    nodes_mm: [[2, 10, 10], [20, 10, 10], [35, 15, 12]]\n"
      "    radius_mm: [2, 1.5, 1]\n"
      "    segments: [[0, 1], [1, 2]]\n"
      "    mechanics: beams\n"
      "regions:\n"
      "  - name: left\n"
      "    box_mm: {min: [0, 0, 0], max: [10, 20, 20]}\n"
      "  - name: lesion\n"
      "    inside: lesion\n"
      "materials:\n"
      "  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, density_kg_per_mm3: 1.06e-6}\n"
      "  left: {youngs_modulus_kPa: 8, poisson_ratio: 0.4, density_kg_per_mm3: 1.0e-6, damping_mass_per_s: 1}\n"
      "  lesion: {youngs_modulus_kPa: 40, poisson_ratio: 0.45, density_kg_per_mm3: 1.1e-6}\n"
      "  vessels: {youngs_modulus_kPa: 500, poisson_ratio: 0.45, density_kg_per_mm3: 1.06e-6}\n"
      "boundary:\n"
      "  fixed:\n"
      "    - box_mm: {min: [-1, -1, -1], max: [0.1, 21, 21]}\n"
      "    - vertices: [44]\n"
      "gravity_mm_s2: [0, -9810, 0]\n"
      "time_step_s: 0.01\n"
      "frames: 5\n"
      "model: {kind: corotational_fem, integrator: implicit_euler, linear_solver: cholmod, tolerance: 1e-8,\n"
      "        refactor_in_background: true, blas_threads: 1, single_precision_preconditioner: true}\n";
  const Scene s = load_scene(write_file(dir, "full.scene.yaml", text));
  const TetMesh& m = s.problem.mesh;
  EXPECT_EQ(m.region_names, (std::vector<std::string>{"default", "left", "lesion"}));
  ASSERT_EQ(s.problem.region_materials.size(), 3u);
  EXPECT_EQ(s.problem.region_materials[1].youngs_modulus_kPa, 8);
  EXPECT_EQ(s.problem.region_materials[1].damping_mass_per_s, 1);
  EXPECT_EQ(s.problem.region_materials[2].youngs_modulus_kPa, 40);
  // Region rules by box and by tumour surface, checked per tet centroid.
  const TriMesh lesion = make_ellipsoid_surface(Eigen::Vector3d(30, 10, 10), Eigen::Vector3d(5, 5, 5), 2);
  int left = 0, inside = 0;
  for (int t = 0; t < m.num_tets(); ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int v : m.tets[t]) c += m.rest_positions_World_mm.col(v) / 4;
    const int expect = winding_number(lesion, c) > 0.5 ? 2 : (c.x() <= 10 ? 1 : 0);
    EXPECT_EQ(m.tet_region[t], expect) << "tet " << t;
    left += m.tet_region[t] == 1;
    inside += m.tet_region[t] == 2;
  }
  EXPECT_GT(left, 0);
  EXPECT_GT(inside, 0);
  // Fixed: the x = 0 face (5 x 5 vertices) plus vertex 44.
  EXPECT_EQ(s.problem.fixed_vertices.size(), 26u);
  EXPECT_TRUE(std::find(s.problem.fixed_vertices.begin(), s.problem.fixed_vertices.end(), 44) != s.problem.fixed_vertices.end());
  ASSERT_TRUE(s.problem.vessels.has_value());
  EXPECT_EQ(s.problem.vessels->segments.size(), 2u);
  EXPECT_EQ(s.problem.vessel_material.youngs_modulus_kPa, 500);
  ASSERT_TRUE(s.vessels.has_value());
  EXPECT_EQ(s.vessels->embedding.size(), 3);
  ASSERT_EQ(s.tumours.size(), 1u);
  EXPECT_LT((s.tumours[0].rest_centroid_World_mm - Eigen::Vector3d(30, 10, 10)).norm(), 1e-9);
  // The embedded tumour follows a translation of the volume exactly.
  const Eigen::Matrix3Xd moved = m.rest_positions_World_mm.colwise() + Eigen::Vector3d(1, 2, 3);
  EXPECT_LT((tumour_centroid_World_mm(s, 0, moved) - Eigen::Vector3d(31, 12, 13)).norm(), 1e-9);
  EXPECT_EQ(s.problem.gravity_World_mm_s2, Eigen::Vector3d(0, -9810, 0));
  EXPECT_DOUBLE_EQ(s.time_step_s, 0.01);
  EXPECT_EQ(s.frames, 5);
  EXPECT_EQ(s.model.kind, "corotational_fem");
  EXPECT_EQ(s.model.linear_solver, "cholmod");
  EXPECT_DOUBLE_EQ(s.model.tolerance, 1e-8);
  EXPECT_TRUE(s.model.refactor_in_background);
  EXPECT_EQ(s.model.blas_threads, 1);
  EXPECT_TRUE(s.model.single_precision_preconditioner);
}

TEST(SceneFile, XpbdEnergyIsRead) {
  const std::string dir = make_box_files(scratch("energy"));
  const Scene s = load_scene(write_file(dir, "nh.scene.yaml", kBase + "  energy: neo_hookean\n  iterations: 1\n"));
  EXPECT_EQ(s.model.energy, "neo_hookean");
  EXPECT_EQ(load_scene(write_file(dir, "default.scene.yaml", kBase)).model.energy, "");
}

TEST(SceneFile, FemMaterialModelIsRead) {
  const std::string dir = make_box_files(scratch("material_model"));
  std::string fem = kBase;
  fem.replace(fem.find("kind: xpbd"), 10, "kind: corotational_fem");
  const Scene s = load_scene(write_file(dir, "snh.scene.yaml", fem + "  material_model: stable_neo_hookean\n  iterations: 3\n"));
  EXPECT_EQ(s.model.material_model, "stable_neo_hookean");
  EXPECT_EQ(load_scene(write_file(dir, "default.scene.yaml", fem)).model.material_model, "");
}

TEST(SceneFile, VesselsForDisplayOnlyAreNotGivenToTheModel) {
  const std::string dir = make_box_files(scratch("display"));
  const std::string text = kBase + "structures:\n  vessels:\n    nodes_mm: [[2, 10, 10], [20, 10, 10]]\n    radius_mm: [2, 1]\n"
                                   "    segments: [[0, 1]]\n    mechanics: display\n";
  const Scene s = load_scene(write_file(dir, "display.scene.yaml", text));
  EXPECT_TRUE(s.vessels.has_value());
  EXPECT_FALSE(s.problem.vessels.has_value());
}

struct BadScene {
  std::string text;
  int line;
  std::string expect;
};

TEST(MeshQuality, RegularTetAndSliver) {
  TetMesh regular;
  regular.rest_positions_World_mm.resize(3, 4);
  regular.rest_positions_World_mm << 1, -1, -1, 1, 1, -1, 1, -1, 1, 1, -1, -1;  // (1,1,1), (-1,-1,1), (-1,1,-1), (1,-1,-1)
  regular.tets = {{0, 1, 2, 3}};
  const TetMeshQuality q = tet_mesh_quality(regular);
  EXPECT_NEAR(q.min_dihedral_deg, std::acos(1.0 / 3.0) * 180.0 / M_PI, 1e-9);  // 70.53 degrees
  EXPECT_NEAR(q.max_dihedral_deg, q.min_dihedral_deg, 1e-9);
  EXPECT_NEAR(q.max_radius_edge_ratio, std::sqrt(6.0) / 4.0, 1e-9);
  EXPECT_NEAR(q.min_volume_mm3, 8.0 / 3.0, 1e-9);
  EXPECT_EQ(q.slivers, 0);
  // A sliver: a square's corners lifted alternately by 0.05 mm (edges 10-14 mm).
  TetMesh sliver;
  sliver.rest_positions_World_mm.resize(3, 4);
  sliver.rest_positions_World_mm << 0, 10, 10, 0, 0, 0, 10, 10, 0, 0.05, 0, 0.05;
  sliver.tets = {{0, 1, 2, 3}};
  const TetMeshQuality qs = tet_mesh_quality(sliver);
  EXPECT_LT(qs.min_dihedral_deg, 1.0);
  EXPECT_GT(qs.max_dihedral_deg, 179.0);
  EXPECT_EQ(qs.slivers, 1);
  EXPECT_EQ(qs.worst_tet, 0);
  EXPECT_NE(describe(qs).find("slivers (<5 or >175 deg) 1"), std::string::npos) << describe(qs);
}

TEST(SceneFile, RestMeshQualityIsReportedAndCanBeRequired) {
  const std::string dir = make_box_files(scratch("quality"));
  auto with = [](const std::string& extra) {
    std::string t = kBase;
    t.replace(t.find("  file: block.vtk\n"), 18, "  file: block.vtk\n" + extra);
    return t;
  };
  const Scene s = load_scene(write_file(dir, "ok.scene.yaml", with("  min_dihedral_required_deg: 30\n")));
  EXPECT_NEAR(s.mesh_quality.min_dihedral_deg, 45.0, 1e-6);  // cubes cut into 6 tets: 45, 60 and 90 degrees
  EXPECT_NEAR(s.mesh_quality.max_dihedral_deg, 90.0, 1e-6);
  EXPECT_EQ(s.mesh_quality.slivers, 0);
  bool noted = false;
  for (const auto& n : s.notes) noted = noted || n.find("rest mesh quality: min dihedral 45.0 deg") != std::string::npos;
  EXPECT_TRUE(noted);
  const std::string path = write_file(dir, "strict.scene.yaml", with("  min_dihedral_required_deg: 50\n"));
  const std::string e = error_of<LoadError>([&] { load_scene(path); });
  EXPECT_NE(e.find(path + ":5:"), std::string::npos) << e;
  EXPECT_NE(e.find("dihedral angle of 45"), std::string::npos) << e;
  EXPECT_NE(e.find("Fix:"), std::string::npos) << e;
  const std::string bad = write_file(dir, "range.scene.yaml", with("  min_dihedral_required_deg: 80\n"));
  EXPECT_NE(error_of<LoadError>([&] { load_scene(bad); }).find(bad + ":5:"), std::string::npos);
}

TEST(SceneFile, SchemaErrorsNameFileAndLine) {
  const std::string dir = make_box_files(scratch("errors"));
  const std::vector<BadScene> cases = {
      {kBase + "colour: red\n", 9, "unknown key 'colour'"},
      {kBase + "time_step_s: -1\n", 9, "time_step_s must be in"},
      {kBase + "gravity_mm_s2: [0, 0]\n", 9, "list of 3 numbers"},
      {kBase + "frames: many\n", 9, "must be an integer"},
      {"organ:\n  surface: block.obj\n  colour: red\n", 3, "unknown key 'colour' in organ"},
      {"organ: {surface: block.obj}\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: -5, poisson_ratio: 0.45, "
       "density_kg_per_mm3: 1e-6}\nmodel: {kind: xpbd}\n",
       4, "Young's modulus must be positive"},
      {"organ: {surface: block.obj}\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, "
       "density_kg_per_mm3: 1060}\nmodel: {kind: xpbd}\n",
       4, "kg/mm^3"},
      {"organ: {surface: block.obj}\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, "
       "density_kg_per_mm3: 1e-6}\n  liver: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, density_kg_per_mm3: 1e-6}\nmodel: {kind: xpbd}\n",
       5, "unknown region 'liver'"},
      {kBase + "  iterations: 0\n", 9, "model.iterations"},
      {kBase + "  refactor_in_background: sometimes\n", 9, "model.refactor_in_background"},
      {kBase + "  blas_threads: -1\n", 9, "model.blas_threads"},
      {kBase + "  energy: neohookean\n", 9, "unknown model.energy"},
      {kBase + "  material_model: stable_neo_hookean\n", 9, "applies to kind corotational_fem only"},
      {"organ: {surface: block.obj}\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, "
       "density_kg_per_mm3: 1e-6}\nmodel: {kind: fem}\n",
       5, "unknown model kind 'fem'"},
      {kBase + "boundary:\n  fixed:\n    - region: nowhere\n", 11, "unknown region 'nowhere'"},
      {kBase + "boundary:\n  fixed:\n    - vertices: [1]\n      box_mm: {min: [0,0,0], max: [1,1,1]}\n", 11, "exactly one of"},
      {kBase + "regions:\n  - name: r\n    box_mm: {min: [5, 0, 0], max: [1, 1, 1]}\n", 11, "min > max"},
      {kBase + "structures:\n  tumours:\n    - name: t\n", 11, "needs 'surface' or 'ellipsoid'"},
      {kBase + "structures:\n  vessels:\n    nodes_mm: [[0,0,0],[1,1,1]]\n    radius_mm: [1, 1]\n    segments: [[0, 5]]\n", 13,
       "out of range"},
      {kBase + "organ2: [\n", 10, "YAML syntax error"},
      {"organ: {surface: block.obj}\nmaterials: {}\n", 1, "needs 'volume'"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const std::string path = write_file(dir, "bad" + std::to_string(i) + ".scene.yaml", cases[i].text);
    const std::string e = error_of<LoadError>([&] { check_scene_text(cases[i].text, path); });
    SCOPED_TRACE("case " + std::to_string(i) + ": " + e);
    EXPECT_NE(e.find(path + ":" + std::to_string(cases[i].line) + ":"), std::string::npos);
    EXPECT_NE(e.find(cases[i].expect), std::string::npos);
    EXPECT_NE(e.find("Fix:"), std::string::npos);
    EXPECT_EQ(error_of<LoadError>([&] { load_scene(path); }), e);  // load_scene reports the same
  }
}

TEST(SceneFile, BuildErrorsNameTheCause) {
  const std::string dir = make_box_files(scratch("build_errors"));
  auto err = [&](const std::string& name, const std::string& text) { return error_of<LoadError>([&] { load_scene(write_file(dir, name, text)); }); };
  std::string e = err("far.scene.yaml", kBase + "structures:\n  tumours:\n    - name: t\n      ellipsoid: {center_mm: [100, 0, 0], radii_mm: [3, 3, 3]}\n");
  EXPECT_NE(e.find("tumour 't'"), std::string::npos) << e;
  EXPECT_NE(e.find("outside the volume mesh"), std::string::npos) << e;
  e = err("range.scene.yaml", kBase + "boundary:\n  fixed:\n    - vertices: [100000]\n");
  EXPECT_NE(e.find("range.scene.yaml:11:"), std::string::npos) << e;
  EXPECT_NE(e.find("out of range"), std::string::npos) << e;
  e = err("empty.scene.yaml", kBase + "boundary:\n  fixed:\n    - box_mm: {min: [100, 100, 100], max: [101, 101, 101]}\n");
  EXPECT_NE(e.find("selects no vertex"), std::string::npos) << e;
  e = err("nomat.scene.yaml", kBase + "regions:\n  - name: r\n    box_mm: {min: [0, 0, 0], max: [10, 20, 20]}\n");
  EXPECT_NE(e.find("region 'r' has no material"), std::string::npos) << e;
  e = err("missing.scene.yaml", "organ: {surface: nothere.obj}\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: 5, "
                                "poisson_ratio: 0.45, density_kg_per_mm3: 1e-6}\nmodel: {kind: xpbd}\n");
  EXPECT_NE(e.find("nothere.obj: cannot open"), std::string::npos) << e;
  e = err("broken.scene.yaml", "organ: {surface: " + test::data_meshes() + "liver_for_test_broken.vtk}\nvolume: {file: block.vtk}\n"
                               "materials:\n  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, density_kg_per_mm3: 1e-6}\nmodel: {kind: xpbd}\n");
  EXPECT_NE(e.find("liver_for_test_broken.vtk: byte offset"), std::string::npos) << e;
  // Two closed components: refused unless the scene asks to keep the largest.
  TriMesh two = make_ellipsoid_surface(Eigen::Vector3d(20, 10, 10), Eigen::Vector3d(8, 5, 5), 1);
  const TriMesh bubble = make_ellipsoid_surface(Eigen::Vector3d(20, 10, 10), Eigen::Vector3d(1, 1, 1), 0);
  const int offset = static_cast<int>(two.positions_World_mm.cols());
  two.positions_World_mm.conservativeResize(3, offset + bubble.positions_World_mm.cols());
  two.positions_World_mm.rightCols(bubble.positions_World_mm.cols()) = bubble.positions_World_mm;
  for (auto t : bubble.tris) two.tris.push_back({t[0] + offset, t[2] + offset, t[1] + offset});
  write_obj(dir + "/two.obj", two.positions_World_mm, two.tris);
  const std::string two_scene = "organ:\n  surface: two.obj\nvolume: {file: block.vtk}\nmaterials:\n  default: {youngs_modulus_kPa: 5, "
                                "poisson_ratio: 0.45, density_kg_per_mm3: 1e-6}\nmodel: {kind: xpbd}\n";
  e = err("two.scene.yaml", two_scene);
  EXPECT_NE(e.find("two.scene.yaml:2:"), std::string::npos) << e;
  EXPECT_NE(e.find("2 separate closed components"), std::string::npos) << e;
  EXPECT_NE(e.find("keep_largest_component"), std::string::npos) << e;
  const Scene kept = load_scene(write_file(dir, "two_kept.scene.yaml",
                                           std::string(two_scene).replace(two_scene.find("volume"), 0, "  keep_largest_component: true\n")));
  EXPECT_EQ(kept.organ_surface.positions_World_mm.cols(), offset);
  e = err("beams.scene.yaml", kBase + "structures:\n  vessels:\n    nodes_mm: [[2, 10, 10], [20, 10, 10]]\n    radius_mm: [2, 1]\n"
                                      "    segments: [[0, 1]]\n    mechanics: beams\n");
  EXPECT_NE(e.find("materials.vessels"), std::string::npos) << e;
}

TEST(BundledScenes, LiverAtPaperSizeWithTumourAndVessels) {
  const Scene s = load_scene(test::source_dir() + "/data/liver/liver.scene.yaml");
  const TetMesh& m = s.problem.mesh;
  EXPECT_NEAR(m.num_vertices(), 6821, 200);  // paper 000: 6,510 vertices / 24,398 tets
  EXPECT_NEAR(m.num_tets(), 26054, 800);
  ASSERT_EQ(s.tumours.size(), 1u);
  ASSERT_TRUE(s.vessels.has_value());
  EXPECT_EQ(s.vessels->rest.segments.size(), 8u);
  EXPECT_FALSE(s.problem.vessels.has_value());  // display only in this scene
  EXPECT_GT(s.problem.fixed_vertices.size(), 50u);
  EXPECT_EQ(m.region_names, (std::vector<std::string>{"default", "tumour"}));
  int tumour_tets = 0;
  for (int r : m.tet_region) tumour_tets += r == 1;
  EXPECT_GT(tumour_tets, 20);
  EXPECT_EQ(s.organ_embedding.size(), 4996);  // 5,008 less 3 bubbles of 4 vertices
  EXPECT_EQ(s.organ_embedding.max_outside_mm, 0.0);  // the volume keeps the surface
  // Internal structures sit well inside the organ: at least 5 mm from its surface.
  const TriMesh& organ = s.organ_surface;
  auto depth = [&](const Eigen::Vector3d& p) { return (organ.positions_World_mm.colwise() - p).colwise().norm().minCoeff(); };
  for (int i = 0; i < s.vessels->rest.nodes_World_mm.cols(); ++i) {
    EXPECT_GT(winding_number(organ, s.vessels->rest.nodes_World_mm.col(i)), 0.5);
    EXPECT_GT(depth(s.vessels->rest.nodes_World_mm.col(i)), 5.0 + s.vessels->rest.radius_mm[i]) << "vessel node " << i;
  }
  for (int i = 0; i < s.tumours[0].rest.positions_World_mm.cols(); ++i) EXPECT_GT(depth(s.tumours[0].rest.positions_World_mm.col(i)), 5.0);
}

// The bundled scene is what users copy: it ships the real-time (60 Hz) FEM setting, and
// liver_accurate.scene.yaml the accurate one on the same organ.
TEST(BundledScenes, RealTimeDefaultAndAccurateVariant) {
  const Scene rt = load_scene(test::source_dir() + "/data/liver/liver.scene.yaml");
  EXPECT_EQ(rt.model.kind, "corotational_fem");
  EXPECT_EQ(rt.model.linear_solver, "pcg");
  EXPECT_EQ(rt.model.iterations, 3);
  EXPECT_EQ(rt.model.refactor_every, 30);
  EXPECT_TRUE(rt.model.refactor_in_background);
  EXPECT_TRUE(rt.model.single_precision_preconditioner);
  const Scene acc = load_scene(test::source_dir() + "/data/liver/liver_accurate.scene.yaml");
  EXPECT_EQ(acc.model.kind, "corotational_fem");
  EXPECT_EQ(acc.model.iterations, 20);
  EXPECT_FALSE(acc.model.refactor_in_background);
  EXPECT_EQ(acc.problem.mesh.num_tets(), rt.problem.mesh.num_tets());
  EXPECT_EQ(acc.organ_surface.positions_World_mm.cols(), rt.organ_surface.positions_World_mm.cols());
}

TEST(BundledScenes, CoarseVariant) {
  const Scene s = load_scene(test::source_dir() + "/data/liver/liver_coarse.scene.yaml");
  EXPECT_LT(s.problem.mesh.num_tets(), 8000);
  EXPECT_GT(s.problem.mesh.num_tets(), 2000);
  EXPECT_EQ(s.organ_embedding.size(), 4996);  // full display surface carried by the coarse volume
  EXPECT_LE(s.organ_embedding.max_outside_mm, 3.0);
  EXPECT_GT(s.problem.fixed_vertices.size(), 10u);
}

// Another patient's liver (binary PLY) meshed with the surface kept: TetGen leaves flat
// tets lying on the surface; peeling removes those with two boundary faces, the boundary
// stays a closed 2-manifold and the display surface stays embedded.
TEST(PatientScenes, BoundarySliversArePeeledAndTheBoundaryStaysClosed) {
  const std::string dir = scratch("peel");
  const std::string base = test::source_dir() + "/data/patients/sksurgery_liver.scene.yaml";
  std::string text = read_text_file(base);
  text.replace(text.find("../meshes/"), 10, test::source_dir() + "/data/meshes/");
  const Scene plain = load_scene(write_file(dir, "plain.scene.yaml", text));
  std::string peel = text;
  peel.replace(peel.find("volume:\n"), 8, "volume:\n  peel_boundary_slivers_deg: 5\n");
  const Scene peeled = load_scene(write_file(dir, "peeled.scene.yaml", peel));
  const int removed = plain.problem.mesh.num_tets() - peeled.problem.mesh.num_tets();
  RecordProperty("peeled", std::to_string(removed));
  RecordProperty("slivers_before_after", std::to_string(plain.mesh_quality.slivers) + "/" + std::to_string(peeled.mesh_quality.slivers));
  EXPECT_GT(removed, 5);
  EXPECT_LT(peeled.mesh_quality.slivers, plain.mesh_quality.slivers / 2);
  EXPECT_EQ(peeled.problem.mesh.num_vertices(), plain.problem.mesh.num_vertices());  // no vertex lost
  bool noted = false;
  for (const auto& n : peeled.notes) noted = noted || n.find("peeled " + std::to_string(removed) + " boundary slivers") != std::string::npos;
  EXPECT_TRUE(noted);
  TriMesh boundary{peeled.problem.mesh.rest_positions_World_mm, peeled.problem.mesh.surface_tris};
  const SurfaceCheck check = validate_closed_surface(boundary, "peeled boundary");  // throws unless closed 2-manifold
  EXPECT_EQ(check.components, 1);
  EXPECT_NEAR(check.volume_mm3, validate_closed_surface(boundary, "again").volume_mm3, 1e-9);
  EXPECT_EQ(peeled.organ_embedding.size(), plain.organ_embedding.size());
  EXPECT_LE(peeled.organ_embedding.max_outside_mm, 0.5);
  // Out of range: named with its line.
  std::string bad = text;
  bad.replace(bad.find("volume:\n"), 8, "volume:\n  peel_boundary_slivers_deg: 45\n");
  const std::string path = write_file(dir, "bad.scene.yaml", bad);
  try {
    load_scene(path);
    ADD_FAILURE() << "accepted 45 degrees";
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("peel_boundary_slivers_deg must be in [0, 30]"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace arnav::host

namespace arnav::host {
namespace {

// Every scene the project ships (data/, the HIL bench's) is valid as written: its YAML
// parses with every key known and in range, and the files it names exist next to it. A
// newcomer's first run must not meet an error in our own configuration (issue 28).
TEST(BundledScenes, EverySceneShippedIsValidAndItsFilesExist) {
  namespace fs = std::filesystem;
  int scenes = 0;
  for (const char* folder : {"data", "hil_tests"})
    for (const auto& entry : fs::recursive_directory_iterator(fs::path(test::source_dir()) / folder)) {
      const std::string name = entry.path().filename().string();
      if (!entry.is_regular_file() || name.size() < 11 || name.substr(name.size() - 11) != ".scene.yaml") continue;
      ++scenes;
      const std::string path = entry.path().string();
      SceneSpec spec;
      const std::string error = error_of<LoadError>([&] { spec = parse_scene_spec(read_text_file(path), path); });
      EXPECT_EQ(error, "") << path;
      if (!error.empty()) continue;
      std::vector<const FileSpec*> files{&spec.organ};
      if (spec.volume.file) files.push_back(&*spec.volume.file);
      for (const auto& t : spec.tumours)
        if (t.surface) files.push_back(&*t.surface);
      if (spec.vessels && spec.vessels->file) files.push_back(&*spec.vessels->file);
      for (const FileSpec* f : files)
        EXPECT_TRUE(fs::exists(entry.path().parent_path() / f->path)) << path << ":" << f->line << ": " << f->path << " does not exist";
    }
  EXPECT_GE(scenes, 13);
}

}  // namespace
}  // namespace arnav::host
