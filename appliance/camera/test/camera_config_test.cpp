#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "appliance/camera/camera_config.hpp"
#include "appliance/synthetic_camera/phantom_recording.hpp"
#include "calibration/lib/rigid_transform_file.hpp"

namespace arnav::camera {
namespace {

const std::string kSynthetic = R"(port: sim
camera:
  source: synthetic
  width: 640
  height: 480
  fps: 30
  detector: {family: tag36h11, decimate: 2, threads: 1}
  tools:
    - name: pointer
      tag: {id: 3, size_mm: 40}
    - name: probe
      tag: {id: 7, size_mm: 30}
  synthetic:
    hfov_deg: 60
    distortion: [-0.1, 0.01, 0, 0, 0]
    noise_sigma: 2
    occluders:
      - polygon_px: [[10, 10], [100, 10], [100, 60]]
        reflectance: 0.2
    boards:
      - tool: pointer
        trajectory: {distance_mm: 400, amplitude_mm: [30, 20, 40], period_s: 5}
)";

void expect_error(const std::string& text, const std::string& needle) {
  try {
    parse_camera_config(text, "app.yaml", ".");
    ADD_FAILURE() << "accepted:\n" << text;
  } catch (const CameraConfigError& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return s.replace(pos, from.size(), to);
}

TEST(CameraConfig, SyntheticCameraSectionParses) {
  const auto c = parse_camera_config(kSynthetic, "app.yaml", ".");
  ASSERT_TRUE(c);
  EXPECT_EQ(c->source, SourceKind::Synthetic);
  ASSERT_EQ(c->tools.size(), 2u);
  EXPECT_EQ(c->tools[1].board.name, "probe");
  EXPECT_EQ(c->tools[1].tool_id, 7);
  ASSERT_TRUE(c->synthetic);
  EXPECT_EQ(c->synthetic->boards.size(), 1u);
  EXPECT_DOUBLE_EQ(c->synthetic->boards[0].trajectory.distance_mm, 400);
  EXPECT_EQ(c->camera.width, 640);
  EXPECT_EQ(c->camera.distortion.size(), 5u);
  EXPECT_DOUBLE_EQ(c->synthetic->render.noise_sigma, 2);
  ASSERT_EQ(c->synthetic->render.occluders.size(), 1u);
  EXPECT_EQ(c->synthetic->render.occluders[0].polygon_px.size(), 3u);
  EXPECT_DOUBLE_EQ(c->synthetic->render.occluders[0].reflectance, 0.2);
  EXPECT_FALSE(parse_camera_config("port: sim\n", "app.yaml", "."));
}

TEST(CameraConfig, MistakesNameFileLineAndKey) {
  expect_error(replace(kSynthetic, "  fps: 30\n", "  fps: 30\n  fsp: 3\n"), "app.yaml:7: key 'camera.fsp': unknown key");
  expect_error(replace(kSynthetic, "source: synthetic", "source: webcam"), "app.yaml:3: key 'camera.source'");
  expect_error(replace(kSynthetic, "decimate: 2", "decimate: 0"), "key 'camera.detector.decimate': must be between 1 and 8");
  expect_error(replace(kSynthetic, "family: tag36h11", "family: tag99"), "camera.detector.family");
  expect_error(replace(kSynthetic, "id: 7", "id: 3"), "tag id 3 is used by two tools");
  expect_error(replace(kSynthetic, "id: 7", "id: 9999"), "camera.tools[1].tag.id");
  expect_error(replace(kSynthetic, "name: probe", "name: pointer"), "'pointer' appears twice");
  expect_error(replace(kSynthetic, "tool: pointer", "tool: scalpel"), "'scalpel' is not in camera.tools");
  expect_error(replace(kSynthetic, "source: synthetic", "source: v4l2"), "camera.intrinsics': missing");
  expect_error(replace(kSynthetic, "- name: probe\n      tag: {id: 7, size_mm: 30}", "- name: probe\n      board: nope.yaml"),
               "nope.yaml");
  expect_error(replace(kSynthetic, "amplitude_mm: [30, 20, 40]", "amplitude_mm: [30, 20]"), "expected [x, y, z]");
  expect_error("camera: [1, 2\n", "YAML syntax error");
  expect_error(replace(kSynthetic, "[[10, 10], [100, 10], [100, 60]]", "[[10, 10], [100, 10]]"), "needs at least 3");
}

TEST(CameraConfig, PhantomSectionLoadsTheRecordingAndNamesMistakes) {
  const auto dir = std::filesystem::temp_directory_path() / ("arnav_phcfg_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  camera_sim::PhantomRecording rec;
  rec.tool_names = {"grasper"};
  rec.target_names = {"tumour_centroid"};
  rec.vertex_count = 3;
  rec.faces = {{0, 1, 2}};
  camera_sim::PhantomFrame f;
  f.X_ModelTool = {Eigen::Isometry3d::Identity()};
  f.targets_Model_mm = {Eigen::Vector3d(1, 2, 3)};
  f.vertices_Model_mm = Eigen::Matrix3Xd::Identity(3, 3);
  rec.frames = {f};
  camera_sim::write_phantom_recording(dir / "phantom.txt", rec);
  calib::RigidTransformRecord reg;
  reg.parent_frame = "Ref";
  reg.child_frame = "Model";
  reg.X_ParentChild.translation() = Eigen::Vector3d(-235, 206, 40);
  reg.date = "2026-11-25T00:00:00Z";
  calib::write_transform(dir / "X_RefModel.yaml", reg);
  {
    std::ofstream bad(dir / "bad.txt");
    bad << "# arnav phantom recording 1\nframe Model\ntools 0\ntargets 1 t\nvertices 3\nfaces 1\nf 0 1 9\n";
  }
  const std::string phantom = kSynthetic + "    phantom: {recording: phantom.txt, board: pointer, X_BoardModel: X_RefModel.yaml, reflectance: 0.5}\n";
  const auto c = parse_camera_config(phantom, "app.yaml", dir);
  ASSERT_TRUE(c && c->synthetic && c->synthetic->phantom);
  EXPECT_EQ(c->synthetic->phantom->board_index, 0u);
  EXPECT_EQ(c->synthetic->phantom->recording->frames.size(), 1u);
  EXPECT_TRUE(c->synthetic->phantom->X_BoardModel.translation().isApprox(Eigen::Vector3d(-235, 206, 40)));
  EXPECT_DOUBLE_EQ(c->synthetic->phantom->reflectance, 0.5);
  EXPECT_FALSE(c->synthetic->phantom->epoch_mono_us.has_value());  // the camera's own clock unless the bench names one
  const auto with_epoch = parse_camera_config(replace(phantom, "reflectance: 0.5", "reflectance: 0.5, epoch_mono_us: 123456789"), "app.yaml", dir);
  ASSERT_TRUE(with_epoch && with_epoch->synthetic && with_epoch->synthetic->phantom);
  EXPECT_EQ(with_epoch->synthetic->phantom->epoch_mono_us, 123456789);
  const auto expect_dir_error = [&](const std::string& text, const std::string& needle) {
    try {
      parse_camera_config(text, "app.yaml", dir);
      ADD_FAILURE() << "accepted:\n" << text;
    } catch (const CameraConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_dir_error(replace(phantom, "recording: phantom.txt", "recording: missing.txt"), "app.yaml:23: key 'camera.synthetic.phantom.recording'");
  expect_dir_error(replace(phantom, "recording: phantom.txt", "recording: bad.txt"), "bad.txt:7: vertex index 9 is outside");
  expect_dir_error(replace(phantom, "board: pointer", "board: probe"), "'probe' is not a rendered board");
  expect_dir_error(replace(phantom, "X_BoardModel: X_RefModel.yaml", "X_BoardModel: nope.yaml"), "camera.synthetic.phantom.X_BoardModel");
  expect_dir_error(replace(phantom, "reflectance: 0.5", "reflectance: 5"), "phantom.reflectance': must be between");
  expect_dir_error(replace(phantom, "reflectance: 0.5", "colour: 5"), "unknown key");
  expect_dir_error(replace(phantom, "reflectance: 0.5", "epoch_mono_us: -1"), "phantom.epoch_mono_us'");
  expect_dir_error(replace(phantom, "recording: phantom.txt, ", ""), "phantom.recording': missing");
  std::filesystem::remove_all(dir);
}

TEST(FramesConfig, ReferenceNeedsItsCalibration) {
  EXPECT_EQ(parse_frames_config("port: sim\n", "app.yaml", ".").reference, frames::Reference::Cam);
  try {
    parse_frames_config("camera:\n  source: synthetic\nframes:\n  reference: Ref\n  reference_tool: ref\n", "app.yaml", ".");
    FAIL();
  } catch (const CameraConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("frames.hand_eye"), std::string::npos) << e.what();
  }
  try {
    parse_frames_config("frames:\n  reference: World\n", "app.yaml", ".");
    FAIL();
  } catch (const CameraConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("app.yaml:2"), std::string::npos) << e.what();
  }
  // NDI only: Ref (or Ndi) needs no hand-eye.
  const auto ndi_only = parse_frames_config("port: sim\nframes:\n  reference: Ref\n  reference_tool: ref\n", "app.yaml", ".");
  EXPECT_EQ(ndi_only.reference, frames::Reference::Ref);
  EXPECT_TRUE(ndi_only.hand_eye.empty());
  const auto f = parse_frames_config("frames:\n  reference: Ref\n  reference_tool: ref\n  hand_eye: calib/X_CamNdi.yaml\n",
                                     "app.yaml", "/etc/arnav");
  EXPECT_EQ(f.hand_eye, std::filesystem::path("/etc/arnav/calib/X_CamNdi.yaml"));
}

}  // namespace
}  // namespace arnav::camera
