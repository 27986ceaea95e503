// arnav-phantom-record's core on the coarse liver (fast): the recording starts at the rest
// shape, the grasped patch follows the scripted pull, the tool pose is the scripted path,
// no load means no motion, and bad scripts are refused.
#include <gtest/gtest.h>

#include "hil_tests/phantom/phantom_record.hpp"
#include "host/scene/scene.hpp"

namespace arnav::hil {
namespace {

std::string coarse_scene() { return std::string(std::getenv("ARNAV_DATA_DIR")) + "/liver/liver_coarse.scene.yaml"; }

TEST(PhantomScript, PullRisesHoldsAndReturns) {
  PhantomScript s;
  EXPECT_EQ(s.pull_fraction(0.0), 0.0);
  EXPECT_NEAR(s.pull_fraction(s.start_s + s.ramp_s * 0.5), 0.5, 1e-12);
  EXPECT_EQ(s.pull_fraction(s.start_s + s.ramp_s + 0.5 * s.hold_s), 1.0);
  EXPECT_NEAR(s.pull_fraction(s.start_s + 2 * s.ramp_s + s.hold_s), 0.0, 1e-12);
  // Repeats after the rest.
  const double period = 2 * s.ramp_s + s.hold_s + s.rest_s;
  EXPECT_NEAR(s.pull_fraction(s.start_s + period + s.ramp_s * 0.5), 0.5, 1e-12);
}

TEST(PhantomRecord, GraspFollowsThePullFromTheRestShape) {
  PhantomScript s;
  s.fps = 10;
  s.duration_s = 1.0;
  s.start_s = 0.0;
  s.ramp_s = 0.5;
  s.hold_s = 2.0;
  s.pull_mm = Eigen::Vector3d(10, 5, -15);
  PhantomRecordStats st;
  const camera_sim::PhantomRecording rec = record_phantom(coarse_scene(), s, st);
  ASSERT_EQ(rec.frames.size(), 11u);
  EXPECT_TRUE(st.healthy) << st.warning;
  EXPECT_GT(st.grasped_vertices, 3);
  for (std::size_t k = 0; k < rec.frames.size(); ++k) EXPECT_NEAR(rec.frames[k].t_s, 0.1 * static_cast<double>(k), 1e-12);

  // Frame 0: the rest shape of the scene (what the host registers), tumour at rest.
  const host::Scene scene = host::load_scene(coarse_scene());
  const Eigen::Matrix3Xd rest = scene.organ_embedding.apply(scene.problem.mesh, scene.problem.mesh.rest_positions_World_mm);
  ASSERT_EQ(rec.vertex_count, rest.cols());
  EXPECT_LT((rec.frames[0].vertices_Model_mm - rest).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_TRUE(rec.frames[0].targets_Model_mm[0].isApprox(
      host::tumour_centroid_World_mm(scene, 0, scene.problem.mesh.rest_positions_World_mm), 1e-9));
  EXPECT_EQ(rec.target_names[0], "tumour_centroid");

  // The tool is the scripted path; the grasp centre follows it (stiff springs, soft tissue).
  const Eigen::Vector3d grasp = rec.frames[0].X_ModelTool[0].translation();
  Eigen::Index centre = 0;
  (rest.colwise() - grasp).colwise().squaredNorm().minCoeff(&centre);
  for (const auto& f : rec.frames) {
    EXPECT_TRUE(f.X_ModelTool[0].translation().isApprox(grasp + s.pull_fraction(f.t_s) * s.pull_mm, 1e-9));
    EXPECT_TRUE(f.X_ModelTool[0].linear().isApprox(rec.frames[0].X_ModelTool[0].linear()));
  }
  const Eigen::Vector3d moved = rec.frames.back().vertices_Model_mm.col(centre) - rest.col(centre);
  EXPECT_GT(moved.dot(s.pull_mm.normalized()), 0.6 * s.pull_mm.norm()) << moved.transpose();
  EXPECT_GT(moved.normalized().dot(s.pull_mm.normalized()), 0.9) << moved.transpose();
  // The tumour inside moves less than the grasped surface, but it moves.
  const double tumour_moved = (rec.frames.back().targets_Model_mm[0] - rec.frames[0].targets_Model_mm[0]).norm();
  EXPECT_GT(tumour_moved, 0.2);
  EXPECT_LT(tumour_moved, moved.norm());
  // Tool z along the patch's outward normal: pointing away from the organ's inside.
  const Eigen::Vector3d z = rec.frames[0].X_ModelTool[0].linear().col(2);
  EXPECT_GT(z.dot(grasp - rest.rowwise().mean()), 0.0);
}

TEST(PhantomRecord, NoPullNoMotion) {
  PhantomScript s;
  s.fps = 10;
  s.duration_s = 0.3;
  s.pull_mm.setZero();
  PhantomRecordStats st;
  const auto rec = record_phantom(coarse_scene(), s, st);
  for (const auto& f : rec.frames) EXPECT_LT((f.vertices_Model_mm - rec.frames[0].vertices_Model_mm).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT(st.max_tumour_displacement_mm, 1e-6);
}

// Skipping the rest frames before the pull (scripts/demo waits ~20 s for the registration):
// frame 0 and the last rest frame are kept, nothing at rest is solved, and the phantom at
// any time (the camera's interpolation) equals the recording made frame by frame.
TEST(PhantomRecord, SkippedRestFramesGiveTheSamePhantomAtEveryTime) {
  PhantomScript s;
  s.fps = 10;
  s.duration_s = 1.6;
  s.start_s = 0.85;
  s.ramp_s = 0.5;
  s.hold_s = 2.0;
  s.pull_mm = Eigen::Vector3d(10, 5, -15);
  PhantomRecordStats full_st, skip_st;
  const camera_sim::PhantomRecording full = record_phantom(coarse_scene(), s, full_st);
  s.skip_rest_frames = true;
  const camera_sim::PhantomRecording skipped = record_phantom(coarse_scene(), s, skip_st);
  ASSERT_EQ(full.frames.size(), 17u);
  // Kept: 0, then 0.8 s (the last rest frame: 0.9 s is past the start) and every frame after.
  ASSERT_EQ(skipped.frames.size(), 10u);
  EXPECT_EQ(skip_st.frames, 10);
  EXPECT_NEAR(skipped.frames[0].t_s, 0.0, 1e-12);
  EXPECT_NEAR(skipped.frames[1].t_s, 0.8, 1e-12);
  EXPECT_LT((skipped.frames[1].vertices_Model_mm - full.frames[0].vertices_Model_mm).cwiseAbs().maxCoeff(), 1e-9);
  for (double t = 0.0; t <= 1.6; t += 0.0375) {
    const camera_sim::PhantomFrame a = full.at(t), b = skipped.at(t);
    EXPECT_LT((a.vertices_Model_mm - b.vertices_Model_mm).cwiseAbs().maxCoeff(), 1e-6) << "t = " << t;
    EXPECT_LT((a.targets_Model_mm[0] - b.targets_Model_mm[0]).norm(), 1e-6) << "t = " << t;
    EXPECT_LT((a.X_ModelTool[0].translation() - b.X_ModelTool[0].translation()).norm(), 1e-9) << "t = " << t;
  }
  EXPECT_GT((full.frames.back().targets_Model_mm[0] - full.frames[0].targets_Model_mm[0]).norm(), 0.1) << "the pull moved the tumour";
}

TEST(PhantomRecord, CompareTumourCentroidsAgainstTheReference) {
  camera_sim::PhantomRecording ref, model;
  for (int k = 0; k < 5; ++k) {
    camera_sim::PhantomFrame f;
    f.t_s = 0.1 * k;
    f.targets_Model_mm = {Eigen::Vector3d(2.0 * k, 0, 0)};  // the reference tumour moves 2 mm per frame
    ref.frames.push_back(f);
    f.targets_Model_mm = {Eigen::Vector3d(2.0 * k, 1.0, 0)};  // the model: 1 mm off throughout
    model.frames.push_back(f);
  }
  const CentroidComparison c = compare_tumour_centroids(ref, model);
  EXPECT_NEAR(c.model_mean_mm, 1.0, 1e-12);
  EXPECT_NEAR(c.model_max_mm, 1.0, 1e-12);
  EXPECT_NEAR(c.rigid_mean_mm, 4.0, 1e-12);  // (0 + 2 + 4 + 6 + 8) / 5
  EXPECT_NEAR(c.rigid_max_mm, 8.0, 1e-12);
  EXPECT_NEAR(c.rigid_p95_mm, 8.0, 1e-12);
  model.frames.pop_back();
  EXPECT_THROW(compare_tumour_centroids(ref, model), std::invalid_argument);
}

TEST(PhantomRecord, BadScriptsAndScenesAreRefused) {
  PhantomRecordStats st;
  PhantomScript s;
  s.fps = 0;
  EXPECT_THROW(record_phantom(coarse_scene(), s, st), std::invalid_argument);
  s = PhantomScript{};
  s.ramp_s = 0;
  EXPECT_THROW(record_phantom(coarse_scene(), s, st), std::invalid_argument);
  s = PhantomScript{};
  s.grasp_radius_mm = -1;
  EXPECT_THROW(record_phantom(coarse_scene(), s, st), std::invalid_argument);
  EXPECT_THROW(record_phantom("/nonexistent/scene.yaml", PhantomScript{}, st), std::exception);
}

}  // namespace
}  // namespace arnav::hil
