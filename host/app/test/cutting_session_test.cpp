// The navigation session with cutting and live registration (no LCM): the pedal held
// cuts the organ along the scalpel's path (the cut faces lie on the surface the blade
// swept, are drawn where it projects, and overlay.csv's cut columns say so); released,
// the blade only pushes; a lost pedal state disarms cutting with a banner, counted; live
// pointer landmarks recover a known X_RefModel; bad inputs/cutting/registration.live
// sections name file:line and the fix.
#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <algorithm>
#include <set>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "arnav/input_event_t.hpp"
#include "host/app/model_runner.hpp"
#include "host/app/navigation_session.hpp"
#include "host/app/session_config.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

std::string cut_session_text(const std::string& extra) {
  return "arnav_session_version: 1\n"
         "lcm_url: \"memq://\"\n"
         "scene: " + data_dir() + "/liver/liver_coarse_cut.scene.yaml\n"
         "registration: X_RefModel.yaml\n"
         "tools:\n"
         "  reference: {name: liver_marker, stale_after_ms: 100}\n"
         "  scalpel: {name: scalpel, stale_after_ms: 100, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 60]}}\n"
         "camera:\n"
         "  name: cam0\n"
         "  intrinsics: camera.yaml\n"
         "  pose_from: reference\n"
         "model: {rate_hz: 60, gravity: false}\n"
         "overlay: {margin_mm: 5, warn_mm: 5}\n" + extra;
}

class CuttingRun : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene_ = new Scene(load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml")); }
  static void TearDownTestSuite() { delete scene_; }
  static Scene* scene_;

  std::unique_ptr<NavigationSession> make(const SessionFolder& f, const std::string& extra, const std::string& record_dir = "") {
    SessionOptions o;
    o.threaded = false;
    o.keep_last_frame = true;
    o.record_dir = record_dir;
    return std::make_unique<NavigationSession>(load_session(f.write("cut.yaml", cut_session_text(extra))), std::make_unique<Scene>(*scene_), o);
  }
  static std::int64_t time_of(std::int64_t k) { return 1'000'000 + k * 16'667; }
  static FrameResult step(NavigationSession& s, std::int64_t k) {
    const std::int64_t t = time_of(k);
    s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t + 2000);
    s.advance_model(t + 4000);
    return s.render_frame(frame_msg(k, t), t + 5000);
  }
  // The stroke: the blade inclined 45 degrees about its direction of motion, tip 18 mm above
  // the tumour centre (8 mm above the tumour at its closest, frame 20), moving 1.1 mm per frame.
  static Eigen::Vector3d direction() { return Eigen::Vector3d(1, 0.5, 0).normalized(); }
  static Eigen::Isometry3d X_ModelTool(int i) {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(M_PI / 4, direction()).toRotationMatrix();
    X.translation() = kTumourCentre_Model + Eigen::Vector3d(-20.0 + i, -10.0 + 0.5 * i, 18);
    return X;
  }
  static void scalpel_at(NavigationSession& s, std::int64_t k, const Eigen::Isometry3d& X_ModelTool) {
    const std::int64_t t = time_of(k);
    s.on_pose(pose_msg("scalpel", "Ref", test_X_RefModel() * X_ModelTool, k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
  }
  static Eigen::Isometry3d away() {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.translation() = kTumourCentre_Model + Eigen::Vector3d(0, 0, 250);
    return X;
  }
};
Scene* CuttingRun::scene_ = nullptr;

TEST_F(CuttingRun, PedalHeldCutsAlongTheScalpelPathAndTheOverlayShowsIt) {
  SessionFolder f("cutting");
  const auto rec = f.dir / "rec";
  auto s = make(f, "inputs: {cut_enable: {input: pedal_right, state_stale_after_ms: 300}}\n", rec.string());
  std::int64_t k = 0, seq = 1;
  for (; k < 5; ++k) {
    scalpel_at(*s, k, away());
    s->on_input(input_msg("pedal_right", false, 0, time_of(k), true), time_of(k) + 500);
    const FrameResult r = step(*s, k);
    EXPECT_EQ(r.row.flags, "");
    ASSERT_TRUE(r.row.cutting);
    EXPECT_FALSE(*r.row.cutting);
  }
  // First blade position inside the organ, then the pedal goes down.
  scalpel_at(*s, k, X_ModelTool(0));
  step(*s, k++);
  s->on_input(input_msg("pedal_right", true, seq++, time_of(k)), time_of(k) + 500);
  FrameResult last;
  for (int i = 1; i <= 40; ++i, ++k) {
    scalpel_at(*s, k, X_ModelTool(i));
    if (k % 6 == 0) s->on_input(input_msg("pedal_right", true, seq - 1, time_of(k), true), time_of(k) + 500);
    last = step(*s, k);
    EXPECT_TRUE(last.row.cutting && *last.row.cutting) << "frame " << k << " " << last.row.flags;
  }
  s->on_input(input_msg("pedal_right", false, seq++, time_of(k)), time_of(k) + 500);
  scalpel_at(*s, k, X_ModelTool(40));
  last = step(*s, k++);
  EXPECT_FALSE(*last.row.cutting);
  ASSERT_GT(last.row.cut_faces, 0);
  const auto cut = s->cut_surface();
  ASSERT_TRUE(cut);
  // Every cut face lies on the swept surface: the plane through the path containing the
  // blade, between the first and the last blade position (the model is at rest: no gravity,
  // cutting does not push).
  const Eigen::Vector3d blade_dir = X_ModelTool(0).linear() * Eigen::Vector3d(0, 0, 1);
  const Eigen::Vector3d normal = direction().cross(blade_dir).normalized();
  const Eigen::Vector3d origin = X_ModelTool(0).translation();
  double worst_plane = 0.0, area = 0.0;
  for (const auto& t : cut->tris) {
    for (int v : t) {
      const Eigen::Vector3d p = cut->positions_World_mm.col(v) - origin;
      worst_plane = std::max(worst_plane, std::abs(p.dot(normal)));
      const double along = p.dot(direction()), up = p.dot(blade_dir);
      EXPECT_GT(along, -1.0);
      EXPECT_LT(along, 40 * (X_ModelTool(1).translation() - X_ModelTool(0).translation()).norm() + 1.0);
      EXPECT_GT(up, -1.0) << "below the blade tip";
      EXPECT_LT(up, 61.0) << "above the heel";
    }
    const Eigen::Vector3d a = cut->positions_World_mm.col(t[0]), b = cut->positions_World_mm.col(t[1]), c = cut->positions_World_mm.col(t[2]);
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  // Crossings near an edge's end snap to the vertex (snap_fraction 0.1 of the edge; host/cut):
  // the cut lies on the swept surface within that bound of the mesh's edges.
  double longest_edge = 0.0;
  const TetMesh& mesh = scene_->problem.mesh;
  for (const auto& t : mesh.tets)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b)
        longest_edge = std::max(longest_edge, (mesh.rest_positions_World_mm.col(t[a]) - mesh.rest_positions_World_mm.col(t[b])).norm());
  const double bound_mm = 0.1 * longest_edge + 0.05;
  EXPECT_LT(worst_plane, bound_mm) << "cut faces off the swept surface (longest edge " << longest_edge << " mm)";
  // The rim (where the cut opens on the organ surface) lies on the swept plane too, above the tip.
  const auto rim = s->cut_rim();
  EXPECT_GE(rim.size(), 4u);
  for (const auto& seg : rim)
    for (const auto& p : seg) {
      EXPECT_LT(std::abs((p - origin).dot(normal)), bound_mm);
      EXPECT_GT((p - origin).dot(blade_dir), 1.0) << "the rim is on the organ's surface, above the tip inside it";
    }
  EXPECT_NEAR(last.row.cut_area_mm2, area / 2, 1e-6 * area + 0.01);
  // The swept area inside the organ: path 44.7 mm x blade 60 mm at most.
  EXPECT_GT(last.row.cut_area_mm2, 200.0);
  EXPECT_LT(last.row.cut_area_mm2, 44.8 * 60.0);
  // Drawn there: the cut colour (green) at the projected centroids of the cut faces facing
  // the camera side.
  const auto intr = test_intrinsics();
  const Eigen::Isometry3d X_CamModel = test_X_CamRef(k - 1) * test_X_RefModel();
  int green = 0, probed = 0;
  for (std::size_t i = 0; i < cut->tris.size(); i += 3) {
    const auto& t = cut->tris[i];
    const Eigen::Vector3d c = X_CamModel * ((cut->positions_World_mm.col(t[0]) + cut->positions_World_mm.col(t[1]) + cut->positions_World_mm.col(t[2])) / 3);
    std::vector<cv::Point3d> in{{c.x(), c.y(), c.z()}};
    std::vector<cv::Point2d> px;
    cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(intr.camera_matrix), intr.distortion_mat(), px);
    const cv::Vec3b bgr = last.image.at<cv::Vec3b>(cv::Point(static_cast<int>(std::lround(px[0].x)), static_cast<int>(std::lround(px[0].y))));
    ++probed;
    green += bgr[1] > bgr[2] + 20 ? 1 : 0;
  }
  EXPECT_GE(green, probed * 7 / 10) << green << " of " << probed;
  if (std::getenv("ARNAV_KEEP")) cv::imwrite((f.dir / "cut.png").string(), last.image);
  // Events: the blade came within the scene's 10 mm tumour margin (8 mm above the tumour).
  const auto j = s->summary_json(1.0);
  ASSERT_TRUE(j.contains("cutting"));
  EXPECT_GE(j["cutting"]["events_by_kind"]["margin_entered"].get<int>(), 1) << j["cutting"].dump();
  EXPECT_EQ(j["cutting"]["frames_cutting"].get<int>(), 40);
  EXPECT_GT(j["cutting"]["cut_steps"].get<int>(), 10);
  // The reported cut-path error is the measured one (distance from the swept patch >= from its plane).
  EXPECT_GE(j["cutting"]["path_error_mm"]["max"].get<double>(), worst_plane - 0.01) << j["cutting"].dump();
  EXPECT_LT(j["cutting"]["path_error_mm"]["max"].get<double>(), bound_mm) << j["cutting"].dump();
  bool printed = false;
  for (const auto& m : s->messages()) printed |= m.find("cut event: margin_entered tumour") != std::string::npos;
  EXPECT_TRUE(printed);
  s->stop();
  // overlay.csv: the cut columns.
  std::ifstream csv(rec / "overlay.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_NE(line.find(",cutting,cut_faces,cut_area_mm2,cut_path_error_mm,cut_events"), std::string::npos);
  int rows = 0, cutting_rows = 0, event_rows = 0, error_rows = 0;
  while (std::getline(csv, line)) {
    ++rows;
    std::vector<std::string> cols;
    std::stringstream ss(line);
    std::string x;
    while (std::getline(ss, x, ',')) cols.push_back(x);
    if (line.back() == ',') cols.emplace_back();
    const std::string header = csv_header();
    ASSERT_EQ(cols.size(), static_cast<std::size_t>(std::count(header.begin(), header.end(), ',') + 1)) << line;
    cutting_rows += cols[10] == "1";
    error_rows += !cols[13].empty();
    event_rows += cols[14].find("margin_entered:tumour") != std::string::npos;
  }
  EXPECT_EQ(rows, static_cast<int>(k));
  EXPECT_EQ(cutting_rows, 40);
  EXPECT_GT(error_rows, 10);
  EXPECT_GE(event_rows, 1);
}

TEST_F(CuttingRun, PedalReleasedTheBladePushesAndCutsNothing) {
  SessionFolder f("nocut");
  auto s = make(f, "inputs: {cut_enable: pedal_right}\n");
  std::int64_t k = 0;
  double moved = 0.0;
  for (int i = 0; i <= 30; ++i, ++k) {
    scalpel_at(*s, k, X_ModelTool(i));
    s->on_input(input_msg("pedal_right", false, 0, time_of(k), true), time_of(k) + 500);
    const FrameResult r = step(*s, k);
    EXPECT_FALSE(*r.row.cutting);
    EXPECT_EQ(r.row.cut_faces, 0);
  }
  EXPECT_FALSE(s->cut_surface());
  const auto j = s->summary_json(1.0);
  EXPECT_EQ(j["cutting"]["cut_steps"].get<int>(), 0);
  EXPECT_EQ(j["cutting"]["frames_cutting"].get<int>(), 0);
  (void)moved;
}

TEST_F(CuttingRun, LostPedalStateDisarmsCuttingWithABannerUntilASnapshotComes) {
  SessionFolder f("disarm");
  auto s = make(f, "inputs: {cut_enable: {input: pedal_right, state_stale_after_ms: 200}}\n");
  std::int64_t k = 0;
  scalpel_at(*s, k, away());
  FrameResult r = step(*s, k++);
  EXPECT_NE(r.row.flags.find("input_stale"), std::string::npos) << "no pedal state yet";
  EXPECT_NE(r.banners.back().find("no state yet"), std::string::npos);
  s->on_input(input_msg("pedal_right", true, 1, time_of(k)), time_of(k) + 500);
  int armed = 0, disarmed_at = -1;
  for (int i = 0; i <= 30; ++i, ++k) {
    scalpel_at(*s, k, X_ModelTool(i));
    r = step(*s, k);
    if (*r.row.cutting) ++armed;
    if (!*r.row.cutting && disarmed_at < 0) {
      disarmed_at = i;
      EXPECT_NE(r.row.flags.find("input_stale"), std::string::npos);
      ASSERT_FALSE(r.banners.empty());
      EXPECT_NE(r.banners.back().find("INPUT STALE: cut_enable 'pedal_right'"), std::string::npos) << r.banners.back();
      EXPECT_NE(r.banners.back().find("cutting disarmed"), std::string::npos);
    }
  }
  // The release was lost and no snapshot came: disarmed once the state is older than 200 ms.
  ASSERT_GE(disarmed_at, 0);
  EXPECT_NEAR(disarmed_at * 16.667, 200.0, 40.0);
  EXPECT_EQ(armed, disarmed_at);
  const int faces = r.row.cut_faces;
  // A snapshot (pressed) re-arms.
  s->on_input(input_msg("pedal_right", true, 1, time_of(k), true), time_of(k) + 500);
  scalpel_at(*s, k, X_ModelTool(31));
  r = step(*s, k++);
  EXPECT_TRUE(*r.row.cutting);
  EXPECT_EQ(r.row.flags.find("input_stale"), std::string::npos);
  // The snapshot says released (the release was lost): disarmed at once, no stale banner.
  s->on_input(input_msg("pedal_right", false, 2, time_of(k), true), time_of(k) + 500);
  scalpel_at(*s, k, X_ModelTool(32));
  r = step(*s, k++);
  EXPECT_FALSE(*r.row.cutting);
  EXPECT_EQ(r.row.flags, "");
  const auto j = s->summary_json(1.0);
  EXPECT_EQ(j["cutting"]["disarmed_by_stale_input"]["episodes"].get<int>(), 1);
  EXPECT_GE(j["inputs"]["by_input"]["pedal_right"]["resyncs"].get<int>(), 1);
  EXPECT_GE(r.row.cut_faces, faces);
}

TEST_F(CuttingRun, ModeAlwaysAndOffWithoutInputs) {
  SessionFolder f("modes");
  auto off = make(f, "cutting: {mode: off}\n");
  auto always = make(f, "cutting: {mode: always}\n");
  for (std::int64_t k = 0; k <= 40; ++k) {
    scalpel_at(*off, k, X_ModelTool(static_cast<int>(k)));
    scalpel_at(*always, k, X_ModelTool(static_cast<int>(k)));
    EXPECT_FALSE(*step(*off, k).row.cutting);
    EXPECT_TRUE(*step(*always, k).row.cutting);
  }
  EXPECT_EQ(off->summary_json(1.0)["cutting"]["cut_steps"].get<int>(), 0);
  EXPECT_GT(always->summary_json(1.0)["cutting"]["cut_steps"].get<int>(), 0);
  EXPECT_EQ(step(*off, 41).row.cut_faces, 0);
  EXPECT_GT(step(*always, 41).row.cut_faces, 0);
  // A scene with cutting and a scalpel but no word on when it cuts: an error, not a default.
  EXPECT_THROW(make(f, ""), SessionError);
  try {
    make(f, "");
  } catch (const SessionError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.yaml:3: key 'scene'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cutting: {mode: always}"), std::string::npos) << e.what();
  }
}

// Without a camera (no overlay) the scalpel's poses drive the cutting stage themselves.
// The model thread's priority (docs/overlay.md, "Threads and cores"): a session that cuts
// runs it above the machine's other work (nice -5: the cut lands where the blade went only
// while the model keeps up with the blade; issue 20), one that does not lets it yield to
// rendering (nice 5), and model.nice says otherwise for either (-20 to 19). A level the
// system refuses is reported, not silently dropped. model.cut_catch_up_ms is read, and bounded.
TEST_F(CuttingRun, ACuttingModelRunsAboveOtherWorkUnlessTheSessionSaysOtherwise) {
  SessionFolder f("nice");
  EXPECT_EQ(make(f, "cutting: {mode: always}\n")->summary_json(1.0)["model"]["nice"].get<int>(), kCuttingModelNice);
  EXPECT_EQ(kCuttingModelNice, -5);
  std::string text = cut_session_text("cutting: {mode: always}\n");
  const std::string from = "model: {rate_hz: 60, gravity: false}";
  text.replace(text.find(from), from.size(), "model: {rate_hz: 60, gravity: false, nice: 7, cut_catch_up_ms: 2000}");
  SessionOptions o;
  o.threaded = false;
  const SessionConfig c = load_session(f.write("nice7.yaml", text));
  EXPECT_EQ(c.model.cut_catch_up_ms, 2000.0);
  EXPECT_EQ(NavigationSession(c, std::make_unique<Scene>(*scene_), o).summary_json(1.0)["model"]["nice"].get<int>(), 7);
  const Scene uncut = load_scene(data_dir() + "/liver/liver_coarse.scene.yaml");
  NavigationSession plain(load_session(f.session()), std::make_unique<Scene>(uncut), o);
  EXPECT_EQ(plain.summary_json(1.0)["model"]["nice"].get<int>(), 5);
  std::string above = text;
  above.replace(above.find("nice: 7"), 7, "nice: -21");
  const std::string nice_error = session_error_of(f, above);
  EXPECT_NE(nice_error.find("key 'model.nice'"), std::string::npos) << nice_error;
  EXPECT_NE(nice_error.find("-21"), std::string::npos) << nice_error;
  text.replace(text.find("cut_catch_up_ms: 2000"), 21, "cut_catch_up_ms: -1");
  const std::string error = session_error_of(f, text);
  EXPECT_NE(error.find("key 'model.cut_catch_up_ms'"), std::string::npos) << error;
}

// A model that falls more than model.cut_catch_up_ms behind during a stroke merges cutting
// samples into one step (docs/overlay.md, "Model clock"): the frames say so (flag
// cut_samples_merged, a banner for 5 s), the summary counts them; a model that keeps up
// shows neither.
TEST_F(CuttingRun, AModelFarBehindDuringAStrokeSaysTheCutMayBeOffThePath) {
  SessionFolder f("merged");
  std::string text = cut_session_text("cutting: {mode: always}\n");
  const std::string from = "model: {rate_hz: 60, gravity: false}";
  text.replace(text.find(from), from.size(), "model: {rate_hz: 60, gravity: false, cut_catch_up_ms: 1000}");
  SessionOptions o;
  o.threaded = false;
  o.keep_last_frame = true;
  NavigationSession late(load_session(f.write("late.yaml", text)), std::make_unique<Scene>(*scene_), o);
  auto timely = make(f, "cutting: {mode: always}\n");
  // 1.2 s of the stroke with no model step (a stalled model thread), then frames again.
  for (std::int64_t k = 0; k <= 72; ++k) {
    scalpel_at(late, k, X_ModelTool(static_cast<int>(k / 3)));
    late.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, time_of(k)), time_of(k) + 2000);
  }
  int flagged = 0, with_banner = 0;
  for (std::int64_t k = 0; k <= 80; ++k) {
    if (k > 72) scalpel_at(late, k, X_ModelTool(static_cast<int>(k / 3)));
    const FrameResult r = k < 72 ? FrameResult{} : step(late, k);
    flagged += r.row.flags.find("cut_samples_merged") != std::string::npos ? 1 : 0;
    for (const auto& b : r.banners) with_banner += b.find("CUT MAY BE OFF THE BLADE'S PATH") != std::string::npos ? 1 : 0;
    scalpel_at(*timely, k, X_ModelTool(static_cast<int>(k / 3)));
    const FrameResult t = step(*timely, k);
    EXPECT_EQ(t.row.flags.find("cut_samples_merged"), std::string::npos) << t.row.flags;
    for (const auto& b : t.banners) EXPECT_EQ(b.find("CUT MAY BE OFF"), std::string::npos) << b;
  }
  EXPECT_EQ(flagged, 1) << "the frame that first shows the merged step";
  EXPECT_EQ(with_banner, 9) << "every frame after it, within 5 s";
  EXPECT_GT(late.summary_json(1.0)["model"]["clock"]["cut_samples_merged"].get<int>(), 0) << late.summary_json(1.0)["model"].dump();
  EXPECT_EQ(timely->summary_json(1.0)["model"]["clock"]["cut_samples_merged"].get<int>(), 0);
}

TEST_F(CuttingRun, WithoutACameraTheScalpelPosesCut) {
  SessionFolder f("nocamera");
  const std::string text = "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                           "/liver/liver_coarse_cut.scene.yaml\nregistration: X_RefModel.yaml\n"
                           "tools:\n  reference: {name: liver_marker}\n"
                           "  scalpel: {name: scalpel, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 60]}}\n"
                           "inputs: {cut_enable: pedal_right}\nmodel: {rate_hz: 60, gravity: false}\n";
  SessionOptions o;
  o.threaded = false;
  NavigationSession s(load_session(f.write("nocam.yaml", text)), std::make_unique<Scene>(*scene_), o);
  std::int64_t k = 0;
  const auto run = [&](int from, int to, bool pedal) {
    for (int i = from; i <= to; ++i, ++k) {
      s.on_input(input_msg("pedal_right", pedal, pedal ? 1 : 2, time_of(k), true), time_of(k) + 200);
      scalpel_at(s, k, X_ModelTool(i));
      s.advance_model(time_of(k) + 4000);
    }
  };
  run(0, 20, false);
  EXPECT_EQ(s.summary_json(1.0)["cutting"]["cut_steps"].get<int>(), 0) << "pedal up: no cut";
  run(21, 40, true);
  s.on_input(input_msg("pedal_right", false, 3, time_of(k)), time_of(k) + 200);
  scalpel_at(s, k, X_ModelTool(40));
  s.advance_model(time_of(k) + 4000);
  s.advance_model(time_of(k + 1) + 4000);
  const auto j = s.summary_json(1.0);
  EXPECT_GT(j["cutting"]["cut_steps"].get<int>(), 0);
  EXPECT_GT(j["cutting"]["cut_faces"].get<int>(), 0);
  EXPECT_EQ(j["cutting"]["frames_cutting"].get<int>(), 20);
  EXPECT_NE(s.format_summary(1.0).find("cutting (input)"), std::string::npos);
}

// Live registration: four landmarks touched with the pointer, accepted by button presses.
TEST(LiveRegistration, PointerLandmarksRecoverAKnownRegistration) {
  SessionFolder f("live");
  const std::vector<std::pair<std::string, Eigen::Vector3d>> landmarks = {
      {"hilum", {40, 130, 120}}, {"dome", {110, 190, 185}}, {"left_tip", {20, 210, 150}}, {"gallbladder", {95, 120, 160}}};
  {
    std::ofstream lm(f.dir / "landmarks.csv");
    lm << "name,x_mm,y_mm,z_mm\n";
    for (const auto& [n, p] : landmarks) lm << n << ',' << p.x() << ',' << p.y() << ',' << p.z() << '\n';
  }
  const std::string text = "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                           "/liver/liver_coarse.scene.yaml\n"
                           "registration:\n  live: {landmarks: landmarks.csv, pointer: pointer, tip_mm: [0, 0, -150], window_ms: 150}\n"
                           "inputs: {accept: button_1}\n"
                           "tools:\n  reference: {name: liver_marker, stale_after_ms: 100}\n  pointer: {name: pointer}\n"
                           "camera:\n  name: cam0\n  intrinsics: camera.yaml\n  pose_from: reference\nmodel: {rate_hz: 60}\n";
  SessionOptions o;
  o.threaded = false;
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse.scene.yaml");
  NavigationSession s(load_session(f.write("live.yaml", text)), std::make_unique<Scene>(scene), o);
  const Eigen::Isometry3d X_true = test_X_RefModel();
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.2);
  std::int64_t k = 0, seq = 0;
  // The pointer in Ndi with the reference also in Ndi (the appliance's usual frame).
  Eigen::Isometry3d X_NdiRef = Eigen::Isometry3d::Identity();
  X_NdiRef.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, -0.2, 1).normalized()).toRotationMatrix();
  X_NdiRef.translation() = Eigen::Vector3d(40, -80, -1300);
  const auto pointer_at = [&](const Eigen::Vector3d& tip_Ref, double jitter_mm) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    Eigen::Isometry3d X_RefPointer = Eigen::Isometry3d::Identity();
    X_RefPointer.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 0.2, 0).normalized()).toRotationMatrix();
    const Eigen::Vector3d jitter(jitter_mm * noise(rng), jitter_mm * noise(rng), jitter_mm * noise(rng));
    X_RefPointer.translation() = tip_Ref + jitter - X_RefPointer.linear() * Eigen::Vector3d(0, 0, -150);
    s.on_pose(pose_msg("liver_marker", "Ndi", X_NdiRef, 500 + k, t, true, tool_pose_t::SOURCE_NDI), t + 800);
    s.on_pose(pose_msg("pointer", "Ndi", X_NdiRef * X_RefPointer, 500 + k, t, true, tool_pose_t::SOURCE_NDI), t + 800);
    s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t), t + 1000);
    ++k;
  };
  const auto press = [&]() {
    const std::int64_t t = 1'000'000 + k * 16'667;
    s.on_input(input_msg("button_1", true, ++seq, t), t);
    s.on_input(input_msg("button_1", false, ++seq, t + 100), t + 100);
  };
  const auto frame = [&]() {
    const std::int64_t t = 1'000'000 + (k - 1) * 16'667;
    return s.render_frame(frame_msg(k - 1, t), t + 5000);
  };
  // Before any landmark: no overlay, the progress banner.
  pointer_at(Eigen::Vector3d(0, 0, 300), 0.0);
  FrameResult r = frame();
  EXPECT_FALSE(r.row.tumour_px);
  EXPECT_NE(r.row.flags.find("unregistered"), std::string::npos);
  ASSERT_FALSE(r.banners.empty());
  EXPECT_NE(r.banners.back().find("registration: 0/4 landmarks - touch 'hilum'"), std::string::npos) << r.banners.back();
  for (std::size_t i = 0; i < landmarks.size(); ++i) {
    const Eigen::Vector3d p_Ref = X_true * landmarks[i].second;
    if (i == 1) {
      // Moving: refused.
      for (int j = 0; j < 10; ++j) pointer_at(p_Ref + Eigen::Vector3d(0.8 * j, 0, 0), 0.0);
      press();
      EXPECT_EQ(s.live_registration()->taken(), 1);
      EXPECT_NE(s.messages().back().find("refused: pointer moving"), std::string::npos) << s.messages().back();
    }
    if (i == 2) {
      // Stale: the pointer's last pose 300 ms before the press.
      pointer_at(p_Ref, 0.0);
      k += 18;
      press();
      EXPECT_NE(s.messages().back().find("refused: pointer 'pointer' stale"), std::string::npos) << s.messages().back();
    }
    for (int j = 0; j < 12; ++j) pointer_at(p_Ref, 1.0);
    press();
    EXPECT_EQ(s.live_registration()->taken(), static_cast<int>(i + 1)) << s.messages().back();
    if (i == 1) {
      r = frame();
      EXPECT_NE(r.banners.back().find("registration: 2/4 landmarks"), std::string::npos) << r.banners.back();
    }
  }
  ASSERT_TRUE(s.live_registration()->done()) << s.messages().back();
  const auto X = s.X_RefModel();
  ASSERT_TRUE(X);
  for (const auto& [n, p] : landmarks) EXPECT_LT(((*X) * p - X_true * p).norm(), 0.5) << n;
  EXPECT_LT(Eigen::AngleAxisd((X->linear() * X_true.linear().transpose())).angle(), 0.01);
  // The overlay now draws the tumour where the true registration puts it (within 0.5 mm ~ a few px).
  pointer_at(Eigen::Vector3d(0, 0, 300), 0.0);
  r = frame();
  ASSERT_TRUE(r.row.tumour_px) << r.row.flags;
  EXPECT_EQ(r.row.flags.find("unregistered"), std::string::npos);
  const auto j = s.summary_json(1.0);
  EXPECT_EQ(j["registration"]["method"], "live landmarks");
  EXPECT_EQ(j["registration"]["refused"], 2);
  EXPECT_GT(j["registration"]["fre_mm"].get<double>(), 0.01);
  EXPECT_LT(j["registration"]["fre_mm"].get<double>(), 0.6);
  EXPECT_GT(j["registration"]["predicted_tre_mm"].get<double>(), 0.0);
  EXPECT_NE(s.format_summary(1.0).find("registration (live, 4 landmarks, 2 refused): FRE"), std::string::npos);
}

std::string error_of(const SessionFolder& f, const std::string& text) { return session_error_of(f, text); }

TEST(SessionConfig, BadInputsCuttingAndLiveRegistrationNameFileLineAndFix) {
  SessionFolder f("bad_inputs");
  const std::string v = "arnav_session_version: 1\n";
  const std::string tools = "tools:\n  reference: {name: r}\n  scalpel: {name: s, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 20]}}\n";
  const std::string scene = "scene: " + data_dir() + "/liver/liver_coarse.scene.yaml\n";
  EXPECT_NE(error_of(f, v + tools + "inputs:\n  cut_enabel: pedal\n").find("bad.yaml:6: key 'inputs.cut_enabel': unknown key (known keys: accept, cut_enable)"),
            std::string::npos)
      << error_of(f, v + tools + "inputs:\n  cut_enabel: pedal\n");
  EXPECT_NE(error_of(f, v + tools + "inputs:\n  cut_enable: {name: pedal}\n").find("bad.yaml:6: key 'inputs.cut_enable.name': unknown key"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + tools + "inputs:\n  cut_enable: {input: p, state_stale_after_ms: 0}\n")
                .find("bad.yaml:6: key 'inputs.cut_enable.state_stale_after_ms': must be between"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + "inputs:\n  cut_enable: pedal\n").find("bad.yaml:3: key 'inputs.cut_enable': cut_enable needs tools.scalpel"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + tools + "cutting: {mode: sometimes}\n").find("bad.yaml:5: key 'cutting.mode': must be 'input'"), std::string::npos)
      << error_of(f, v + tools + "cutting: {mode: sometimes}\n");
  EXPECT_NE(error_of(f, v + tools + "cutting: {mode: input}\n").find("'input' needs inputs.cut_enable"), std::string::npos);
  EXPECT_NE(error_of(f, v + "cutting: {mode: always}\n").find("bad.yaml:2: key 'cutting': cutting needs tools.scalpel"), std::string::npos);
  // registration.live
  std::ofstream(f.dir / "two.csv") << "name,x_mm,y_mm,z_mm\na,0,0,0\nb,1,0,0\n";
  std::ofstream(f.dir / "broken.csv") << "name,x_mm,y_mm,z_mm\na,0,0\n";
  const std::string ref = "tools:\n  reference: {name: r}\n";
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {pointer: p, accept: b}\n").find("bad.yaml:6: key 'registration.live.landmarks': missing"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {landmarks: two.csv, pointer: p, accept: b}\n")
                .find("bad.yaml:6: key 'registration.live.landmarks': "),
            std::string::npos);
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {landmarks: two.csv, pointer: p, accept: b}\n").find("at least 3"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {landmarks: broken.csv, pointer: p, accept: b}\n").find("broken.csv:2"),
            std::string::npos)
      << error_of(f, v + scene + ref + "registration:\n  live: {landmarks: broken.csv, pointer: p, accept: b}\n");
  std::ofstream(f.dir / "four.csv") << "name,x_mm,y_mm,z_mm\na,0,0,0\nb,10,0,0\nc,0,10,0\nd,0,0,10\n";
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {landmarks: four.csv, pointer: p}\n").find("key 'registration.live.accept': missing"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  live: {landmarks: four.csv, pointer: p, acept: b}\n").find("key 'registration.live.acept': unknown key"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + scene + ref + "registration:\n  livee: {}\n").find("bad.yaml:6: key 'registration.livee': unknown key"), std::string::npos)
      << error_of(f, v + scene + ref + "registration:\n  livee: {}\n");
  EXPECT_NE(error_of(f, v + scene + "registration:\n  live: {landmarks: four.csv, pointer: p, accept: b}\n").find("needs tools.reference"),
            std::string::npos);
  const SessionConfig ok = load_session(f.write("ok.yaml", v + scene + ref + "inputs: {accept: button_1}\nregistration:\n  live: {landmarks: four.csv, pointer: p}\n"));
  ASSERT_TRUE(ok.live_registration);
  EXPECT_EQ(ok.live_registration->accept_input, "button_1");
  EXPECT_EQ(ok.live_registration->landmarks_Model_mm.size(), 4u);
}

// The overlay's geometry after a cut through the tumour: the model snapshot draws the tumour
// split along the cut (more triangles, closed again: every directed edge has its opposite,
// every new point drawn) and the vessel tree with one radius per (split) node.
TEST(ModelRunnerCut, SnapshotDrawsTheTumourAndVesselsSplitAlongTheCut) {
  const Scene scene = load_scene(data_dir() + "/liver/liver_coarse_cut.scene.yaml");
  ModelRunner runner(scene, 60.0, false, 5.0, 0, cut::CutSessionSettings{});
  runner.expect_blade();
  std::int64_t t = 60 * 16'667;  // on the model's grid of device times
  for (int f = 0; f <= 45; ++f, t += 16'667) {  // vertical blade at x = 71.3 through the tumour, y 125 .. 215
    runner.push_blade({t, std::array<Eigen::Vector3d, 2>{Eigen::Vector3d(71.3, 125 + 2 * f, 100), Eigen::Vector3d(71.3, 125 + 2 * f, 200)}, true}, t);
    runner.advance_to(t, 1);
  }
  const auto snap = runner.snapshot();
  ASSERT_TRUE(snap);
  ASSERT_EQ(snap->tumours.size(), 1u);
  const TriMesh& tumour = snap->tumours[0];
  EXPECT_GT(tumour.tris.size(), scene.tumours[0].rest.tris.size());
  std::set<std::pair<int, int>> directed;
  for (const auto& tri : tumour.tris)
    for (int k = 0; k < 3; ++k) directed.insert({tri[static_cast<std::size_t>(k)], tri[static_cast<std::size_t>((k + 1) % 3)]});
  EXPECT_EQ(directed.size(), 3 * tumour.tris.size());  // no edge used twice in one direction
  for (const auto& [a, b] : directed) EXPECT_TRUE(directed.count({b, a})) << "open edge " << a << "-" << b;
  int highest = 0;
  for (const auto& tri : tumour.tris) highest = std::max({highest, tri[0], tri[1], tri[2]});
  EXPECT_EQ(highest + 1, static_cast<int>(tumour.positions_World_mm.cols()));  // every split point is drawn
  EXPECT_EQ(snap->margins.size(), 1u);
  ASSERT_TRUE(snap->vessels);
  EXPECT_EQ(snap->vessels->radius_mm.size(), static_cast<std::size_t>(snap->vessels->nodes_World_mm.cols()));
  for (const auto& [a, b] : snap->vessels->segments) {
    EXPECT_LT(a, snap->vessels->nodes_World_mm.cols());
    EXPECT_LT(b, snap->vessels->nodes_World_mm.cols());
  }
}

}  // namespace
}  // namespace arnav::host
