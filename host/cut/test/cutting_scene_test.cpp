// The scene's cutting section: parsed only when declared, defaults, file:line errors.
#include <gtest/gtest.h>

#include "host/cut/cut_session.hpp"
#include "host/mesh/load_error.hpp"
#include "host/scene/scene.hpp"
#include "host/scene/scene_spec.hpp"
#include "protocol/testing/error_of.hpp"

using namespace arnav::host;

namespace {
const std::string kBase =
    "organ: {surface: block.obj}\nvolume: {file: block.vtk}\n"
    "materials:\n  default: {youngs_modulus_kPa: 5, poisson_ratio: 0.45, density_kg_per_mm3: 1e-6}\n"
    "model: {kind: xpbd}\n";
std::string error_of(const std::string& text) {
  return arnav::testing::error_of<LoadError>([&] { parse_scene_spec(text, "s.yaml"); });
}
}  // namespace

TEST(CuttingSection, OnlyWhenDeclaredWithDefaults) {
  EXPECT_FALSE(parse_scene_spec(kBase, "s.yaml").cutting.has_value());
  const SceneSpec s = parse_scene_spec(kBase + "cutting:\n", "s.yaml");
  ASSERT_TRUE(s.cutting.has_value());
  EXPECT_EQ(s.cutting->tumour_margin_mm, 10.0);
  EXPECT_EQ(s.cutting->snap_fraction, 0.1);
  EXPECT_EQ(s.cutting->path_tolerance_mm, 0.1);
  EXPECT_EQ(s.cutting->min_dihedral_deg, 5.0);
  EXPECT_EQ(s.cutting->line, 6);
  const SceneSpec t = parse_scene_spec(kBase + "cutting:\n  blade: {tip_mm: [1, 2, 3], heel_mm: [1, 2, 33]}\n  tumour_margin_mm: 5\n"
                                               "  snap_fraction: 0.2\n  path_tolerance_mm: 0.05\n  sweep_strips: 4\n  push_stiffness_mN_per_mm: 10\n", "s.yaml");
  EXPECT_EQ(t.cutting->blade_heel_Tool_mm, Eigen::Vector3d(1, 2, 33));
  EXPECT_EQ(t.cutting->tumour_margin_mm, 5.0);
  EXPECT_EQ(t.cutting->snap_fraction, 0.2);
  EXPECT_EQ(t.cutting->path_tolerance_mm, 0.05);
  EXPECT_EQ(t.cutting->sweep_strips, 4);
  EXPECT_EQ(t.cutting->push_stiffness_mN_per_mm, 10.0);
  EXPECT_EQ(parse_scene_spec(kBase + "cutting:\n  min_dihedral_deg: 2.5\n", "s.yaml").cutting->min_dihedral_deg, 2.5);
  EXPECT_EQ(parse_scene_spec(kBase + "cutting:\n  min_dihedral_deg: 0\n", "s.yaml").cutting->min_dihedral_deg, 0.0);  // off
  // Refinement ahead of the blade: off unless the scene asks for it; the settings the
  // session, the bench and arnav-sim take from the section carry it.
  EXPECT_EQ(s.cutting->chord_sagitta_mm, 0.0);
  const SceneSpec r = parse_scene_spec(kBase + "cutting:\n  chord_sagitta_mm: 1.5\n  min_refined_edge_mm: 4\n  path_tolerance_mm: 0.2\n", "s.yaml");
  EXPECT_EQ(r.cutting->chord_sagitta_mm, 1.5);
  EXPECT_EQ(r.cutting->min_refined_edge_mm, 4.0);
  const cut::CutSessionSettings settings = cut::cut_settings_from(*r.cutting);
  EXPECT_EQ(settings.cut.chord_sagitta_mm, 1.5);
  EXPECT_EQ(settings.cut.min_refined_edge_mm, 4.0);
  EXPECT_EQ(settings.cut.path_tolerance_mm, 0.2);  // the live session dropped it before
}

TEST(CuttingSection, ErrorsNameTheLine) {
  EXPECT_NE(error_of(kBase + "cutting:\n  margin: 3\n").find("s.yaml:7: unknown key 'margin' in cutting"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  snap_fraction: 0.7\n").find("s.yaml:7: cutting.snap_fraction must be in (0, 0.5) (got 0.7)"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  path_tolerance_mm: -1\n").find("s.yaml:7: cutting.path_tolerance_mm must be >= 0 (got -1)"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  tumour_margin_mm: -1\n").find("s.yaml:7: cutting.tumour_margin_mm must be >= 0"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 0]}\n").find("s.yaml:7: cutting.blade: tip and heel"),
            std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  sweep_strips: 0\n").find("s.yaml:7: cutting.sweep_strips = 0 is out of range"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  push_stiffness_mN_per_mm: 0\n").find("must be positive"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  min_dihedral_deg: -1\n").find("s.yaml:7: cutting.min_dihedral_deg must be in [0, 30]"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  chord_sagitta_mm: -1\n").find("s.yaml:7: cutting.chord_sagitta_mm must be in [0, 100] mm"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  min_refined_edge_mm: 0.5\n").find("s.yaml:7: cutting.min_refined_edge_mm must be in [1, 1000] mm"),
            std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  min_dihedral_deg: 45\n").find("s.yaml:7: cutting.min_dihedral_deg must be in [0, 30]"), std::string::npos);
  EXPECT_NE(error_of(kBase + "cutting:\n  min_dihedral_deg: flat\n").find("s.yaml:7"), std::string::npos);
}

TEST(CuttingSection, BundledCuttingSceneLoads) {
  const std::string data = std::getenv("ARNAV_DATA_DIR") ? std::getenv("ARNAV_DATA_DIR") : "data";
  const Scene scene = load_scene(data + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  EXPECT_EQ(scene.cutting->tumour_margin_mm, 10.0);
  EXPECT_FALSE(load_scene(data + "/liver/liver_coarse.scene.yaml").cutting.has_value());
}
