#include <gtest/gtest.h>

#include <algorithm>

#include "host/mesh/box_mesh.hpp"
#include "host/sim/model_factory.hpp"

namespace arnav::host {
namespace {

SimProblem small_problem() {
  SimProblem p;
  p.mesh = make_box_tet_mesh(2, 2, 2, {20, 20, 20});
  p.region_materials = {Material{}};
  return p;
}

TEST(ModelFactory, EveryVariantBuildsAndSteps) {
  const auto variants = model_variants();
  ASSERT_FALSE(variants.empty());
  for (const ModelVariant& v : variants) {
    auto model = make_tissue_model(small_problem(), v.config);
    ASSERT_NE(model, nullptr);
    EXPECT_EQ(model->name(), v.label);
    ModelConfig c = v.config;
    c.substeps = std::max(c.substeps, 20);  // small enough for the explicit bound
    model = make_tissue_model(small_problem(), c);
    const StepSummary s = model->step(1e-3);
    EXPECT_TRUE(s.healthy) << v.label << ": " << s.warning;
    EXPECT_EQ(model->positions_World_mm().cols(), 27);
    EXPECT_EQ(model->element_measures().size(), 48u);
  }
  for (const std::string& kind : available_model_kinds()) {
    bool found = false;
    for (const ModelVariant& v : variants) found = found || v.config.kind == kind;
    EXPECT_TRUE(found) << kind << " has no variant";
  }
}

// Mass-spring and XPBD have no beam coupling: a declared vessel tree must not be dropped
// silently.
TEST(ModelFactory, ModelsWithoutBeamsSayTheyIgnoreVessels) {
  SimProblem p = small_problem();
  VesselTree tree;
  tree.nodes_World_mm.resize(3, 2);
  tree.nodes_World_mm << 5, 15, 10, 10, 10, 10;
  tree.radius_mm = {1.0, 1.0};
  tree.segments = {{0, 1}};
  p.vessels = tree;
  for (const ModelVariant& v : model_variants()) {
    if (v.config.kind != "mass_spring" && v.config.kind != "xpbd") continue;
    ModelConfig c = v.config;
    c.substeps = std::max(c.substeps, 20);
    const StepSummary s = make_tissue_model(p, c)->step(1e-3);
    EXPECT_NE(s.warning.find("vessel tree ignored"), std::string::npos) << v.label << ": " << s.warning;
    EXPECT_EQ(make_tissue_model(small_problem(), c)->step(1e-3).warning.find("vessel"), std::string::npos);
  }
}

TEST(ModelFactory, RejectsUnknownKindAndBadSettingsByName) {
  ModelConfig c;
  c.kind = "finite_volume";
  try {
    make_tissue_model(small_problem(), c);
    FAIL() << "unknown kind accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("finite_volume"), std::string::npos) << e.what();
  }
  c.kind = "mass_spring";
  c.integrator = "leapfrog";
  EXPECT_THROW(make_tissue_model(small_problem(), c), std::invalid_argument);
  c.integrator = "explicit";
  c.substeps = 0;
  EXPECT_THROW(make_tissue_model(small_problem(), c), std::invalid_argument);
  c.substeps = 1;
  c.threads = 0;
  EXPECT_THROW(make_tissue_model(small_problem(), c), std::invalid_argument);
  c.threads = 1;
  SimProblem no_material = small_problem();
  no_material.region_materials.clear();
  EXPECT_THROW(make_tissue_model(no_material, c), std::invalid_argument);
}

}  // namespace
}  // namespace arnav::host

namespace arnav::host {
namespace {

// check_setting_holds (issue 29): the quasi-static FEM on a body nothing holds is refused at load
// (singular stiffness), naming the key and both fixes; with a fixed vertex it is accepted and steps.
TEST(ModelFactory, QuasiStaticFemWithoutFixedVertexIsRefusedAtLoad) {
  const auto kinds = available_model_kinds();
  if (std::find(kinds.begin(), kinds.end(), "corotational_fem") == kinds.end()) GTEST_SKIP() << "built without the FEM";
  SimProblem p = small_problem();
  for (const std::string material : {"corotational_linear", "stable_neo_hookean"}) {
    ModelConfig c;
    c.kind = "corotational_fem";
    c.material_model = material;
    c.integrator = "quasi_static";
    c.linear_solver = "cholmod";
    std::string message;
    try {
      check_setting_holds(p, c, 1.0 / 60.0);
    } catch (const std::invalid_argument& e) {
      message = e.what();
    }
    EXPECT_NE(message.find("model.integrator: quasi_static"), std::string::npos) << material << ": " << message;
    EXPECT_NE(message.find("boundary.fixed"), std::string::npos) << message;
    EXPECT_FALSE(make_tissue_model(p, c)->step(1.0 / 60.0).healthy) << material;  // what the refusal spares the user
    SimProblem held = p;
    for (int i = 0; i < held.mesh.num_vertices(); ++i)
      if (held.mesh.rest_positions_World_mm(2, i) < 1e-9) held.fixed_vertices.push_back(i);  // the bottom face
    EXPECT_NO_THROW(check_setting_holds(held, c, 1.0 / 60.0)) << material;
    EXPECT_TRUE(make_tissue_model(held, c)->step(1.0 / 60.0).healthy) << material;
  }
}

// check_setting_holds (issue 29): an explicit mass-spring setting beyond its stability bound
// even at the step control's budget (8x the substeps at 1/60 s) is refused before the run,
// naming the key and the substeps that hold; that count is accepted, and so is a count the
// budget holds (the model then takes the substeps the bound needs, counted as step control).
TEST(ModelFactory, SettingThatCannotHoldIsRefusedAtLoadNamingTheFix) {
  SimProblem p = small_problem();
  p.region_materials[0].youngs_modulus_kPa = 5000.0;  // stiff: the explicit bound shrinks
  for (const ModelVariant& v : model_variants()) {
    if (v.label != "mass_spring/explicit") {
      EXPECT_NO_THROW(check_setting_holds(p, v.config, 1.0 / 20.0)) << v.label;
      continue;
    }
    ModelConfig c = v.config;
    c.substeps = 1;
    std::string message;
    try {
      check_setting_holds(p, c, 1.0 / 60.0);
    } catch (const std::invalid_argument& e) {
      message = e.what();
    }
    ASSERT_NE(message.find("model.substeps"), std::string::npos) << message;
    EXPECT_NE(message.find("even at the step control's budget of 8 substeps"), std::string::npos) << message;
    const std::size_t at = message.find("model.substeps >= ");
    ASSERT_NE(at, std::string::npos) << message;
    const int named = std::stoi(message.substr(at + 18));
    EXPECT_GT(named, 8);
    c.substeps = named;
    EXPECT_NO_THROW(check_setting_holds(p, c, 1.0 / 60.0));
    StepSummary s = make_tissue_model(p, c)->step(1.0 / 60.0);
    EXPECT_TRUE(s.healthy) << s.warning;  // the named setting does hold
    EXPECT_EQ(s.warning.find("step control"), std::string::npos) << s.warning;
    c.substeps = (named + 7) / 8;  // within the budget: accepted, the step control takes the rest
    EXPECT_NO_THROW(check_setting_holds(p, c, 1.0 / 60.0));
    s = make_tissue_model(p, c)->step(1.0 / 60.0);
    EXPECT_TRUE(s.healthy) << s.warning;
    EXPECT_NE(s.warning.find("step control: "), std::string::npos) << s.warning;
    EXPECT_GE(s.iterations, named);
  }
}

}  // namespace
}  // namespace arnav::host
