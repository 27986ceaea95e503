// The model's surfaces on the bus (host/app/surface_publisher.hpp): messages from a real
// cutting model's snapshots (organ = the cut volume's boundary, compacted to the vertices it
// uses, in Ref; tumour; cut faces only once there is a cut), the publisher thread's
// per-channel sequence and its silence before a registration, and surfaces.publish_rate_hz
// checked at load with file:line. Waits are bounded by generous timeouts; nothing asserts on speed.
#include <gtest/gtest.h>

#include <chrono>
#include <mutex>
#include <set>
#include <thread>

#include "host/app/session_config.hpp"
#include "host/app/surface_publisher.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/overlay/overlay_renderer.hpp"
#include "protocol/clock.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

Eigen::Isometry3d some_X_RefModel() {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.2, 1, 0.3).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(-30, 12, -1400);
  return X;
}

// Every triangle of `msg` is the triangle of `mesh` at the same index, moved into Ref.
void expect_same_triangles(const surface_mesh_t& msg, const TriMesh& mesh, const Eigen::Isometry3d& X_RefModel) {
  ASSERT_EQ(msg.num_triangles, static_cast<int>(mesh.tris.size()));
  ASSERT_EQ(msg.triangles.size(), mesh.tris.size());
  ASSERT_EQ(msg.num_vertices, static_cast<int>(msg.positions_mm.size()));
  std::set<int> used;
  for (const auto& t : mesh.tris) used.insert(t.begin(), t.end());
  EXPECT_EQ(msg.positions_mm.size(), used.size());  // only the vertices the triangles use
  double worst_mm = 0.0;
  for (std::size_t i = 0; i < mesh.tris.size(); ++i)
    for (std::size_t k = 0; k < 3; ++k) {
      const int id = msg.triangles[i][k];
      ASSERT_GE(id, 0);
      ASSERT_LT(id, msg.num_vertices);
      const auto& p = msg.positions_mm[static_cast<std::size_t>(id)];
      const Eigen::Vector3d expected = X_RefModel * mesh.positions_World_mm.col(mesh.tris[i][k]);
      worst_mm = std::max(worst_mm, (Eigen::Vector3d(p[0], p[1], p[2]) - expected).norm());
    }
  EXPECT_LT(worst_mm, 1e-3);  // float32 of positions around 1.4 m
}

TEST(SurfaceMessages, CuttingModelOrganTumourAndCutInRef) {
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ModelRunner runner(scene, 60.0, false, 5.0, 0, cut::CutSessionSettings{});
  runner.expect_blade();
  const Eigen::Isometry3d X = some_X_RefModel();
  const auto rest = surface_messages(*runner.snapshot(), X, 1'764'633'600'000'000, 1'764'633'600'000'100);
  ASSERT_EQ(rest.size(), 2u);  // organ and tumour; no cut yet: no "cut" message
  EXPECT_EQ(rest[0].name, "organ");
  EXPECT_EQ(rest[1].name, "tumour");
  EXPECT_EQ(rest[0].frame_name, "Ref");
  EXPECT_EQ(rest[0].model_step_wall_us, 1'764'633'600'000'000);
  EXPECT_EQ(rest[0].publish_time_wall_us, 1'764'633'600'000'100);
  expect_same_triangles(rest[0], runner.snapshot()->organ, X);

  std::int64_t t = 60 * 16'667;  // the vertical cut through the tumour of cutting_session_test
  for (int f = 0; f <= 45; ++f, t += 16'667) {
    runner.push_blade({t, std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(71.3, 125 + 2 * f, 100), Eigen::Vector3d(71.3, 125 + 2 * f, 200)}, true}, t);
    runner.advance_to(t, 1);
  }
  const auto snap = runner.snapshot();
  ASSERT_TRUE(snap->cut_surface);
  const auto cut = surface_messages(*snap, X, 1, 2);
  ASSERT_EQ(cut.size(), 3u);
  EXPECT_EQ(cut[2].name, "cut");
  EXPECT_EQ(cut[0].model_step, snap->step);
  EXPECT_EQ(cut[0].model_time_us, snap->step_device_time_us);
  expect_same_triangles(cut[0], snap->organ, X);
  expect_same_triangles(cut[1], snap->tumours[0], X);
  expect_same_triangles(cut[2], *snap->cut_surface, X);
  // The organ is the cut volume's boundary: its cut faces are among the organ's triangles.
  EXPECT_GT(cut[0].num_triangles, rest[0].num_triangles);
  EXPECT_LT(cut[2].num_triangles, cut[0].num_triangles);
  EXPECT_GT(cut[0].num_vertices, rest[0].num_vertices);  // the cut added vertices to the boundary
  EXPECT_FLOAT_EQ(cut[1].rgba[0], overlay::OverlayStyle{}.tumour.r);
  EXPECT_FLOAT_EQ(cut[2].rgba[1], overlay::OverlayStyle{}.cut.g);
}

template <class Pred>
bool wait_until(Pred pred, double timeout_s = 20.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!pred()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

TEST(SurfacePublisher, NothingBeforeRegistrationThenSequencedPerChannel) {
  auto snap = std::make_shared<ModelSnapshot>();
  snap->step = 7;
  snap->step_done_mono_us = monotonic_us() - 20'000;
  snap->organ.positions_World_mm = Eigen::Matrix3Xd::Random(3, 5);
  snap->organ.tris = {{0, 1, 2}, {0, 2, 3}};
  snap->tumours.push_back(snap->organ);
  std::mutex mutex;
  std::optional<Eigen::Isometry3d> X;
  std::vector<std::pair<std::string, surface_mesh_t>> got;
  SurfacePublisher publisher(
      200.0,
      [&] {
        std::lock_guard lock(mutex);
        return SurfaceSource{snap, X};
      },
      [&](const std::string& channel, const surface_mesh_t& m) {
        std::lock_guard lock(mutex);
        got.emplace_back(channel, m);
        return true;
      });
  ASSERT_TRUE(wait_until([&] { return publisher.stats().rounds_unregistered >= 3; }));
  {
    std::lock_guard lock(mutex);
    EXPECT_TRUE(got.empty());
    X = Eigen::Isometry3d::Identity();
  }
  ASSERT_TRUE(wait_until([&] {
    std::lock_guard lock(mutex);
    return got.size() >= 6;
  }));
  publisher.stop();
  std::lock_guard lock(mutex);
  std::map<std::string, std::int64_t> last;
  for (const auto& [channel, m] : got) {
    EXPECT_EQ(channel, "ARNAV_SURFACE_" + m.name);
    EXPECT_EQ(m.sequence, last[channel] + 1) << channel;
    last[channel] = m.sequence;
    EXPECT_EQ(m.model_step, 7);
    EXPECT_EQ(m.num_vertices, 4);  // vertex 4 is not used
    // The step's UTC time: 20 ms before the publish time (the host's clocks, at most a round apart).
    EXPECT_LT(m.model_step_wall_us, m.publish_time_wall_us);
    EXPECT_GT(m.model_step_wall_us, m.publish_time_wall_us - 10'000'000);
  }
  EXPECT_EQ(last.size(), 2u);  // organ and tumour
  EXPECT_EQ(publisher.stats().publish_failures, 0);
}

// The rest state is shown from the model's start until the first step, which may take
// longer than a round (a loaded machine): its stamp is the start, so the first step's own
// time (when the host began it, before the rest state's later rounds) never goes back.
TEST(SurfacePublisher, TimeStampsNeverGoBackFromTheRestStateToTheFirstStep) {
  const std::int64_t started = monotonic_us() - 1'000'000;
  auto rest = std::make_shared<ModelSnapshot>();
  rest->step = 0;
  rest->step_done_mono_us = -1;
  rest->organ.positions_World_mm = Eigen::Matrix3Xd::Random(3, 3);
  rest->organ.tris = {{0, 1, 2}};
  auto first = std::make_shared<ModelSnapshot>(*rest);
  first->step = 1;
  first->step_done_mono_us = started + 500'000;  // begun half a second ago, finished only now
  std::mutex mutex;
  std::shared_ptr<const ModelSnapshot> current = rest;
  std::vector<surface_mesh_t> got;
  SurfacePublisher publisher(
      200.0,
      [&] {
        std::lock_guard lock(mutex);
        return SurfaceSource{current, Eigen::Isometry3d::Identity()};
      },
      [&](const std::string&, const surface_mesh_t& m) {
        std::lock_guard lock(mutex);
        got.push_back(m);
        return true;
      },
      {}, started);
  ASSERT_TRUE(wait_until([&] {
    std::lock_guard lock(mutex);
    return got.size() >= 3;
  }));
  {
    std::lock_guard lock(mutex);
    current = first;
  }
  ASSERT_TRUE(wait_until([&] {
    std::lock_guard lock(mutex);
    return !got.empty() && got.back().model_step == 1;
  }));
  publisher.stop();
  std::int64_t last = 0;
  for (const auto& m : got) {
    EXPECT_GE(m.model_step_wall_us, last) << "step " << m.model_step;
    last = m.model_step_wall_us;
  }
  EXPECT_LT(got.front().model_step_wall_us, got.front().publish_time_wall_us - 900'000);  // the start, not the publish time
}

TEST(SessionConfig, SurfacesPublishRateCheckedAtLoad) {
  SessionFolder f("surfaces");
  const std::string v = "arnav_session_version: 1\n";
  EXPECT_DOUBLE_EQ(load_session(f.write("default.yaml", v)).surfaces.publish_rate_hz, 10.0);
  EXPECT_DOUBLE_EQ(load_session(f.write("off.yaml", v + "surfaces: {publish_rate_hz: 0}\n")).surfaces.publish_rate_hz, 0.0);
  EXPECT_DOUBLE_EQ(load_session(f.write("five.yaml", v + "surfaces:\n  publish_rate_hz: 5\n")).surfaces.publish_rate_hz, 5.0);
  EXPECT_NE(session_error_of(f, v + "surfaces:\n  publish_rate_hz: -1\n").find("bad.yaml:3: key 'surfaces.publish_rate_hz': must be between 0"),
            std::string::npos)
      << session_error_of(f, v + "surfaces:\n  publish_rate_hz: -1\n");
  EXPECT_NE(session_error_of(f, v + "surfaces:\n  publish_rate_hz: .nan\n").find("bad.yaml:3: key 'surfaces.publish_rate_hz'"), std::string::npos)
      << session_error_of(f, v + "surfaces:\n  publish_rate_hz: .nan\n");
  EXPECT_NE(session_error_of(f, v + "surfaces:\n  rate_hz: 5\n").find("bad.yaml:3: key 'surfaces.rate_hz': unknown key"), std::string::npos)
      << session_error_of(f, v + "surfaces:\n  rate_hz: 5\n");
}

}  // namespace
}  // namespace arnav::host
