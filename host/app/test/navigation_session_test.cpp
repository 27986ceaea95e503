// The navigation session in process (no LCM): session-file errors with file:line, the
// overlay of synthetic frames against cv::projectPoints through the whole frame chain
// (X_CamRef from the reference board, X_RefModel from the registration file), banners on
// lost and stale tools within 200 ms and their recovery, the blade-to-margin distance, and
// the recording (CSV complete, video readable, contact sheet).
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/videoio.hpp>

#include "host/app/navigation_session.hpp"
#include "host/app/tumour_surface_file.hpp"
#include "host/app/session_config.hpp"
#include "host/app/test/session_test_util.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {
namespace {

using namespace arnav::host::test;

std::string error_of(const SessionFolder& f, const std::string& text) { return session_error_of(f, text); }

TEST(SessionConfig, ErrorsNameFileLineKeyAndFix) {
  SessionFolder f("errors");
  const std::string v = "arnav_session_version: 1\n";
  EXPECT_NE(error_of(f, v + "camerra: {}\n").find("bad.yaml:2: key 'camerra': unknown key"), std::string::npos);
  EXPECT_NE(error_of(f, "lcm_url: x\n").find("bad.yaml:1: key 'arnav_session_version': missing"), std::string::npos);
  EXPECT_NE(error_of(f, v + "tools:\n  reference: {stale_after_ms: 5}\n").find("bad.yaml:3: key 'tools.reference.name'"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + "tools:\n  reference: {name: r, stale_after_ms: -5}\n").find("bad.yaml:3: key 'tools.reference.stale_after_ms': must be between"),
            std::string::npos);
  const std::string cam = "camera:\n  name: cam0\n  intrinsics: camera.yaml\n";
  EXPECT_NE(error_of(f, v + "tools:\n  reference: {name: r}\n" + cam).find("needs a scene"), std::string::npos);
  const std::string scene = "scene: " + data_dir() + "/liver/liver_coarse.scene.yaml\n";
  EXPECT_NE(error_of(f, v + scene + "tools:\n  reference: {name: r}\n" + cam).find("registration"), std::string::npos);
  EXPECT_NE(error_of(f, v + scene + "registration: nope.yaml\n").find("bad.yaml:3: key 'registration'"), std::string::npos);
  EXPECT_NE(error_of(f, v + "scene: nope.scene.yaml\n").find("bad.yaml:2: key 'scene': file"), std::string::npos);
  EXPECT_NE(error_of(f, v + scene + "registration: X_RefModel.yaml\ntools:\n  reference: {name: r}\ncamera:\n  name: c\n  intrinsics: missing.yaml\n")
                .find("bad.yaml:8: key 'camera.intrinsics'"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + "overlay:\n  layers: [tumour, tumor]\n").find("bad.yaml:3: key 'overlay.layers[1]': unknown layer 'tumor'"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + "tools:\n  reference: {name: r}\n  scalpel: {name: s}\n").find("key 'tools.scalpel.blade': missing"),
            std::string::npos);
  EXPECT_NE(error_of(f, v + "model: [1, 2\n").find("bad.yaml:3: YAML syntax error"), std::string::npos);  // at the end of the text
  // Wrong registration name: the file's own frames are checked.
  calib::RigidTransformRecord wrong;
  wrong.parent_frame = "Cam";
  wrong.child_frame = "Model";
  calib::write_transform(f.dir / "X_CamModel.yaml", wrong);
  EXPECT_NE(error_of(f, v + scene + "registration: X_CamModel.yaml\n").find("X_RefModel"), std::string::npos);
  // A monitor-only session (no camera, no scene) is valid.
  const SessionConfig monitor = load_session(f.write("monitor.yaml", v + "lcm_url: \"memq://\"\nstale_after_ms: 300\n"));
  EXPECT_FALSE(monitor.camera);
  EXPECT_FALSE(monitor.scene_path);
  EXPECT_DOUBLE_EQ(monitor.stale_after_ms, 300.0);
}

class SessionRun : public CoarseLiverSuite {
 protected:
  std::unique_ptr<NavigationSession> make(const SessionFolder& f, const std::string& record_dir = "") {
    SessionOptions o;
    o.threaded = false;
    o.keep_last_frame = true;
    o.record_dir = record_dir;
    return std::make_unique<NavigationSession>(load_session(f.session()), std::make_unique<Scene>(*scene_), o);
  }
  static cv::Point2d expected_tumour_px(std::int64_t k) {
    const Eigen::Vector3d p = test_X_CamRef(k) * test_X_RefModel() * tumour_centroid_World_mm(*scene_, 0, scene_->problem.mesh.rest_positions_World_mm);
    std::vector<cv::Point3d> in{{p.x(), p.y(), p.z()}};
    std::vector<cv::Point2d> out;
    const auto c = test_intrinsics();
    cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(c.camera_matrix), c.distortion_mat(), out);
    return out[0];
  }
  // One camera frame k at 60 Hz: the board pose (same sequence) then the JPEG.
  static FrameResult step(NavigationSession& s, std::int64_t k, bool board_seen = true, bool board_published = true) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    if (board_published) s.on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(k), k, t, board_seen), t + 2000);
    s.advance_model(t + 4000);
    return s.render_frame(frame_msg(k, t), t + 5000);
  }
};

TEST_F(SessionRun, TumourOverlayLiesWhereTheChainProjectsIt) {
  SessionFolder f("chain");
  auto s = make(f);
  for (std::int64_t k = 0; k < 20; ++k) {
    const FrameResult r = step(*s, k);
    ASSERT_TRUE(r.row.tumour_px) << "frame " << k << " flags " << r.row.flags;
    const cv::Point2d e = expected_tumour_px(k);
    // The model runs (gravity off, nothing touching it): the tumour stays where it was.
    EXPECT_LT(cv::norm(*r.row.tumour_px - e), 0.05) << "frame " << k;
    EXPECT_EQ(r.row.flags, "scalpel_stale") << "no scalpel pose was sent";
    EXPECT_EQ(r.row.pose_time_mono_us, 1'000'000 + k * 16'667);
    // The rendered image is red at the tumour (drawn through the organ veil).
    const cv::Vec3b px = r.image.at<cv::Vec3b>(cv::Point(static_cast<int>(std::lround(e.x)), static_cast<int>(std::lround(e.y))));
    EXPECT_GT(px[2], px[1] + 60) << "BGR " << px;
  }
  const auto j = s->summary_json(20 / 60.0);
  EXPECT_EQ(j["frames_displayed"], 20);
  EXPECT_GT(j["model"]["steps"].get<int>(), 15);
  EXPECT_EQ(j["model"]["step_control_steps"].get<int>(), 0);  // the FEM at rest: never redone (issue 29)
}

TEST_F(SessionRun, BannersWithin200msOfLosingTheReferenceAndGoneOnRecovery) {
  SessionFolder f("banners");
  auto s = make(f);
  for (std::int64_t k = 0; k < 10; ++k) EXPECT_EQ(step(*s, k).banners.size(), 1u);  // scalpel stale only
  // The board disappears from the appliance's stream (no messages at all): stale.
  std::int64_t first_banner = -1;
  for (std::int64_t k = 10; k < 40; ++k) {
    const FrameResult r = step(*s, k, true, false);
    if (r.row.flags.find("reference_stale") != std::string::npos && first_banner < 0) first_banner = k;
    if (first_banner >= 0) {
      EXPECT_FALSE(r.row.tumour_px) << "no frozen overlay while the reference is stale";
      ASSERT_FALSE(r.banners.empty());
      EXPECT_NE(r.banners[0].find("STALE: reference 'liver_marker'"), std::string::npos) << r.banners[0];
    }
  }
  ASSERT_GE(first_banner, 0);
  const double delay_ms = static_cast<double>(first_banner - 9) * 16.667;  // after the last pose (frame 9)
  EXPECT_LE(delay_ms, 200.0);
  EXPECT_GE(delay_ms, 100.0) << "not before the configured limit";
  // Back: the first frame with a pose is clean again.
  FrameResult back = step(*s, 40);
  EXPECT_EQ(back.row.flags, "scalpel_stale");
  EXPECT_TRUE(back.row.tumour_px);
  // The board reported missing (occluded): "tracking lost" at once.
  FrameResult lost = step(*s, 41, false);
  EXPECT_NE(lost.row.flags.find("reference_lost"), std::string::npos);
  EXPECT_FALSE(lost.row.tumour_px);
  EXPECT_NE(lost.banners[0].find("TRACKING LOST: reference"), std::string::npos);
  EXPECT_TRUE(step(*s, 42).row.tumour_px);
  // A 0.5 s gap in the camera's frames (limit 150 ms): flagged on the next frame, counted.
  EXPECT_EQ(step(*s, 42 + 30).row.flags.find("camera_gap") != std::string::npos, true);
  EXPECT_EQ(step(*s, 42 + 31).row.flags.find("camera_gap"), std::string::npos);
  const auto j = s->summary_json(1.0);
  EXPECT_EQ(j["camera_gaps"]["count"], 1);
  EXPECT_NEAR(j["camera_gaps"]["max_ms"].get<double>(), 30 * 16.667, 0.01);
  EXPECT_EQ(j["flags"]["reference_stale"]["episodes"], 1);
  EXPECT_EQ(j["flags"]["reference_lost"]["episodes"], 1);
  EXPECT_GE(j["flags"]["reference_stale"]["spans"][0]["recovered_capture_us"].get<std::int64_t>(), 0);
}

TEST_F(SessionRun, BladeToMarginThroughTheFrameChain) {
  SessionFolder f("blade");
  auto s = make(f);
  // Blade tip 8 mm above the tumour's pole along Model +z (radius 10 there): 3 mm outside
  // the 5 mm margin; the heel further up. Given as X_RefScalpel (NDI path in Ref).
  const Eigen::Isometry3d X_RefModel = test_X_RefModel();
  Eigen::Isometry3d X_ModelTool = Eigen::Isometry3d::Identity();
  X_ModelTool.translation() = kTumourCentre_Model + Eigen::Vector3d(0, 0, 10 + 5 + 3);
  const Eigen::Isometry3d X_RefTool = X_RefModel * X_ModelTool;
  const std::int64_t t = 1'000'000;
  s->on_pose(pose_msg("scalpel", "Ref", X_RefTool, 5, t, true, tool_pose_t::SOURCE_NDI), t);
  FrameResult r = step(*s, 0);
  ASSERT_TRUE(r.row.blade_to_margin_mm) << r.row.flags;
  EXPECT_NEAR(*r.row.blade_to_margin_mm, 3.0, 0.15);
  EXPECT_EQ(r.row.flags, "");
  // Pushed 5 mm deeper: 2 mm inside the margin.
  X_ModelTool.translation().z() -= 5;
  s->on_pose(pose_msg("scalpel", "Ref", X_RefModel * X_ModelTool, 6, t + 16'667, true, tool_pose_t::SOURCE_NDI), t + 16'667);
  r = step(*s, 1);
  EXPECT_NEAR(*r.row.blade_to_margin_mm, -2.0, 0.15);
  // The same scalpel given in Cam (relative to the board) gives the same distance.
  const Eigen::Isometry3d X_CamTool = test_X_CamRef(2) * X_RefModel * X_ModelTool;
  s->on_pose(pose_msg("scalpel", "Cam", X_CamTool, 7, t + 2 * 16'667, true), t + 2 * 16'667);
  r = step(*s, 2);
  EXPECT_NEAR(*r.row.blade_to_margin_mm, -2.0, 0.15);
}

TEST_F(SessionRun, CutShownAlongTheScalpelPathThroughTheTissue) {
  SessionFolder f("cut");
  auto s = make(f);
  const Eigen::Isometry3d X_RefModel = test_X_RefModel();
  const auto scalpel_at = [&](std::int64_t k, const Eigen::Vector3d& tip_Model) {
    Eigen::Isometry3d X_ModelTool = Eigen::Isometry3d::Identity();
    X_ModelTool.translation() = tip_Model;
    const std::int64_t t = 1'000'000 + k * 16'667;
    s->on_pose(pose_msg("scalpel", "Ref", X_RefModel * X_ModelTool, k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
  };
  // Above the organ first (no cut), then a straight stroke 18 mm above the tumour's centre
  // (inside the liver), then out again.
  std::vector<Eigen::Vector3d> path;
  std::int64_t k = 0;
  for (; k < 5; ++k) {
    scalpel_at(k, kTumourCentre_Model + Eigen::Vector3d(0, 0, 250));
    step(*s, k);
  }
  EXPECT_TRUE(s->cut_strokes().empty());
  for (int i = 0; i <= 40; ++i, ++k) {
    const Eigen::Vector3d tip = kTumourCentre_Model + Eigen::Vector3d(-20.0 + i, 0.5 * i, 18);
    path.push_back(tip);
    scalpel_at(k, tip);
    const FrameResult r = step(*s, k);
    ASSERT_TRUE(r.row.blade_to_margin_mm) << r.row.flags;
  }
  scalpel_at(k, kTumourCentre_Model + Eigen::Vector3d(0, 0, 250));
  const FrameResult last = step(*s, k);
  const auto strokes = s->cut_strokes();
  ASSERT_EQ(strokes.size(), 1u);
  ASSERT_EQ(strokes[0].size(), path.size()) << "one point per mm of the 1.1 mm steps";
  // The trace is the blade tip's path (the model is at rest: nothing deforms it).
  for (std::size_t i = 0; i < path.size(); ++i) EXPECT_LT((strokes[0][i] - path[i]).norm(), 1e-6) << i;
  // And it is drawn there: the cut colour (green) along the projected path.
  const auto intr = test_intrinsics();
  int green = 0;
  for (std::size_t i = 5; i + 5 < path.size(); i += 5) {
    const Eigen::Vector3d p = test_X_CamRef(k) * X_RefModel * path[i];
    std::vector<cv::Point3d> in{{p.x(), p.y(), p.z()}};
    std::vector<cv::Point2d> px;
    cv::projectPoints(in, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(intr.camera_matrix), intr.distortion_mat(), px);
    const cv::Vec3b bgr = last.image.at<cv::Vec3b>(cv::Point(static_cast<int>(std::lround(px[0].x)), static_cast<int>(std::lround(px[0].y))));
    green += bgr[1] > bgr[2] + 20 ? 1 : 0;
  }
  EXPECT_GE(green, 6) << "of 7 points along the path";
}

TEST_F(SessionRun, RecordingWritesCsvVideoAndContactSheet) {
  SessionFolder f("record");
  const auto rec = f.dir / "rec";
  {
    auto s = make(f, rec.string());
    for (std::int64_t k = 0; k < 90; ++k) step(*s, k, k < 60 || k > 70);
    s->stop();
    const auto files = s->recorded_files();
    EXPECT_EQ(files.size(), 4u);  // overlay.csv, tumour_Cam.bin, overlay.avi, contact_sheet.png
  }
  // The drawn tumour's surface in Cam, one record per frame with the tumour drawn.
  const auto surfaces = read_tumour_surfaces((rec / "tumour_Cam.bin").string());
  EXPECT_GT(surfaces.size(), 50u);
  std::ifstream csv(rec / "overlay.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, csv_header());
  const auto split = [](const std::string& text) {
    std::vector<std::string> out;
    std::stringstream ss(text);
    for (std::string c; std::getline(ss, c, ',');) out.push_back(c);
    if (!text.empty() && text.back() == ',') out.emplace_back();
    return out;
  };
  const std::vector<std::string> header = split(csv_header());
  const auto index = [&](const char* name) {
    const auto it = std::find(header.begin(), header.end(), name);
    EXPECT_NE(it, header.end()) << name;
    return static_cast<std::size_t>(it - header.begin());
  };
  // The frame's instants in order: exposure <= published <= received <= decoded <= ready <= shown.
  const std::vector<std::size_t> instants{index("capture_time_mono_us"), index("publish_time_mono_us"), index("receive_time_mono_us"),
                                          index("decode_done_mono_us"), index("render_done_mono_us"), index("shown_mono_us")};
  int rows = 0;
  while (std::getline(csv, line)) {
    ++rows;
    const std::vector<std::string> col = split(line);
    ASSERT_EQ(col.size(), header.size()) << line;
    EXPECT_EQ(std::stoll(col[0]), rows - 1);
    std::vector<std::int64_t> t;
    for (std::size_t i : instants) t.push_back(std::stoll(col[i]));
    EXPECT_TRUE(std::is_sorted(t.begin(), t.end())) << line;
  }
  EXPECT_EQ(rows, 90);
  cv::VideoCapture video((rec / "overlay.avi").string());
  ASSERT_TRUE(video.isOpened());
  EXPECT_EQ(static_cast<int>(video.get(cv::CAP_PROP_FRAME_COUNT)), 90);
  const cv::Mat sheet = cv::imread((rec / "contact_sheet.png").string());
  ASSERT_FALSE(sheet.empty());
  EXPECT_EQ(sheet.cols, 4 * 320);
  EXPECT_EQ(sheet.rows, 180);  // 1.5 s of frames, one thumbnail per second: 2 thumbnails, one row
}

TEST_F(SessionRun, TrackedCameraMarkerWithHandEyeInNdiAndRefFrames) {
  // pose_from: tool: the camera carries an NDI marker; X_CamMarkerCam is the hand-eye.
  SessionFolder f("tracked");
  Eigen::Isometry3d X_MarkerCam = Eigen::Isometry3d::Identity();
  X_MarkerCam.linear() = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  X_MarkerCam.translation() = Eigen::Vector3d(12, -40, 85);
  calib::RigidTransformRecord he;
  he.parent_frame = "Cam";  // written as X_CamMarker: the reader takes either direction
  he.child_frame = "Marker";
  he.X_ParentChild = X_MarkerCam.inverse();
  he.method = "test";
  he.date = "2026-11-25T00:00:00Z";
  calib::write_transform(f.dir / "X_CamMarker.yaml", he);
  const std::string text = "arnav_session_version: 1\nlcm_url: \"memq://\"\nscene: " + data_dir() +
                           "/liver/liver_coarse.scene.yaml\nregistration: X_RefModel.yaml\n"
                           "tools:\n  reference: {name: reference, stale_after_ms: 100}\n"
                           "camera:\n  name: cam0\n  intrinsics: camera.yaml\n  pose_from: tool\n  pose_tool: cam_marker\n"
                           "  hand_eye: X_CamMarker.yaml\n";
  SessionOptions o;
  o.threaded = false;
  NavigationSession s(load_session(f.write("tracked.yaml", text)), std::make_unique<Scene>(*scene_), o);
  // Tracker frame: reference and camera marker both seen by the NDI (parent Ndi).
  Eigen::Isometry3d X_NdiRef = Eigen::Isometry3d::Identity();
  X_NdiRef.linear() = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.2, 0.3, 1).normalized()).toRotationMatrix();
  X_NdiRef.translation() = Eigen::Vector3d(-50, 120, -1400);
  for (std::int64_t k = 0; k < 6; ++k) {
    const std::int64_t t = 1'000'000 + k * 16'667;
    const Eigen::Isometry3d X_RefCam = test_X_CamRef(k).inverse();
    const Eigen::Isometry3d X_NdiMarker = X_NdiRef * X_RefCam * X_MarkerCam.inverse();
    if (k < 3) {  // NDI poses in Ndi
      s.on_pose(pose_msg("reference", "Ndi", X_NdiRef, 100 + k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
      s.on_pose(pose_msg("cam_marker", "Ndi", X_NdiMarker, 100 + k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
    } else {  // the appliance publishing in Ref (frames.reference: Ref)
      s.on_pose(pose_msg("reference", "Ndi", X_NdiRef, 100 + k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
      s.on_pose(pose_msg("cam_marker", "Ref", X_RefCam * X_MarkerCam.inverse(), 100 + k, t, true, tool_pose_t::SOURCE_NDI), t + 1000);
    }
    s.advance_model(t + 2000);
    const FrameResult r = s.render_frame(frame_msg(k, t), t + 3000);
    ASSERT_TRUE(r.row.tumour_px) << "frame " << k << " flags " << r.row.flags;
    EXPECT_LT(cv::norm(*r.row.tumour_px - expected_tumour_px(k)), 0.05) << "frame " << k;
    EXPECT_EQ(r.row.flags, "");
  }
  // The camera marker missing: no camera pose, banner.
  const std::int64_t t = 2'000'000;
  s.on_pose(pose_msg("reference", "Ndi", X_NdiRef, 200, t, true, tool_pose_t::SOURCE_NDI), t);
  s.on_pose(pose_msg("cam_marker", "Ndi", X_NdiRef, 200, t, false, tool_pose_t::SOURCE_NDI), t);
  const FrameResult r = s.render_frame(frame_msg(10, t), t + 1000);
  EXPECT_FALSE(r.row.tumour_px);
  EXPECT_NE(r.row.flags.find("camera_pose_lost"), std::string::npos) << r.row.flags;
}

TEST_F(SessionRun, DownscaledFramesUseScaledIntrinsics) {
  SessionFolder f("scaled");
  auto s = make(f);
  const std::int64_t t = 1'000'000;
  s->on_pose(pose_msg("liver_marker", "Cam", test_X_CamRef(0), 0, t), t);
  const FrameResult r = s->render_frame(frame_msg(0, t, 640, 360), t + 1000);
  ASSERT_TRUE(r.row.tumour_px);
  const cv::Point2d e = expected_tumour_px(0);
  EXPECT_LT(cv::norm(*r.row.tumour_px - cv::Point2d((e.x + 0.5) / 2 - 0.5, (e.y + 0.5) / 2 - 0.5)), 0.05);
}

// Issue 29: a scene setting the model cannot hold at the session's rate is refused when the
// session is made (arnav-host: exit 2, before it starts), naming the session file and line,
// the scene file and its model line, the key, the reason and the setting that holds; that
// setting is then accepted.
TEST_F(SessionRun, SettingTheModelCannotHoldIsRefusedBeforeTheSessionStarts) {
  SessionFolder f("refused");
  const SessionConfig config = load_session(f.session());
  SessionOptions o;
  o.threaded = false;
  auto refusal = [&](const Scene& scene) -> std::string {
    try {
      NavigationSession s(config, std::make_unique<Scene>(scene), o);
    } catch (const SessionError& e) {
      return e.what();
    }
    return "(accepted)";
  };
  // Explicit mass-spring, one substep a 1/60 s step: beyond its stability bound.
  Scene explicit_ms = *scene_;
  explicit_ms.model = ModelConfig{};
  explicit_ms.model.kind = "mass_spring";
  explicit_ms.model.integrator = "explicit";
  explicit_ms.model.substeps = 1;
  std::string m = refusal(explicit_ms);
  EXPECT_NE(m.find("session.yaml:3: key 'scene': " + scene_->source + ":" + std::to_string(scene_->model_line) + ": "), std::string::npos) << m;
  EXPECT_GT(scene_->model_line, 1);
  EXPECT_NE(m.find("beyond its stability bound"), std::string::npos) << m;
  EXPECT_NE(m.find("the session's model.rate_hz 60"), std::string::npos) << m;
  const std::size_t at = m.find("model.substeps >= ");
  ASSERT_NE(at, std::string::npos) << m;
  explicit_ms.model.substeps = std::stoi(m.substr(at + 18));
  EXPECT_GT(explicit_ms.model.substeps, 1);
  EXPECT_EQ(refusal(explicit_ms), "(accepted)");
  // Quasi-static FEM on a body nothing holds: singular at every step.
  Scene floating = *scene_;
  floating.model.integrator = "quasi_static";
  floating.model.linear_solver = "cholmod";
  floating.problem.fixed_vertices.clear();
  m = refusal(floating);
  EXPECT_NE(m.find("key 'scene': " + scene_->source), std::string::npos) << m;
  EXPECT_NE(m.find("model.integrator: quasi_static"), std::string::npos) << m;
  EXPECT_NE(m.find("add boundary.fixed"), std::string::npos) << m;
  floating.problem.fixed_vertices = scene_->problem.fixed_vertices;
  EXPECT_EQ(refusal(floating), "(accepted)");
}

}  // namespace
}  // namespace arnav::host
