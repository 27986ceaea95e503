// The tracked grasper coupled to the tissue model (host/app/grasp_coupling.hpp,
// tools.grasper; docs/overlay.md "Grasper"): grasp attaches the organ surface near the tip
// and the surface there follows the tool; releasing the input or a stale grasper pose frees
// it; the session file's errors; the navigation session drives it from tracked poses.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>

#include "arnav/input_event_t.hpp"
#include "host/app/grasp_coupling.hpp"
#include "host/app/navigation_session.hpp"
#include "host/scene/scene.hpp"
#include "host/sim/model_factory.hpp"
#include "session_test_util.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

class Grasp : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(load_scene(data_dir() + "/liver/liver_coarse.scene.yaml"));
    scene_->problem.gravity_World_mm_s2.setZero();
  }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  static Scene* scene_;

  Eigen::Matrix3Xd surface(const TissueModel& m) const { return scene_->organ_embedding.apply(scene_->problem.mesh, m.positions_World_mm()); }
  // The organ surface vertex nearest to p (rest shape).
  int surface_vertex_near(const Eigen::Vector3d& p) const {
    const Eigen::Matrix3Xd s = scene_->organ_embedding.apply(scene_->problem.mesh, scene_->problem.mesh.rest_positions_World_mm);
    Eigen::Index i = 0;
    (s.colwise() - p).colwise().squaredNorm().minCoeff(&i);
    return static_cast<int>(i);
  }
  static GrasperRole role(bool always) {
    GrasperRole g;
    g.name = "grasper";
    g.stale_after_ms = 100;
    g.radius_mm = 10;
    g.grasp_always = always;
    if (!always) g.grasp_input = InputBinding{"pedal_left", 1000, 1};
    return g;
  }
  static GraspCommand at(const Eigen::Vector3d& tip, std::int64_t t_us, bool requested) {
    GraspCommand c;
    c.X_ModelTool = Eigen::Isometry3d(Eigen::Translation3d(tip));
    c.pose_time_us = t_us;
    c.device_time_us = t_us;
    c.requested = requested;
    if (!requested) c.why_not = "input 'pedal_left' released";
    return c;
  }
};
Scene* Grasp::scene_ = nullptr;

TEST_F(Grasp, AttachesTheSurfaceNearTheTipWhichFollowsTheToolAndIsFreedOnRelease) {
  auto model = make_tissue_model(scene_->problem, scene_->model);
  const int v0 = surface_vertex_near({70, 160, 60});  // the underside near the tumour
  const Eigen::Matrix3Xd rest = surface(*model);
  const Eigen::Vector3d p0 = rest.col(v0);
  GraspCoupling g(role(false), *scene_);
  std::int64_t t = 1'000'000;
  const double dt = 1.0 / 60.0;

  // Not requested (input released): nothing attached.
  g.apply(*model, at(p0, t, false), t);
  EXPECT_FALSE(g.status().grasping);
  // Requested: the surface vertices within 10 mm of the tip, and only those.
  g.apply(*model, at(p0, t, true), t);
  ASSERT_TRUE(g.status().grasping);
  int expected = 0;
  for (Eigen::Index i = 0; i < rest.cols(); ++i) expected += (rest.col(i) - p0).norm() <= 10.0 ? 1 : 0;
  EXPECT_EQ(g.status().attached_vertices, expected);
  EXPECT_GT(expected, 3);
  for (int v : g.grasped_surface_vertices()) EXPECT_LE((rest.col(v) - p0).norm(), 10.0);
  EXPECT_EQ(g.status().grasps, 1);

  // The tool moves 12 mm (a smooth ramp over 1 s, then held): the grasped surface follows.
  const Eigen::Vector3d pull(6, 3, -10.4);  // |pull| = 12.4 mm, away from the underside
  for (int k = 1; k <= 150; ++k) {
    t += 16'667;
    const Eigen::Vector3d tip = p0 + std::min(1.0, k / 60.0) * pull;
    g.apply(*model, at(tip, t, true), t);
    ASSERT_TRUE(model->step(dt).healthy);
  }
  const Eigen::Matrix3Xd pulled = surface(*model);
  EXPECT_LT((pulled.col(v0) - (p0 + pull)).norm(), 1.5) << "the surface at the tip follows the tool";
  EXPECT_NEAR(g.status().tip_travel_mm, pull.norm(), 1e-9);
  // Far from the grasp (> 80 mm) the organ barely moves.
  double far_sum = 0.0;
  int far_n = 0;
  for (Eigen::Index i = 0; i < rest.cols(); ++i)
    if ((rest.col(i) - p0).norm() > 80.0) far_sum += (pulled.col(i) - rest.col(i)).norm(), ++far_n;
  ASSERT_GT(far_n, 10);
  EXPECT_LT(far_sum / far_n, 0.2 * pull.norm());
  // Release (input let go): the springs are removed and the tissue relaxes toward rest.
  g.apply(*model, at(p0 + pull, t, false), t);
  EXPECT_FALSE(g.status().grasping);
  EXPECT_EQ(g.status().releases, 1);
  EXPECT_EQ(g.status().stale_releases, 0);
  for (int k = 0; k < 150; ++k) {
    t += 16'667;
    g.apply(*model, at(p0 + pull, t, false), t);
    ASSERT_TRUE(model->step(dt).healthy);
  }
  EXPECT_LT((surface(*model).col(v0) - p0).norm(), 0.25 * pull.norm()) << "released: the organ returns toward its rest shape";
}

TEST_F(Grasp, StaleGrasperPoseReleasesAndFarTipIsRefused) {
  auto model = make_tissue_model(scene_->problem, scene_->model);
  const int v0 = surface_vertex_near({70, 160, 60});
  const Eigen::Vector3d p0 = surface(*model).col(v0);
  GraspCoupling g(role(true), *scene_);
  std::int64_t t = 5'000'000;
  // 40 mm out from the surface: no grasp (counted once per request), nothing attached.
  const Eigen::Vector3d out = p0 + Eigen::Vector3d(0, 0, -40);
  g.apply(*model, at(out, t, true), t);
  g.apply(*model, at(out, t + 16'667, true), t + 16'667);
  EXPECT_FALSE(g.status().grasping);
  EXPECT_EQ(g.status().refused, 1);
  // At the surface: grasps.
  t += 100'000;
  g.apply(*model, at(p0, t, true), t);
  ASSERT_TRUE(g.status().grasping);
  const Eigen::Vector3d pulled_tip = p0 + Eigen::Vector3d(0, 0, -8);
  for (int k = 1; k <= 60; ++k) {
    t += 16'667;
    g.apply(*model, at(p0 + std::min(1.0, k / 30.0) * (pulled_tip - p0), t, true), t);
    model->step(1.0 / 60.0);
  }
  EXPECT_GT((surface(*model).col(v0) - p0).norm(), 5.0);
  // The grasper's pose stops arriving: within its limit the grasp holds ...
  const std::int64_t last_pose = t;
  const GraspCommand frozen = at(pulled_tip, last_pose, true);
  g.apply(*model, frozen, last_pose + 90'000);
  EXPECT_TRUE(g.status().grasping);
  // ... past it (100 ms) the tissue is released, never pinned to the stale pose.
  g.apply(*model, frozen, last_pose + 120'000);
  EXPECT_FALSE(g.status().grasping);
  EXPECT_TRUE(g.status().stale);
  EXPECT_EQ(g.status().stale_releases, 1);
  EXPECT_EQ(g.status().releases, 0);
  for (int k = 0; k < 150; ++k) {
    g.apply(*model, frozen, last_pose + 120'000 + k * 16'667);
    model->step(1.0 / 60.0);
  }
  EXPECT_FALSE(g.status().grasping);
  EXPECT_LT((surface(*model).col(v0) - p0).norm(), 2.5) << "the organ relaxed: nothing holds it at the stale pose";
  // A lost pose (none at all) also releases; the tool tracked again near the surface grasps anew.
  t = last_pose + 3'000'000;
  g.apply(*model, at(p0, t, true), t);
  EXPECT_TRUE(g.status().grasping);
  EXPECT_EQ(g.status().grasps, 2);
  GraspCommand none;
  none.requested = true;
  g.apply(*model, none, t + 16'667);
  EXPECT_FALSE(g.status().grasping);
  EXPECT_EQ(g.status().stale_releases, 2);
  EXPECT_FALSE(g.status().messages.empty());
}

std::string error_of(const SessionFolder& f, const std::string& text) { return session_error_of(f, text); }

TEST(GraspConfig, ParsesAndNamesFileLineKey) {
  SessionFolder f("grasp_config");
  const std::string head = "arnav_session_version: 1\nscene: " + data_dir() +
                           "/liver/liver_coarse.scene.yaml\nregistration: X_RefModel.yaml\ntools:\n  reference: {name: ref}\n";
  const SessionConfig c = load_session(
      f.write("ok.yaml", head + "  grasper: {name: g, stale_after_ms: 80, tip_mm: [0, 0, 5], radius_mm: 12, grasp: {input: pedal_left}}\n"));
  ASSERT_TRUE(c.grasper);
  EXPECT_EQ(c.grasper->name, "g");
  EXPECT_DOUBLE_EQ(c.grasper->stale_after_ms, 80);
  EXPECT_DOUBLE_EQ(c.grasper->radius_mm, 12);
  EXPECT_EQ(c.grasper->tip_Tool_mm, Eigen::Vector3d(0, 0, 5));
  ASSERT_TRUE(c.grasper->grasp_input);
  EXPECT_EQ(c.grasper->grasp_input->input, "pedal_left");
  EXPECT_FALSE(c.grasper->grasp_always);
  const SessionConfig a = load_session(f.write("always.yaml", head + "  grasper: {name: g, radius_mm: 15, grasp: {always: true}}\n"));
  EXPECT_TRUE(a.grasper->grasp_always);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, grasp: {always: true}}\n").find("bad.yaml:6: key 'tools.grasper.radius_mm': missing"),
            std::string::npos);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, radius_mm: 10}\n").find("bad.yaml:6: key 'tools.grasper.grasp': missing"),
            std::string::npos);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, radius_mm: 10, grasp: {always: false}}\n").find("key 'tools.grasper.grasp.always'"),
            std::string::npos);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, radius_mm: 10, grasp: {inpt: x}}\n").find("key 'tools.grasper.grasp"), std::string::npos);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, radius_mm: 10, grasp: {always: true}, jaw: 3}\n").find("bad.yaml:6: key 'tools.grasper.jaw': unknown key"),
            std::string::npos);
  EXPECT_NE(error_of(f, head + "  grasper: {name: g, radius_mm: -1, grasp: {always: true}}\n").find("key 'tools.grasper.radius_mm': must be between"),
            std::string::npos);
  EXPECT_NE(error_of(f, "arnav_session_version: 1\ntools:\n  grasper: {name: g, radius_mm: 10, grasp: {always: true}}\n").find("bad.yaml:3: key 'tools.grasper': a grasper needs a scene"),
            std::string::npos);
}

input_event_t pedal(bool pressed, std::int64_t seq, std::int64_t t_us, bool snapshot = false) {
  return input_msg("pedal_left", pressed, seq, t_us, snapshot);
}

// The session end to end without a camera (replay-style, unthreaded): tracked reference and
// grasper in the tracker frame, through the registration into Model; the pedal grasps.
TEST_F(Grasp, SessionCouplesTheTrackedGrasperThroughTheRegistration) {
  SessionFolder f("grasp_session");
  const std::string text = "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                           "/liver/liver_coarse.scene.yaml\nregistration: X_RefModel.yaml\n"
                           "tools:\n  reference: {name: ref, stale_after_ms: 100}\n"
                           "  grasper: {name: grasper, stale_after_ms: 100, tip_mm: [0, 0, 20], radius_mm: 10, grasp: {input: pedal_left}}\n"
                           "model: {rate_hz: 60, gravity: false}\n";
  SessionOptions o;
  o.threaded = false;
  NavigationSession s(load_session(f.write("session.yaml", text)), std::make_unique<Scene>(*scene_), o);
  const Eigen::Isometry3d X_RefModel = test_X_RefModel();
  Eigen::Isometry3d X_NdiRef = Eigen::Isometry3d::Identity();
  X_NdiRef.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.2, 0.3, 1).normalized()).toRotationMatrix();
  X_NdiRef.translation() = Eigen::Vector3d(-50, 120, -1400);
  const int v0 = surface_vertex_near({70, 160, 60});
  const Eigen::Matrix3Xd rest = scene_->organ_embedding.apply(scene_->problem.mesh, scene_->problem.mesh.rest_positions_World_mm);
  const Eigen::Vector3d p0 = rest.col(v0);
  // Tool frame: tip 20 mm along its z; turned, so the tip offset matters.
  const Eigen::Matrix3d R_ModelTool = Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 0, 0)).toRotationMatrix();
  const auto X_ModelTool = [&](const Eigen::Vector3d& tip) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = R_ModelTool;
    X.translation() = tip - R_ModelTool * Eigen::Vector3d(0, 0, 20);
    return X;
  };
  const Eigen::Vector3d pull(0, 0, -10);
  std::int64_t seq = 0;
  bool pedal_down = false;
  const auto tick = [&](std::int64_t k, const Eigen::Vector3d& tip) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    if (k % 10 == 0) s.on_input(pedal(pedal_down, seq, t, true), t + 200);  // the appliance's state snapshots
    s.on_pose(pose_msg("ref", "Ndi", X_NdiRef, k, t, true, tool_pose_t::SOURCE_NDI), t + 500);
    s.on_pose(pose_msg("grasper", "Ndi", X_NdiRef * X_RefModel * X_ModelTool(tip), k, t, true, tool_pose_t::SOURCE_NDI), t + 600);
    s.advance_model(t + 1000);
    return t;
  };
  std::int64_t k = 0;
  for (; k < 10; ++k) tick(k, p0);
  ASSERT_TRUE(s.grasp_status());
  EXPECT_FALSE(s.grasp_status()->grasping) << "pedal not pressed yet";
  pedal_down = true;
  s.on_input(pedal(true, ++seq, 1'000'000 + k * 16'667), 1'000'000 + k * 16'667);
  for (int j = 0; j < 120; ++j, ++k) tick(k, p0 + std::min(1.0, j / 40.0) * pull);
  ASSERT_TRUE(s.grasp_status()->grasping);
  EXPECT_GT(s.grasp_status()->attached_vertices, 3);
  EXPECT_NEAR(s.grasp_status()->tip_travel_mm, pull.norm(), 0.05) << "the tip, through the registration, in Model";
  pedal_down = false;
  s.on_input(pedal(false, ++seq, 1'000'000 + k * 16'667), 1'000'000 + k * 16'667);
  // The release goes with the next grasper pose; the model step that takes it runs once the
  // tracker's next frame shows nothing measured by its time is still coming (docs/overlay.md,
  // "Model clock"): two tracker frames.
  tick(k++, p0 + pull);
  tick(k++, p0 + pull);
  EXPECT_FALSE(s.grasp_status()->grasping);
  EXPECT_EQ(s.grasp_status()->releases, 1);
  const nlohmann::json j = s.summary_json(3.0);
  ASSERT_TRUE(j.contains("grasper"));
  EXPECT_EQ(j["grasper"]["grasps"].get<int>(), 1);
  EXPECT_EQ(j["grasper"]["releases"].get<int>(), 1);
  // Pressed again, then the grasper stops being tracked: released as stale.
  pedal_down = true;
  s.on_input(pedal(true, ++seq, 1'000'000 + k * 16'667), 1'000'000 + k * 16'667);
  for (int j2 = 0; j2 < 5; ++j2, ++k) tick(k, p0 + pull);
  // The tissue relaxed from the first pull while released: the tip 10 mm out may be too far; grasp at the surface.
  for (int j2 = 0; j2 < 60; ++j2, ++k) tick(k, p0);
  ASSERT_TRUE(s.grasp_status()->grasping);
  for (int j2 = 0; j2 < 20; ++j2, ++k) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    s.on_pose(pose_msg("ref", "Ndi", X_NdiRef, k, t, true, tool_pose_t::SOURCE_NDI), t + 500);  // grasper missing
    s.advance_model(t + 1000);
  }
  EXPECT_FALSE(s.grasp_status()->grasping);
  EXPECT_GE(s.grasp_status()->stale_releases, 1);
  bool said = false;
  for (const auto& m : s.messages()) said = said || m.find("STALE") != std::string::npos;
  EXPECT_TRUE(said);
}

}  // namespace
}  // namespace arnav::host

namespace arnav::host {
namespace {

// With a grasper the overlay draws the model as the tool had it when the frame was
// captured: snapshot_at(device time) picks the newest snapshot whose step's device time
// (and so its grasper pose) is no later than the capture.
TEST_F(Grasp, SnapshotAtTheFramesCaptureTimeFollowsTheGrasperPoseTime) {
  ModelRunner runner(*scene_, 60.0, false, 5.0);
  GrasperRole g = role(true);
  runner.enable_grasper(g);
  const int v0 = surface_vertex_near({70, 160, 60});
  const Eigen::Vector3d p0 = scene_->organ_embedding.apply(scene_->problem.mesh, scene_->problem.mesh.rest_positions_World_mm).col(v0);
  std::int64_t t = 1'000'000;
  const std::int64_t device0 = 3000 * 16'667;  // the tracker's clock, on the model's grid
  for (int k = 0; k < 40; ++k, t += 16'667) {
    GraspCommand c = at(p0 + std::min(1.0, k / 20.0) * Eigen::Vector3d(0, 0, -8), device0 + k * 16'667, true);
    runner.push_grasp({device0 + k * 16'667, c}, t);
    runner.advance_to(t, 1);
  }
  ASSERT_TRUE(runner.grasp_status().grasping);
  const auto newest = runner.snapshot();
  EXPECT_EQ(newest->grasper_device_time_us, device0 + 39 * 16'667);
  EXPECT_EQ(runner.snapshot_at(60'000'000)->step, newest->step);
  const auto earlier = runner.snapshot_at(device0 + 10 * 16'667 + 5);  // a frame captured when the tool was at pose 10
  EXPECT_EQ(earlier->grasper_device_time_us, device0 + 10 * 16'667);
  EXPECT_LT(earlier->step, newest->step);
  // The tumour drawn for that frame is where the model had it then, not now.
  EXPECT_GT((earlier->tumour_centroids_mm[0] - newest->tumour_centroids_mm[0]).norm(), 0.05);
  // Older than everything kept: the oldest snapshot kept (about one second).
  EXPECT_LE(runner.snapshot_at(0)->step, newest->step - 30);
}

// The cutting settings of the scene's `cutting:` section.
cut::CutSessionSettings cut_settings(const Scene& scene) { return cut::cut_settings_from(*scene.cutting); }

// A grasper on a cutting scene (the coarse liver with cutting:): the model is a host/cut
// CutSession; the grasp holds through the cuts the scalpel makes beside it (the model updated
// or rebuilt on the cut mesh, the springs kept by vertex id) and its release removes them
// for good (the organ relaxes, no spring comes back with a later cut).
TEST(GraspCutting, GraspHoldsThroughCutsAndReleasesForGood) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  ModelRunner runner(scene, 60.0, false, 5.0, 0, cut_settings(scene));
  ASSERT_TRUE(runner.cutting());
  runner.expect_blade();
  GrasperRole g;
  g.name = "grasper";
  g.stale_after_ms = 100;
  g.radius_mm = 15;
  g.grasp_always = true;
  ASSERT_NO_THROW(runner.enable_grasper(g));
  const Eigen::Matrix3Xd rest = scene.organ_embedding.apply(scene.problem.mesh, scene.problem.mesh.rest_positions_World_mm);
  Eigen::Index v0 = 0;
  (rest.colwise() - Eigen::Vector3d(70, 160, 60)).colwise().squaredNorm().minCoeff(&v0);
  const Eigen::Vector3d p0 = rest.col(v0);
  const auto surface_at = [&](const ModelSnapshot& s) { return Eigen::Vector3d(scene.organ_embedding.apply(scene.problem.mesh, s.volume_positions_World_mm).col(v0)); };
  const auto grasp = [&](const Eigen::Vector3d& tip, std::int64_t t, bool requested) {
    GraspCommand c;
    c.X_ModelTool = Eigen::Isometry3d(Eigen::Translation3d(tip));
    c.pose_time_us = t;
    c.device_time_us = t;
    c.requested = requested;
    if (!requested) c.why_not = "released by the test";
    runner.push_grasp({t, c}, t);
  };
  // The blade: vertical (tip below the organ, heel 60 mm up), 35 mm beside the grasp in x,
  // drawn along y at 20 mm/s through the underside while the grasper pulls.
  const auto blade = [&](double y) {
    return std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(p0.x() + 35, y, p0.z() - 20), Eigen::Vector3d(p0.x() + 35, y, p0.z() + 40)};
  };
  const Eigen::Vector3d pull(6, 3, -10.4);
  std::int64_t t = 60 * 16'667;  // on the model's grid of device times
  int k = 0;
  for (; k < 240; ++k, t += 16'667) {
    grasp(p0 + std::min(1.0, k / 60.0) * pull, t, true);
    const double y = std::clamp(p0.y() - 40 + 20.0 * (k - 30) / 60.0, p0.y() - 40, p0.y() + 40);
    runner.push_blade({t, blade(y), k >= 30}, t);
    runner.advance_to(t, 1);
  }
  auto snap = runner.snapshot();
  ASSERT_TRUE(snap->healthy) << snap->warning;
  EXPECT_GT(snap->cut_steps_total, 3) << "the blade cut beside the grasp";
  EXPECT_GT(snap->cut_faces, 10);
  GraspStatus st = runner.grasp_status();
  ASSERT_TRUE(st.grasping);
  EXPECT_EQ(st.grasps, 1);
  EXPECT_EQ(st.releases + st.stale_releases + st.refused, 0);
  EXPECT_GT(st.attached_vertices, 3);
  EXPECT_LT((surface_at(*snap) - (p0 + pull)).norm(), 1.5) << "the grasped surface follows the tool through the cuts";
  // The cut-path error is measured in the material: the tissue the grasper moves after the
  // blade passed does not count (measured in Model now, these points are mm off the sweeps).
  {
    std::vector<double> e;
    for (const auto& r : runner.cut_steps(0))
      if (r.new_cut_vertices > 0) e.push_back(r.path_error_mm);
    ASSERT_GT(e.size(), 3u);
    std::sort(e.begin(), e.end());
    std::printf("[grasp + cut] cut-path error over %zu steps: p50 %.3f mm, max %.3f mm\n", e.size(), e[e.size() / 2], e.back());
  }
  // Released: the springs are gone; the organ relaxes toward rest while the blade cuts on.
  const std::int64_t cut_steps_grasping = snap->cut_steps_total;
  std::int64_t cut_steps_while_released = 0;
  for (int r = 0; r < 240; ++r, ++k, t += 16'667) {
    grasp(p0 + pull, t, false);
    const double y = std::clamp(p0.y() + 40 - 20.0 * r / 60.0, p0.y() - 40, p0.y() + 40);
    if (r < 120)
      runner.push_blade({t, blade(y), true}, t);
    else
      runner.push_blade({t, std::nullopt, false}, t);  // the scalpel taken away (a blade left in the slot would push)
    runner.advance_to(t, 1);
    if (r == 119) cut_steps_while_released = runner.snapshot()->cut_steps_total;
  }
  EXPECT_GT(cut_steps_while_released, cut_steps_grasping) << "the blade cut again after the release";
  snap = runner.snapshot();
  st = runner.grasp_status();
  EXPECT_FALSE(st.grasping);
  EXPECT_EQ(st.releases, 1);
  EXPECT_LT((surface_at(*snap) - p0).norm(), 0.25 * pull.norm()) << "released: no spring holds the organ any more";
}

// A stroke while the grasper pulls the tissue across the blade's path: the scalpel is
// sampled at 240 Hz (four samples per model step), the grasper at 60 Hz. Every vertex the
// cut puts on a cut face is checked against the surfaces the blade swept, in the material
// (ModelRunner's cut-path error). The same samples handed in as a loaded machine would (the
// model thread late, stepping in bursts of six) give the same cut, vertex by vertex.
constexpr double kPi = 3.14159265358979323846;

struct PulledStroke {
  std::vector<double> path_error_mm;        // per step with new cut vertices
  std::vector<ModelRunner::CutVertex> cut;  // the cut at the end
  bool healthy = false;
};

// gaps: the tracker misses the scalpel now and then, as a loaded bench's did: every 37th
// sample has no blade (markers not seen) and twice the scalpel goes silent for 150 ms (a
// lost BX reply's timeout), mid-stroke.
// A curved stroke: the blade goes round a circle (radius_mm, from -angle_deg to +angle_deg)
// instead of along a line. radius_mm 0: the straight stroke.
// stall_steps: the model thread does not run for that many steps from the stroke's 30th step
// on (descheduled on a loaded machine), so the model falls further behind than its catch-up.
struct Arc {
  double radius_mm = 0.0;
  double angle_deg = 0.0;
};

// sagitta_mm >= 0: refinement ahead of the blade (CutSettings::chord_sagitta_mm) instead of the scene's.
PulledStroke pulled_stroke(const Scene& scene, int burst, bool gaps = false, Arc arc = {}, int stall_steps = 0, double sagitta_mm = -1) {
  cut::CutSessionSettings settings = cut_settings(scene);
  if (sagitta_mm >= 0) settings.cut.chord_sagitta_mm = sagitta_mm;
  ModelRunner runner(scene, 60.0, false, 5.0, 0, settings);
  runner.expect_blade();
  GrasperRole g;
  g.name = "grasper";
  g.stale_after_ms = 100;
  g.radius_mm = 15;
  g.grasp_always = true;
  runner.enable_grasper(g);
  const Eigen::Matrix3Xd rest = scene.organ_embedding.apply(scene.problem.mesh, scene.problem.mesh.rest_positions_World_mm);
  Eigen::Index v0 = 0;
  (rest.colwise() - Eigen::Vector3d(70, 160, 60)).colwise().squaredNorm().minCoeff(&v0);
  const Eigen::Vector3d p0 = rest.col(v0);
  // The grasp 30 mm beside the blade's line pulls toward and along it (x and y) and down.
  const Eigen::Vector3d pull(-12, 8, -8);
  const auto blade = [&](double y) {
    if (arc.radius_mm > 0) {  // the distance travelled, y - (p0.y() - 45), along the arc
      const double end = arc.angle_deg * kPi / 180.0, r = arc.radius_mm;
      const double angle = std::min(-end + (y - (p0.y() - 45)) / r, end);
      const Eigen::Vector3d c(p0.x() + 30 - r * std::cos(angle), p0.y() + r * std::sin(angle), 0.0);
      return std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(c.x(), c.y(), p0.z() - 20), Eigen::Vector3d(c.x(), c.y(), p0.z() + 40)};
    }
    return std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(p0.x() + 30, y, p0.z() - 20), Eigen::Vector3d(p0.x() + 30, y, p0.z() + 40)};
  };
  const std::int64_t t0 = 60 * 16'667;
  const int steps = 180;
  std::int64_t host = t0;
  for (int k = 0; k < steps; ++k) {
    const std::int64_t t = t0 + k * 16'667;
    GraspCommand c;
    c.X_ModelTool = Eigen::Isometry3d(Eigen::Translation3d(p0 + std::min(1.0, k / 90.0) * pull));
    c.pose_time_us = c.device_time_us = t;
    c.requested = true;
    for (int j = 0; j < 4; ++j) {  // 240 Hz scalpel: 30 mm/s along y from step 30 on
      const std::int64_t ts = t + j * 4'167;
      const double y = p0.y() - 45 + 30.0 * std::max(0.0, (ts - t0) * 1e-6 - 0.5);
      const int sample = 4 * k + j;
      if (gaps && ((sample >= 300 && sample < 336) || (sample >= 500 && sample < 536))) continue;  // silent 150 ms
      if (gaps && sample % 37 == 0) {
        runner.push_blade({ts, std::nullopt, k >= 30}, ts + 1'000);  // the markers not seen
        continue;
      }
      runner.push_blade({ts, blade(y), k >= 30}, ts + 1'000);
    }
    runner.push_grasp({t, c}, t + 1'000);
    host = t + 1'000;
    const bool stalled = k >= 60 && k < 60 + stall_steps;
    if ((k + 1) % burst == 0 && !stalled) runner.advance_to(host + 50'000);  // burst > 1: the model thread ran late
  }
  runner.advance_to(host + 50'000);
  PulledStroke out;
  for (const auto& r : runner.cut_steps(0))
    if (r.new_cut_vertices > 0) out.path_error_mm.push_back(r.path_error_mm);
  out.cut = runner.cut_vertices();
  out.healthy = runner.snapshot()->healthy;
  return out;
}

// Issue 20's targets on a stroke's per-step worst new cut vertex: p95 <= 1 mm, max <= 3 mm.
void expect_on_the_blades_path(const PulledStroke& stroke, const char* what) {
  ASSERT_TRUE(stroke.healthy);
  ASSERT_GT(stroke.path_error_mm.size(), 10u);
  std::vector<double> e = stroke.path_error_mm;
  std::sort(e.begin(), e.end());
  const double p95 = e[static_cast<std::size_t>(0.95 * static_cast<double>(e.size() - 1))];
  std::printf("[%s] cut-path error in the material over %zu steps: p50 %.3f mm, p95 %.3f mm, max %.3f mm; %zu cut vertices\n", what,
              e.size(), e[e.size() / 2], p95, e.back(), stroke.cut.size());
  EXPECT_LE(p95, 1.0);
  EXPECT_LE(e.back(), 3.0);
}

TEST(GraspCutting, CutVerticesLieOnTheSweptSurfaceInTheMaterialWhileTheTissueIsPulled) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  const PulledStroke idle = pulled_stroke(scene, 1);
  expect_on_the_blades_path(idle, "pulled stroke");
  const PulledStroke loaded = pulled_stroke(scene, 6);
  ASSERT_EQ(loaded.cut.size(), idle.cut.size()) << "the late model thread cut differently";
  double worst = 0.0;
  for (std::size_t i = 0; i < idle.cut.size(); ++i) {
    ASSERT_EQ(loaded.cut[i].id, idle.cut[i].id);
    worst = std::max({worst, (loaded.cut[i].rest_mm - idle.cut[i].rest_mm).norm(), (loaded.cut[i].now_mm - idle.cut[i].now_mm).norm()});
  }
  EXPECT_LE(worst, 1e-6) << "same samples, same cut, whatever the thread's timing";
}

// The model thread stalled for 1.5 s mid-stroke (more than the clock's 1 s catch-up): it
// used to skip the stalled time's grid steps, so the blade samples of those 1.5 s all met
// the tissue as it was before the stall and the grasper's pull came after them in one jump.
// Now the stroke's steps all run, late, each with its own samples and the tissue as it was
// then: the same cut as the idle run, to 1e-6 mm (issue 20, item 2).
TEST(GraspCutting, AModelThreadStalledMidStrokeCatchesUpAlongTheBladesPath) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  const PulledStroke idle = pulled_stroke(scene, 1);
  const PulledStroke stalled = pulled_stroke(scene, 1, false, {}, 90);
  expect_on_the_blades_path(stalled, "pulled stroke, model stalled 1.5 s");
  ASSERT_EQ(stalled.cut.size(), idle.cut.size()) << "the stalled model thread cut differently";
  double worst = 0.0;
  for (std::size_t i = 0; i < idle.cut.size(); ++i) {
    ASSERT_EQ(stalled.cut[i].id, idle.cut[i].id);
    worst = std::max({worst, (stalled.cut[i].rest_mm - idle.cut[i].rest_mm).norm(), (stalled.cut[i].now_mm - idle.cut[i].now_mm).norm()});
  }
  EXPECT_LE(worst, 1e-6) << "same samples, same cut, however long the model thread stalled";
}

// The same stroke with the tracker missing the scalpel (single samples without the blade, two
// 150 ms silences mid-stroke): the stroke goes on across the gaps (issue 20: each gap ended
// the stroke, and the stroke's end completed the tets the blade was in, up to 18 mm off its
// path), so the cut stays on the blade's path as without gaps.
TEST(GraspCutting, TrackerGapsMidStrokeDoNotTakeTheCutOffThePath) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  expect_on_the_blades_path(pulled_stroke(scene, 1, true), "pulled stroke, tracker gaps");
}

// Curved strokes (the blade round a circle, as round a tumour; the demo's ring has a 21 mm
// radius) while the grasper pulls: edges the curved cut passes between (chords of the cut)
// and tets the tissue carried away from the blade before their crossings were complete get
// their points where the blade went in the material (issue 20: from the plane through a
// tet's points, such points were up to 9 mm off on the demo's ring; a chord's mid-point
// stayed where it was once the lips had opened). Radii of 20-30 mm over 200 and 340 degrees.
// Tighter curves on this coarse mesh (edges 16-40 mm) are a known limit: docs/benchmarks.md.
class CurvedStroke : public ::testing::TestWithParam<Arc> {};

TEST_P(CurvedStroke, StaysOnTheBladesPathWhileTheTissueIsPulled) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  const Arc arc = GetParam();
  const std::string what = "pulled stroke round " + std::to_string(static_cast<int>(arc.radius_mm)) + " mm, +-" +
                           std::to_string(static_cast<int>(arc.angle_deg)) + " deg";
  expect_on_the_blades_path(pulled_stroke(scene, 1, false, arc), what.c_str());
}

INSTANTIATE_TEST_SUITE_P(GraspCutting, CurvedStroke,
                         ::testing::Values(Arc{20, 100}, Arc{20, 170}, Arc{25, 100}, Arc{25, 170}, Arc{30, 100}, Arc{30, 170}),
                         [](const ::testing::TestParamInfo<Arc>& arc_info) {
                           return "Radius" + std::to_string(static_cast<int>(arc_info.param.radius_mm)) + "mmTo" +
                                  std::to_string(static_cast<int>(arc_info.param.angle_deg)) + "Deg";
                         });

// A tighter curve (15 mm radius, +-100 degrees) than the coarse mesh's tets can follow: its
// chords' mid-points stay off the curve (measured without refinement: p95 0.7, max 1.6 mm).
// With refinement ahead of the blade (cutting.chord_sagitta_mm s: edges over sqrt(8 s 15 mm)
// bisected before the blade enters their tets) it meets issue 20's targets, and the late
// model thread (bursts of six steps) still cuts the same, vertex by vertex: the refinement
// depends on the blade's path in the material only. At s = 1.5 and 3 mm a tet completed
// mid-stroke took points 7.6-8.0 mm off the path from sides the surface in the material had
// not reached yet (such completions now wait: TetCutter::complete_from_sides).
class RefinedTightCurve : public ::testing::TestWithParam<double> {};

TEST_P(RefinedTightCurve, StaysOnThePathAndCutsTheSameWhenTheModelIsLate) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  const Arc arc{15, 100};
  const double s_mm = GetParam();
  const std::string what = "pulled stroke round 15 mm, refined ahead of the blade, s = " + std::to_string(s_mm) + " mm";
  const PulledStroke idle = pulled_stroke(scene, 1, false, arc, 0, s_mm);
  expect_on_the_blades_path(idle, what.c_str());
  const PulledStroke loaded = pulled_stroke(scene, 6, false, arc, 0, s_mm);
  ASSERT_EQ(loaded.cut.size(), idle.cut.size()) << "the late model thread refined or cut differently";
  double worst = 0.0;
  for (std::size_t i = 0; i < idle.cut.size(); ++i) {
    ASSERT_EQ(loaded.cut[i].id, idle.cut[i].id);
    worst = std::max({worst, (loaded.cut[i].rest_mm - idle.cut[i].rest_mm).norm(), (loaded.cut[i].now_mm - idle.cut[i].now_mm).norm()});
  }
  EXPECT_LE(worst, 1e-6);
}

INSTANTIATE_TEST_SUITE_P(GraspCutting, RefinedTightCurve, ::testing::Values(1.0, 1.5, 3.0),
                         [](const ::testing::TestParamInfo<double>& s_info) {
                           return "Sagitta" + std::to_string(static_cast<int>(10 * s_info.param)) + "TenthsMm";
                         });

// A blade that comes back from a tracker gap far from where it was (lifted out and put in
// 30 mm along while the tracker missed it, the pedal held) starts a new stroke: no cut is
// drawn across the 30 mm it never went through (the gap bridge holds for a blade back within
// 10 mm only).
TEST(GraspCutting, BladeBackFarFromAGapDoesNotCutAChord) {
  Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ASSERT_TRUE(scene.cutting.has_value());
  ModelRunner runner(scene, 60.0, false, 5.0, 0, cut_settings(scene));
  runner.expect_blade();
  const Eigen::Matrix3Xd rest = scene.organ_embedding.apply(scene.problem.mesh, scene.problem.mesh.rest_positions_World_mm);
  Eigen::Index v0 = 0;
  (rest.colwise() - Eigen::Vector3d(70, 160, 60)).colwise().squaredNorm().minCoeff(&v0);
  const Eigen::Vector3d p0 = rest.col(v0);
  const auto blade = [&](double y) {
    return std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(p0.x() + 30, y, p0.z() - 20), Eigen::Vector3d(p0.x() + 30, y, p0.z() + 40)};
  };
  const std::int64_t t0 = 60 * 16'667;
  const double y_gap = p0.y() - 30, y_back = y_gap + 30;  // the blade leaves the tracker at y_gap, is back at y_back
  std::int64_t host = t0;
  for (int k = 0; k < 120; ++k) {
    const std::int64_t t = t0 + k * 16'667;
    for (int j = 0; j < 4; ++j) {
      const std::int64_t ts = t + j * 4'167;
      const double s = (ts - t0) * 1e-6;  // 20 mm/s along y from y_gap - 10, then 200 ms unseen
      double y = y_gap - 10 + 20.0 * std::min(s, 0.5);
      if (s > 0.5 && s < 0.7) continue;
      if (s >= 0.7) y = y_back + 20.0 * (s - 0.7);
      runner.push_blade({ts, blade(y), true}, ts + 1'000);
    }
    host = t + 1'000;
  }
  runner.advance_to(host + 50'000);
  const std::vector<ModelRunner::CutVertex> cut = runner.cut_vertices();
  ASSERT_GT(cut.size(), 10u);
  int across = 0;
  for (const auto& c : cut)
    if (c.rest_mm.y() > y_gap + 5 && c.rest_mm.y() < y_back - 5) ++across;
  EXPECT_EQ(across, 0) << "cut vertices in the 30 mm the blade skipped while unseen";
}

}  // namespace
}  // namespace arnav::host

namespace arnav::host {
namespace {

// On the overlay: frames while grasping carry the `grasping` flag; the grasper's poses
// stop: the tissue is released and every frame says so (banner + `grasper_stale`).
TEST_F(Grasp, StaleGrasperIsBanneredOnTheOverlay) {
  SessionFolder f("grasp_banner");
  const std::string text = "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                           "/liver/liver_coarse.scene.yaml\nregistration: X_RefModel.yaml\n"
                           "tools:\n  reference: {name: liver_marker, stale_after_ms: 100}\n"
                           "  grasper: {name: grasper, stale_after_ms: 100, radius_mm: 10, grasp: {always: true}}\n"
                           "camera:\n  name: cam0\n  intrinsics: camera.yaml\n  pose_from: reference\n"
                           "model: {rate_hz: 60, gravity: false}\n";
  SessionOptions o;
  o.threaded = false;
  NavigationSession s(load_session(f.write("session.yaml", text)), std::make_unique<Scene>(*scene_), o);
  const int v0 = surface_vertex_near({70, 160, 60});
  const Eigen::Vector3d p0 = scene_->organ_embedding.apply(scene_->problem.mesh, scene_->problem.mesh.rest_positions_World_mm).col(v0);
  const auto frame = [&](std::int64_t k, bool grasper_tracked) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    const Eigen::Isometry3d X_CamRef = test_X_CamRef(k);
    s.on_pose(pose_msg("liver_marker", "Cam", X_CamRef, k, t), t + 2000);
    const Eigen::Vector3d tip = p0 + std::min(1.0, k / 20.0) * Eigen::Vector3d(0, 0, -6);
    if (grasper_tracked)
      s.on_pose(pose_msg("grasper", "Cam", X_CamRef * test_X_RefModel() * Eigen::Isometry3d(Eigen::Translation3d(tip)), k, t, true,
                         tool_pose_t::SOURCE_NDI),
                t + 2500);  // after the board pose it pairs with
    s.advance_model(t + 3000);
    return s.render_frame(frame_msg(k, t), t + 5000);
  };
  std::int64_t k = 0;
  for (; k < 30; ++k) {
    const FrameResult r = frame(k, true);
    if (k >= 2) {
      EXPECT_NE(r.row.flags.find("grasping"), std::string::npos) << "frame " << k << ": " << r.row.flags;
    }
    for (const auto& b : r.banners) {
      EXPECT_EQ(b.find("GRASPER"), std::string::npos) << "frame " << k << ": " << b;
    }
  }
  ASSERT_TRUE(s.grasp_status()->grasping);
  int bannered = 0;
  for (int j = 0; j < 20; ++j, ++k) {
    const FrameResult r = frame(k, false);
    bool banner = false;
    for (const auto& b : r.banners) banner = banner || b.find("GRASPER STALE: 'grasper' - tissue released (1 stale release(s))") != std::string::npos;
    if (j >= 10) {  // 100 ms limit + one model step
      EXPECT_TRUE(banner) << "frame " << k;
      EXPECT_NE(r.row.flags.find("grasper_stale"), std::string::npos) << r.row.flags;
    }
    bannered += banner ? 1 : 0;
  }
  EXPECT_FALSE(s.grasp_status()->grasping);
  EXPECT_EQ(s.grasp_status()->stale_releases, 1);
  EXPECT_GE(bannered, 10);
  EXPECT_EQ(s.summary_json(1.0)["grasper"]["frames_stale_banner"].get<int>(), bannered);
}

}  // namespace
}  // namespace arnav::host
