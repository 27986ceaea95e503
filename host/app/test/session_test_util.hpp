#pragma once
// Shared by the session tests: a temporary session folder (intrinsics, registration,
// session file on the bundled coarse liver) and synthetic appliance messages.
#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <unistd.h>

#include "arnav/image_frame_t.hpp"
#include "arnav/input_event_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "calibration/lib/camera_intrinsics.hpp"
#include "calibration/lib/rigid_transform_file.hpp"
#include "host/app/session_config.hpp"
#include "host/scene/scene.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::host::test {

inline std::string data_dir() {
  const char* d = std::getenv("ARNAV_DATA_DIR");
  return d ? d : "data";
}

// A test suite on the bundled coarse liver: the scene is loaded once per suite (scene_).
class CoarseLiverSuite : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene_ = new Scene(load_scene(data_dir() + "/liver/liver_coarse.scene.yaml")); }
  static void TearDownTestSuite() {
    delete scene_;
    scene_ = nullptr;
  }
  static inline Scene* scene_ = nullptr;
};

inline const Eigen::Vector3d kTumourCentre_Model(70, 160, 140);  // data/liver/*.scene.yaml

inline calib::CameraIntrinsics test_intrinsics() {
  calib::CameraIntrinsics c;
  c.camera_name = "cam0";
  c.image_width = 1280;
  c.image_height = 720;
  c.camera_matrix = cv::Matx33d(1000, 0, 641.5, 0, 1002, 358.25, 0, 0, 1);
  c.distortion = {-0.12, 0.03, 0.0005, -0.0004, 0.0};
  c.calibration_date = "2026-11-25T00:00:00Z";
  return c;
}

// Model rotated so the camera looks at the liver from "above" (Model +z toward the camera),
// tumour centre at the Ref origin.
inline Eigen::Isometry3d test_X_RefModel() {
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = (Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())).toRotationMatrix();
  X.translation() = -(X.linear() * kTumourCentre_Model);
  return X;
}

// The reference board seen by the camera at frame k: 380 mm away, drifting and turning.
inline Eigen::Isometry3d test_X_CamRef(std::int64_t k) {
  const double t = static_cast<double>(k) / 60.0;
  Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
  X.linear() = Eigen::AngleAxisd(0.15 * std::sin(t), Eigen::Vector3d(0.3, 1, 0).normalized()).toRotationMatrix();
  X.translation() = Eigen::Vector3d(30 * std::sin(0.7 * t), -20 * std::cos(0.5 * t), 380);
  return X;
}

struct SessionFolder {
  std::filesystem::path dir;
  explicit SessionFolder(const std::string& name) {
    dir = std::filesystem::temp_directory_path() / ("arnav_session_" + name + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    calib::write_intrinsics(dir / "camera.yaml", test_intrinsics());
    calib::RigidTransformRecord reg;
    reg.parent_frame = "Ref";
    reg.child_frame = "Model";
    reg.X_ParentChild = test_X_RefModel();
    reg.method = "test";
    reg.date = "2026-11-25T00:00:00Z";
    calib::write_transform(dir / "X_RefModel.yaml", reg);
  }
  ~SessionFolder() {
    if (!std::getenv("ARNAV_KEEP")) std::filesystem::remove_all(dir);
  }
  std::string write(const std::string& name, const std::string& text) const {
    std::ofstream(dir / name) << text;
    return (dir / name).string();
  }
  // A full session: camera + reference board + scalpel on the coarse liver.
  std::string session(const std::string& extra = "") const {
    return write("session.yaml", "arnav_session_version: 1\n"
                                 "lcm_url: \"memq://\"\n"
                                 "scene: " + data_dir() + "/liver/liver_coarse.scene.yaml\n"
                                 "registration: X_RefModel.yaml\n"
                                 "tools:\n"
                                 "  reference: {name: liver_marker, stale_after_ms: 100}\n"
                                 "  scalpel: {name: scalpel, stale_after_ms: 100, blade: {tip_mm: [0, 0, 0], heel_mm: [0, 0, 30]}}\n"
                                 "camera:\n"
                                 "  name: cam0\n"
                                 "  intrinsics: camera.yaml\n"
                                 "  pose_from: reference\n"
                                 "model: {rate_hz: 60, gravity: false}\n"
                                 "overlay: {margin_mm: 5, warn_mm: 5}\n" + extra + "security: off\n");
  }
};

inline tool_pose_t pose_msg(const std::string& tool, const std::string& parent, const Eigen::Isometry3d& X, std::int64_t frame,
                            std::int64_t time_us, bool valid = true, std::int8_t source = tool_pose_t::SOURCE_CAMERA) {
  tool_pose_t m{};
  m.tool_name = tool;
  m.source = source;
  m.frame_parent = parent;
  m.frame_child = "Tool";
  set_pose(m, X);
  m.status = valid ? tool_pose_t::STATUS_VALID : tool_pose_t::STATUS_MISSING;
  m.device_frame_number = frame;
  m.device_time_us = time_us;
  m.receive_time_mono_us = time_us;
  m.publish_time_mono_us = time_us + 500;
  m.receive_time_wall_us = time_us + 1'700'000'000'000'000;
  m.publish_time_wall_us = m.publish_time_mono_us + 1'700'000'000'000'000;
  m.sequence = frame;
  return m;
}

inline image_frame_t frame_msg(std::int64_t sequence, std::int64_t capture_us, int width = 1280, int height = 720) {
  cv::Mat img(height, width, CV_8UC3, cv::Scalar(90, 110, 140));
  cv::putText(img, std::to_string(sequence), {40, 200}, cv::FONT_HERSHEY_SIMPLEX, 3, cv::Scalar(255, 255, 255), 3);
  image_frame_t m{};
  m.camera_name = "cam0";
  m.sequence = sequence;
  m.capture_time_mono_us = capture_us;
  m.capture_time_wall_us = capture_us + 1'700'000'000'000'000;
  m.publish_time_mono_us = capture_us + 3000;
  m.width = m.source_width = width;
  m.height = m.source_height = height;
  m.channels = 3;
  m.encoding = image_frame_t::ENCODING_JPEG;
  cv::imencode(".jpg", img, m.data, {cv::IMWRITE_JPEG_QUALITY, 85});
  m.size = static_cast<std::int32_t>(m.data.size());
  return m;
}

// A pedal/button message as the appliance's CAN path publishes it: a change on ARNAV_INPUT,
// or (snapshot) the periodic state on ARNAV_INPUT_STATE.
inline input_event_t input_msg(const std::string& name, bool pressed, std::int64_t seq, std::int64_t t_us,
                               bool snapshot = false) {
  input_event_t m{};
  m.input_name = name;
  m.state = pressed ? input_event_t::STATE_PRESSED : input_event_t::STATE_RELEASED;
  m.value = pressed ? 1.0 : 0.0;
  m.cause = snapshot ? input_event_t::CAUSE_STATE : input_event_t::CAUSE_FRAME;
  m.device = "pedal";
  m.source_interface = "vcan0";
  m.device_time_wall_us = -1;
  m.receive_time_mono_us = t_us;
  m.decided_time_mono_us = t_us;
  m.publish_time_mono_us = t_us + 100;
  m.sequence = seq;
  return m;
}

// The SessionError text for a session file with this content ("(no error)" when it loads).
inline std::string session_error_of(const SessionFolder& folder, const std::string& text) {
  try {
    load_session(folder.write("bad.yaml", text));
  } catch (const SessionError& e) {
    return e.what();
  }
  return "(no error)";
}

}  // namespace arnav::host::test
