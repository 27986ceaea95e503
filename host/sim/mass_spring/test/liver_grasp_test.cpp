// The bundled liver grasped and pulled as in arnav-bench deform's lobe_pull: a 10 mm
// surface patch at the tip of the hanging lobe, 200 mN/mm in all, pulled 25 mm along +x
// over 0.25 s, under gravity with the top fixed; 45 frames of 1/60 s. Before the volume
// term had its inversion barrier, 10 tets at the grasp stayed inverted with the
// local/global integrator (9 with the semi-implicit one).
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>

#include "host/scene/scene.hpp"
#include "host/mesh/test/test_paths.hpp"
#include "host/sim/mass_spring/mass_spring_model.hpp"

namespace arnav::host {
namespace {

int inverted_after_lobe_pull(MassSpringModel::Integrator integrator, int iterations, double tolerance) {
  Scene s = load_scene(test::source_dir() + "/data/liver/liver.scene.yaml");
  for (Material& m : s.problem.region_materials) m.damping_mass_per_s = 20.0;
  ModelConfig c;
  c.kind = "mass_spring";
  c.iterations = iterations;
  c.tolerance = tolerance;
  MassSpringModel model(s.problem, integrator, c);
  const Eigen::Matrix3Xd& p = s.organ_surface.positions_World_mm;
  const std::vector<int> patch = lowest_surface_patch(s, 10.0);
  const Eigen::Vector3d pull(25, 0, 0);
  std::vector<AttachmentId> ids;
  for (int g : patch)
    ids.push_back(model.add_attachment({s.organ_embedding.material_point(s.problem.mesh, g), p.col(g),
                                        200.0 / static_cast<double>(patch.size())}));
  for (int f = 0; f < 45; ++f) {
    const double ramp = std::min(1.0, (f + 1) / 60.0 / 0.25);
    for (std::size_t j = 0; j < ids.size(); ++j)
      model.set_attachment_target(ids[j], p.col(patch[j]) + ramp * pull);
    const StepSummary st = model.step(1.0 / 60.0);
    EXPECT_TRUE(st.healthy) << "frame " << f << ": " << st.warning;
  }
  const Eigen::Matrix3Xd& x = model.positions_World_mm();
  int inverted = 0;
  for (const auto& t : s.problem.mesh.tets) {
    const Eigen::Vector3d x0 = x.col(t[0]);
    if (!((x.col(t[1]) - x0).dot((x.col(t[2]) - x0).cross(x.col(t[3]) - x0)) > 0.0)) ++inverted;
  }
  return inverted;
}

TEST(MassSpringLiver, GraspedLobeLeavesFewTetsInverted) {
  const int local_global = inverted_after_lobe_pull(MassSpringModel::Integrator::kLocalGlobal, 1, 0.0);
  const int semi_implicit = inverted_after_lobe_pull(MassSpringModel::Integrator::kSemiImplicit, 20, 1e-4);
  RecordProperty("inverted_local_global", std::to_string(local_global));
  RecordProperty("inverted_semi_implicit", std::to_string(semi_implicit));
  // 2 remain in both: tets with 3-4 grasped vertices squeezed between attachments that
  // pull their material points to a rigidly translated patch (the FEM reference inverts
  // tets at this grasp too, docs/benchmarks.md). Bound 4: margin for another compiler's
  // rounding, still far below the 9-10 without the barrier.
  EXPECT_LE(local_global, 4);
  EXPECT_LE(semi_implicit, 4);
}

}  // namespace
}  // namespace arnav::host
