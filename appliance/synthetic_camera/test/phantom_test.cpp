// Phantom recordings (read/write, errors with file:line, interpolation), the renderer's
// surface drawing (pixels where the recording puts the organ, depth against boards) and
// the ground-truth projection of the deformed targets (against cv::projectPoints).
#include <gtest/gtest.h>

#include <map>

#include <opencv2/calib3d.hpp>

#include <filesystem>
#include <numbers>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include "appliance/capture/synthetic_source.hpp"
#include "appliance/markers/camera_model.hpp"
#include "appliance/synthetic_camera/ground_truth.hpp"
#include "appliance/synthetic_camera/phantom_recording.hpp"
#include "protocol/clock.hpp"
#include "appliance/synthetic_camera/synthetic_renderer.hpp"

namespace arnav::camera_sim {
namespace {

// A closed, outward-oriented box surface (8 vertices, 12 triangles), centre c, half sizes h.
void box(const Eigen::Vector3d& c, const Eigen::Vector3d& h, Eigen::Matrix3Xd& v, std::vector<Eigen::Vector3i>& f) {
  v.resize(3, 8);
  for (int i = 0; i < 8; ++i) v.col(i) = c + Eigen::Vector3d((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  f = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4}, {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
}

PhantomRecording small_recording() {
  PhantomRecording r;
  r.tool_names = {"grasper"};
  r.target_names = {"tumour_centroid", "p1"};
  Eigen::Matrix3Xd v;
  box({0, 0, 0}, {20, 15, 10}, v, r.faces);
  r.vertex_count = 8;
  for (int k = 0; k < 3; ++k) {
    PhantomFrame f;
    f.t_s = 0.5 * k;
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear() = Eigen::AngleAxisd(0.2 * k, Eigen::Vector3d::UnitY()).toRotationMatrix();
    X.translation() = Eigen::Vector3d(1.0 * k, 2, -3);
    f.X_ModelTool = {X};
    f.targets_Model_mm = {Eigen::Vector3d(1.0 * k, 0, 0), Eigen::Vector3d(0, 5, 1.5 * k)};
    f.vertices_Model_mm = v;
    f.vertices_Model_mm.row(0).array() += 4.0 * k;  // the whole box slides along x
    r.frames.push_back(f);
  }
  return r;
}

std::string text_of(const PhantomRecording& r) {
  std::ostringstream ss;
  write_phantom_recording(ss, r);
  return ss.str();
}

// Replaces line `line_no` (1-based) of text.
std::string with_line(const std::string& text, int line_no, const std::string& replacement) {
  std::istringstream in(text);
  std::string line, out;
  for (int n = 1; std::getline(in, line); ++n) out += (n == line_no ? replacement : line) + "\n";
  return out;
}

void expect_error(const std::string& text, const std::string& where) {
  try {
    parse_phantom_recording(text, "ph.txt");
    FAIL() << "accepted; expected an error at " << where;
  } catch (const PhantomError& e) {
    EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
  }
}

TEST(PhantomRecording, WriteThenReadRoundTrips) {
  const PhantomRecording r = small_recording();
  const auto path = std::filesystem::temp_directory_path() / ("arnav_phantom_" + std::to_string(::getpid()) + ".txt");
  write_phantom_recording(path, r);
  const PhantomRecording back = read_phantom_recording(path);
  std::filesystem::remove(path);
  ASSERT_EQ(back.frames.size(), 3u);
  EXPECT_EQ(back.tool_names, r.tool_names);
  EXPECT_EQ(back.target_names, r.target_names);
  EXPECT_EQ(back.faces, r.faces);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_DOUBLE_EQ(back.frames[k].t_s, r.frames[k].t_s);
    EXPECT_TRUE(back.frames[k].X_ModelTool[0].isApprox(r.frames[k].X_ModelTool[0], 1e-6));
    EXPECT_TRUE(back.frames[k].vertices_Model_mm.isApprox(r.frames[k].vertices_Model_mm, 1e-6));
    EXPECT_TRUE(back.frames[k].targets_Model_mm[1].isApprox(r.frames[k].targets_Model_mm[1], 1e-6));
  }
}

TEST(PhantomRecording, InterpolatesBetweenFramesAndHoldsOutside) {
  const PhantomRecording r = small_recording();
  const PhantomFrame mid = r.at(0.25);
  EXPECT_NEAR(mid.vertices_Model_mm(0, 0), r.frames[0].vertices_Model_mm(0, 0) + 2.0, 1e-12);
  EXPECT_NEAR(mid.targets_Model_mm[0].x(), 0.5, 1e-12);
  EXPECT_NEAR(Eigen::AngleAxisd(mid.X_ModelTool[0].linear()).angle(), 0.1, 1e-9);
  EXPECT_TRUE(r.tool_pose_at(0.25, 0).isApprox(mid.X_ModelTool[0], 1e-12));
  EXPECT_TRUE(r.at(-1.0).vertices_Model_mm.isApprox(r.frames[0].vertices_Model_mm));
  EXPECT_TRUE(r.at(99.0).vertices_Model_mm.isApprox(r.frames[2].vertices_Model_mm));
  EXPECT_EQ(r.tool_index("grasper"), 0);
  EXPECT_EQ(r.tool_index("scalpel"), -1);
}

TEST(PhantomRecording, BadFilesNameTheLine) {
  const std::string good = text_of(small_recording());
  // Layout: 1 header, 2 frame, 3 tools, 4 targets, 5 vertices, 6 faces, 7-18 f, 19 frames,
  // 20 t, 21 tool, 22-23 target, 24-31 v, 32 t ...
  expect_error("", "ph.txt:1: not a phantom recording");
  expect_error(with_line(good, 1, "# arnav phantom recording 7"), "ph.txt:1: phantom recording version '7'");
  expect_error(with_line(good, 2, "frame World"), "ph.txt:2: frame must be 'Model'");
  expect_error(with_line(good, 3, "tools 2 grasper"), "ph.txt:3:");
  expect_error(with_line(good, 4, "targets 2 a a"), "ph.txt:4: target 'a' is declared twice");
  expect_error(with_line(good, 5, "vertices -3"), "ph.txt:5: vertex count -3");
  expect_error(with_line(good, 5, "vertices 1000000"), "ph.txt:5: vertex count 1000000 cannot fit");
  expect_error(with_line(good, 7, "f 0 0 1"), "ph.txt:7: face uses a vertex twice");
  expect_error(with_line(good, 8, "f 0 1 8"), "ph.txt:8: vertex index 8 is outside");
  expect_error(with_line(good, 21, "tool grasper 1 2 3 2 0 0 0"), "ph.txt:21: tool quaternion is not unit");
  expect_error(with_line(good, 21, "tool scalpel 1 2 3 1 0 0 0"), "ph.txt:21: expected tool 'grasper'");
  expect_error(with_line(good, 24, "v 1 nan 3"), "ph.txt:24: 'nan' is not a finite number");
  expect_error(with_line(good, 25, "v 1 2"), "ph.txt:25: 'v' takes 3 value(s)");
  expect_error(with_line(good, 32, "t 0.0"), "ph.txt:32: time 0.0 s does not increase");
  {
    std::size_t cut = 0;
    for (int n = 0; n < 27; ++n) cut = good.find('\n', cut) + 1;
    expect_error(good.substr(0, cut), "ph.txt:28: file ends where 'v' was expected (truncated recording?");
  }
  expect_error(good + "v 1 2 3\n", "after the last frame");
  try {
    read_phantom_recording("/nonexistent/phantom.txt");
    FAIL();
  } catch (const PhantomError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/phantom.txt: cannot read"), std::string::npos);
  }
}

markers::CameraModel test_camera() {
  markers::CameraModel cam = markers::pinhole_camera(640, 480, 60);
  cam.distortion = {-0.05, 0.01, 0, 0, 0};
  return cam;
}

TEST(PhantomRender, SurfaceDrawnWhereItProjects) {
  const markers::CameraModel cam = test_camera();
  SyntheticRenderer renderer(cam);
  Eigen::Matrix3Xd v;
  std::vector<Eigen::Vector3i> faces;
  box({30, -20, 400}, {40, 30, 20}, v, faces);
  RenderOptions opt;
  opt.background_reflectance = 0.1;
  const RenderResult r = renderer.render({}, {{&v, &faces, 0.8}}, opt);
  ASSERT_FALSE(r.surface_mask.empty());
  // The front face (z = 380) projects to a quadrilateral: its centre and a point just inside
  // each corner are drawn bright, points just outside are background.
  std::vector<Eigen::Vector3d> inside{{30, -20, 380}}, outside;
  for (int sx : {-1, 1})
    for (int sy : {-1, 1}) {
      inside.emplace_back(30 + sx * 36, -20 + sy * 26, 380);
      outside.emplace_back(30 + sx * 46, -20 + sy * 36, 380);
    }
  for (const auto& p : cam.project(inside)) {
    EXPECT_EQ(r.surface_mask.at<std::uint8_t>(cvRound(p.y), cvRound(p.x)), 255) << p;
    EXPECT_GT(r.image.at<std::uint8_t>(cvRound(p.y), cvRound(p.x)), 150) << p;
  }
  for (const auto& p : cam.project(outside)) {
    EXPECT_EQ(r.surface_mask.at<std::uint8_t>(cvRound(p.y), cvRound(p.x)), 0) << p;
    EXPECT_LT(r.image.at<std::uint8_t>(cvRound(p.y), cvRound(p.x)), 40) << p;
  }
  // A deformed surface: the box moved 50 mm right is drawn there, not where it was.
  Eigen::Matrix3Xd moved = v;
  moved.row(0).array() += 50.0;
  const RenderResult r2 = renderer.render({}, {{&moved, &faces, 0.8}}, opt);
  const auto old_left = cam.project({Eigen::Vector3d(30 - 36, -20, 380)})[0];
  const auto new_right = cam.project({Eigen::Vector3d(80 + 36, -20, 380)})[0];
  EXPECT_EQ(r2.surface_mask.at<std::uint8_t>(cvRound(old_left.y), cvRound(old_left.x)), 0);
  EXPECT_EQ(r2.surface_mask.at<std::uint8_t>(cvRound(new_right.y), cvRound(new_right.x)), 255);
}

TEST(PhantomRender, BoardAndSurfaceComposeByDepth) {
  const markers::CameraModel cam = test_camera();
  SyntheticRenderer renderer(cam);
  markers::TagBoard board = markers::single_tag_board("b", "tag36h11", 3, 60);
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(0, 0, 400);
  Eigen::Matrix3Xd v;
  std::vector<Eigen::Vector3i> faces;
  RenderOptions opt;
  // Surface behind the board: the tag is fully visible.
  box({0, 0, 500}, {200, 200, 20}, v, faces);
  auto r = renderer.render({{&board, X}}, {{&v, &faces, 0.6}}, opt);
  ASSERT_EQ(r.tags.size(), 1u);
  EXPECT_LT(r.tags[0].occluded_fraction, 0.01);
  const auto centre = cam.project({Eigen::Vector3d(0, 0, 400)})[0];
  EXPECT_EQ(r.surface_mask.at<std::uint8_t>(cvRound(centre.y), cvRound(centre.x)), 0);
  // Surface in front of the board: the tag is hidden (counted occluded).
  box({0, 0, 300}, {200, 200, 20}, v, faces);
  r = renderer.render({{&board, X}}, {{&v, &faces, 0.6}}, opt);
  EXPECT_GT(r.tags[0].occluded_fraction, 0.99);
  EXPECT_EQ(r.surface_mask.at<std::uint8_t>(cvRound(centre.y), cvRound(centre.x)), 255);
}

// A camera 400 mm from a one-tag board, the small recording's phantom placed on it; ground
// truth written to dir/gt.csv.
capture::SyntheticSettings phantom_settings(const std::filesystem::path& dir, double fps, bool realtime, int frame_count) {
  capture::SyntheticSettings s;
  s.camera = test_camera();
  s.fps = fps;
  s.realtime = realtime;
  s.frame_count = frame_count;
  s.ground_truth_csv = dir / "gt.csv";
  markers::TagBoard board = markers::single_tag_board("liver_marker", "tag36h11", 3, 40);
  Trajectory tr;
  tr.amplitude_mm.setZero();
  tr.tilt_deg = tr.spin_deg = 0;
  tr.distance_mm = 400;
  tr.image_offset_mm = Eigen::Vector2d(80, 0);
  s.boards.push_back({board, tr});
  capture::SyntheticPhantom ph;
  ph.recording = std::make_shared<const PhantomRecording>(small_recording());
  ph.X_BoardModel.linear() = Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).toRotationMatrix();
  ph.X_BoardModel.translation() = Eigen::Vector3d(-120, 0, -20);
  s.phantom = ph;
  return s;
}

TEST(PhantomSource, GroundTruthHoldsDeformedTargetsProjectedLikeOpenCv) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_phsrc_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  capture::SyntheticSettings s = phantom_settings(dir, 10, false, 3);
  const capture::SyntheticPhantom ph = *s.phantom;
  capture::SyntheticSource src(s);
  src.open();
  for (int k = 0; k < 3; ++k) {
    capture::Frame f;
    ASSERT_EQ(src.read(f).status, capture::ReadStatus::Ok);
  }
  src.close();
  const auto rows = read_ground_truth(dir / "gt.csv");
  std::filesystem::remove_all(dir);
  ASSERT_EQ(rows.size(), 9u);  // per frame: the board + 2 targets
  int checked = 0;
  for (const auto& row : rows) {
    if (!row.is_target()) continue;
    const Eigen::Isometry3d X_CamModel = src.X_CamBoard(0, row.sequence) * ph.X_BoardModel;
    const PhantomFrame pf = ph.recording->at(row.sequence / 10.0);
    const int i = row.board == "target:tumour_centroid" ? 0 : 1;
    const Eigen::Vector3d p = X_CamModel * pf.targets_Model_mm[static_cast<std::size_t>(i)];
    EXPECT_TRUE(row.X_CamBoard.translation().isApprox(p, 1e-5));
    std::vector<cv::Point2d> px;
    cv::projectPoints(std::vector<cv::Point3d>{{p.x(), p.y(), p.z()}}, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(s.camera.K),
                      cv::Mat(s.camera.distortion), px);
    ASSERT_TRUE(row.has_px);
    EXPECT_NEAR(row.u_px, px[0].x, 1e-3);
    EXPECT_NEAR(row.v_px, px[0].y, 1e-3);
    EXPECT_EQ(row.tags_visible, 1);
    ++checked;
  }
  EXPECT_EQ(checked, 6);
}

// The bench's world clock (docs/hil.md "World clock"): with an epoch, the camera's frames
// count from it (those already due when it opens are skipped) and a frame shows the phantom
// at its capture time minus the epoch (the time the simulated Polaris moves the phantom's
// tool on), not at k / fps since the camera opened.
TEST(PhantomSource, WorldClockEpochPicksThePhantomAtTheCaptureTime) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_phepoch_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  // Enough frames that a renderer slowed by a busy machine still delivers three (a frame it
  // cannot render in time is dropped, docs/camera.md "Timestamps").
  capture::SyntheticSettings s = phantom_settings(dir, 20, true, 400);
  s.phantom->epoch_mono_us = monotonic_us() - 400'000;  // the world started 0.4 s before the camera opens
  const capture::SyntheticPhantom ph = *s.phantom;
  capture::SyntheticSource src(s);
  src.open();
  std::map<std::int64_t, std::int64_t> capture_us;
  for (int k = 0; k < 3; ++k) {
    capture::Frame f;
    ASSERT_EQ(src.read(f).status, capture::ReadStatus::Ok);
    capture_us[f.sequence] = f.capture_time_mono_us;
    // The frames count from the epoch: those already due when the camera opened are skipped.
    EXPECT_GE(f.sequence, 7);
    EXPECT_EQ(f.capture_time_mono_us, *ph.epoch_mono_us + f.sequence * 50'000);
  }
  src.close();
  const auto rows = read_ground_truth(dir / "gt.csv");
  std::filesystem::remove_all(dir);
  int checked = 0;
  for (const auto& row : rows) {
    if (row.board != "target:tumour_centroid") continue;
    const double t_world = 1e-6 * static_cast<double>(capture_us.at(row.sequence) - *ph.epoch_mono_us);
    EXPECT_GT(t_world, 0.35);
    const Eigen::Isometry3d X_CamModel = src.X_CamBoard(0, row.sequence) * ph.X_BoardModel;
    const Eigen::Vector3d expected = X_CamModel * ph.recording->at(t_world).targets_Model_mm[0];
    EXPECT_TRUE(row.X_CamBoard.translation().isApprox(expected, 1e-6)) << row.X_CamBoard.translation().transpose() << " vs " << expected.transpose();
    // Without the epoch the first frame would be sequence 0 at the camera's opening, showing
    // the recording at 0 s; here the phantom is 0.35+ s in.
    EXPECT_GT((expected - X_CamModel * ph.recording->at(0.0).targets_Model_mm[0]).norm(), 0.1);
    ++checked;
  }
  EXPECT_EQ(checked, 3);
}

}  // namespace
}  // namespace arnav::camera_sim
