#include <gtest/gtest.h>

#include "appliance/markers/camera_config.hpp"

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
