// The camera path end to end inside one process: synthetic camera -> detection -> pose ->
// reference frame -> LCM (memq), checked against the synthetic camera's ground truth.
#include <gtest/gtest.h>

#include <map>

#include "appliance/camera/camera_pipeline.hpp"
#include "arnav/appliance_event_t.hpp"
#include "arnav/device_health_t.hpp"
#include "arnav/image_frame_t.hpp"
#include "arnav/tool_pose_t.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::camera {
namespace {

const std::string kConfig = R"(camera:
  source: synthetic
  width: 640
  height: 480
  fps: 30
  realtime: false
  detector: {family: tag36h11, decimate: 1}
  publish_frames: {every: 5, jpeg_quality: 70}
  tools:
    - name: pointer
      tag: {id: 3, size_mm: 50}
  synthetic:
    frames: 40
    noise_sigma: 2
    boards:
      - tool: pointer
        trajectory: {distance_mm: 400, amplitude_mm: [40, 30, 50], period_s: 1.3, tilt_deg: 30}
)";

struct Collector {
  std::map<std::int64_t, tool_pose_t> poses;
  std::vector<device_health_t> health;
  std::vector<appliance_event_t> events;
  std::vector<image_frame_t> images;
  void pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { poses[m->device_frame_number] = *m; }
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) { health.push_back(*m); }
  void event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m) { events.push_back(*m); }
  void image(const lcm::ReceiveBuffer*, const std::string&, const image_frame_t* m) { images.push_back(*m); }
};

TEST(CameraPipeline, PublishesCameraPosesThatMatchGroundTruth) {
  auto cfg = parse_camera_config(kConfig, "test.yaml", ".");
  ASSERT_TRUE(cfg);
  auto lcm = std::make_shared<seal::SealedLcm>("memq://", seal::BusSecurity::off());
  ASSERT_TRUE(lcm->good());
  Collector col;
  lcm->subscribe("ARNAV_POSE_pointer", &Collector::pose, &col);
  lcm->subscribe("ARNAV_HEALTH_camera", &Collector::on_health, &col);
  lcm->subscribe("ARNAV_EVENT", &Collector::event, &col);
  lcm->subscribe("ARNAV_FRAME_cam0", &Collector::image, &col);
  capture::SyntheticSource truth(*cfg->synthetic);  // same trajectory, for ground truth
  CameraPipeline pipeline(*cfg, nullptr, lcm);
  std::atomic<bool> stop{false};
  EXPECT_EQ(pipeline.run(stop), 40);
  while (lcm->handleTimeout(0) > 0) {
  }
  ASSERT_EQ(col.poses.size(), 40u);
  int valid = 0;
  for (const auto& [seq, m] : col.poses) {
    EXPECT_EQ(m.source, +tool_pose_t::SOURCE_CAMERA);
    EXPECT_EQ(m.tool_id, 3);
    EXPECT_EQ(m.frame_parent, "Cam");
    if (m.status != tool_pose_t::STATUS_VALID) continue;
    ++valid;
    const Eigen::Isometry3d X = get_pose(m);
    const Eigen::Isometry3d X_true = truth.X_CamBoard(0, seq);
    EXPECT_LT((X.translation() - X_true.translation()).norm(), 3.0) << "frame " << seq;
    EXPECT_LT(Eigen::AngleAxisd(X.linear().transpose() * X_true.linear()).angle() * 180 / M_PI, 2.0) << "frame " << seq;
    EXPECT_GT(m.quality, 0.f);
    EXPECT_LT(m.reprojection_error_px, 1.5f);
  }
  EXPECT_GE(valid, 36);
  ASSERT_FALSE(col.health.empty());
  EXPECT_EQ(col.health.back().device, "camera");
  EXPECT_EQ(col.health.back().frames_total, 40);
  EXPECT_EQ(col.health.back().dropped_frames, 0);
  bool found = false, ended = false;
  for (const auto& e : col.events) {
    found = found || e.code == "CAMERA_TOOL_FOUND";
    ended = ended || e.code == "CAMERA_END";
    EXPECT_EQ(e.source, "camera");
  }
  EXPECT_TRUE(found);
  EXPECT_TRUE(ended);
  ASSERT_EQ(col.images.size(), 8u);  // every 5th of 40
  EXPECT_EQ(col.images[0].encoding, +image_frame_t::ENCODING_JPEG);
  EXPECT_EQ(col.images[0].width, 640);
  EXPECT_EQ(static_cast<size_t>(col.images[0].size), col.images[0].data.size());
}

TEST(CameraPipeline, ReferenceFrameAppliedAndMissingReferenceReported) {
  auto cfg = parse_camera_config(kConfig, "test.yaml", ".");
  ASSERT_TRUE(cfg);
  cfg->synthetic->frame_count = 6;
  Eigen::Isometry3d X_NdiCam = Eigen::Isometry3d::Identity();
  X_NdiCam.translation() = Eigen::Vector3d(100, -50, -1200);
  auto frames = std::make_shared<frames::ReferenceFrames>(frames::Reference::Ndi, X_NdiCam, "", 0.05);
  auto lcm = std::make_shared<seal::SealedLcm>("memq://", seal::BusSecurity::off());
  Collector col;
  lcm->subscribe("ARNAV_POSE_pointer", &Collector::pose, &col);
  capture::SyntheticSource truth(*cfg->synthetic);
  CameraPipeline pipeline(*cfg, frames, lcm);
  std::atomic<bool> stop{false};
  pipeline.run(stop);
  while (lcm->handleTimeout(0) > 0) {
  }
  ASSERT_FALSE(col.poses.empty());
  for (const auto& [seq, m] : col.poses) {
    EXPECT_EQ(m.frame_parent, "Ndi");
    if (m.status == tool_pose_t::STATUS_VALID) {
      EXPECT_LT((get_pose(m).translation() - (X_NdiCam * truth.X_CamBoard(0, seq)).translation()).norm(), 3.0);
    }
  }
  // Ref without any reference pose: every pose is MISSING and the reason is an event.
  auto ref = std::make_shared<frames::ReferenceFrames>(frames::Reference::Ref, X_NdiCam, "ref", 0.05);
  Collector col2;
  auto lcm2 = std::make_shared<seal::SealedLcm>("memq://", seal::BusSecurity::off());
  lcm2->subscribe("ARNAV_POSE_pointer", &Collector::pose, &col2);
  lcm2->subscribe("ARNAV_EVENT", &Collector::event, &col2);
  CameraPipeline p2(*cfg, ref, lcm2);
  p2.run(stop);
  while (lcm2->handleTimeout(0) > 0) {
  }
  for (const auto& [seq, m] : col2.poses) EXPECT_EQ(m.status, +tool_pose_t::STATUS_MISSING);
  bool reason = false;
  for (const auto& e : col2.events) reason = reason || e.text.find("reference tool 'ref' not seen yet") != std::string::npos;
  EXPECT_TRUE(reason);
}

}  // namespace
}  // namespace arnav::camera
