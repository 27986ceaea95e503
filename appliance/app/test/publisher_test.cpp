#include <gtest/gtest.h>

#include <cstdlib>

#include "appliance/app/publisher.hpp"
#include "appliance/ndi/test/fake_polaris.hpp"
#include "protocol/clock.hpp"
#include "protocol/pose_convert.hpp"

namespace arnav::app {
namespace {

using namespace std::chrono_literals;

std::filesystem::path rom(const std::string& name) {
  const char* data = std::getenv("ARNAV_DATA_DIR");
  if (!data) throw std::runtime_error("ARNAV_DATA_DIR is not set (run the test through ctest)");
  return std::filesystem::path(data) / "ndi_roms" / name;
}

struct Sink {
  std::vector<tool_pose_t> poses;
  std::vector<device_health_t> health;
  std::vector<appliance_event_t> events;
  void on_pose(const lcm::ReceiveBuffer*, const std::string&, const tool_pose_t* m) { poses.push_back(*m); }
  void on_health(const lcm::ReceiveBuffer*, const std::string&, const device_health_t* m) { health.push_back(*m); }
  void on_event(const lcm::ReceiveBuffer*, const std::string&, const appliance_event_t* m) { events.push_back(*m); }
};

// A session on the fake Polaris with short timeouts (the fake answers at once).
ndi::SessionConfig fast_session(std::vector<ndi::ToolConfig> tools) {
  ndi::SessionConfig c;
  c.tools = std::move(tools);
  c.setup_timeout = 300ms;
  c.reset_wait = 80ms;
  c.break_duration = 1ms;
  c.comm_settle = 1ms;
  return c;
}

void drain(lcm::LCM& lcm) {
  while (lcm.handleTimeout(10) > 0) {
  }
}

TEST(Publisher, PosesHealthAndEventsOverLcm) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  Sink sink;
  lcm.subscribe("ARNAV_POSE_.*", &Sink::on_pose, &sink);
  lcm.subscribe("ARNAV_HEALTH_ndi", &Sink::on_health, &sink);
  lcm.subscribe("ARNAV_EVENT", &Sink::on_event, &sink);

  ndi::SessionConfig c = fast_session({{"pointer", rom("8700340.rom")}, {"reference", rom("8700339.rom")}});
  c.tracking_timeout = 30ms;
  auto dev = std::make_shared<ndi::test::FakeDevice>();
  Publisher pub(lcm, c.tools, 60.0);
  ndi::Session session(c, ndi::test::fake_factory(dev), [&](const ndi::Event& e) { pub.publish_event(e); });
  ASSERT_TRUE(session.start());
  ndi::TrackingReply reply;
  std::int64_t rx = 0;
  for (int i = 0; i < 5; ++i) {
    ASSERT_EQ(session.poll(reply, rx), ndi::PollResult::NewFrame);
    const float latency = pub.publish_frame(session, reply, rx);
    EXPECT_GE(latency, 0.0f);
  }
  pub.publish_health(session, "fake0", 60.0);
  drain(lcm);

  ASSERT_EQ(sink.poses.size(), 10u);
  const tool_pose_t& last = sink.poses.back();
  EXPECT_EQ(last.tool_name, "reference");
  EXPECT_EQ(last.frame_parent, "Ndi");
  EXPECT_EQ(last.status, +tool_pose_t::STATUS_VALID);
  EXPECT_EQ(last.sequence, 5);
  EXPECT_EQ(last.device_frame_number, dev->frame);
  EXPECT_EQ(last.device_time_us, static_cast<std::int64_t>(dev->frame * 1e6 / 60.0));
  EXPECT_GE(last.publish_time_mono_us, last.receive_time_mono_us);
  // The fake's pose for this handle and frame: rotation about z by 0.01*frame, p = (10h, -20, -1500 + frame/2).
  const Eigen::Isometry3d X = get_pose(last);
  EXPECT_NEAR(X.translation().x(), 10.0 * last.tool_id, 1e-3);
  EXPECT_NEAR(X.translation().z(), -1500.0 + 0.5 * static_cast<double>(dev->frame), 1e-3);
  const double angle = Eigen::AngleAxisd(X.rotation()).angle();
  EXPECT_NEAR(angle, 0.01 * static_cast<double>(dev->frame), 1e-5);
  EXPECT_NEAR(last.rms_error_mm, 0.15f, 1e-6f);

  ASSERT_EQ(sink.health.size(), 1u);
  const auto& h = sink.health[0];
  EXPECT_EQ(h.link_state, +device_health_t::LINK_TRACKING);
  EXPECT_EQ(h.frames_total, 5);
  EXPECT_EQ(h.baud, 115200);
  EXPECT_EQ(h.serial_number, "P6-01234");
  EXPECT_GT(h.latency_max_us, 0.0f);
  EXPECT_LE(h.latency_p50_us, h.latency_p99_us);
  EXPECT_LE(h.latency_p99_us, h.latency_max_us);

  bool started = false;
  for (const auto& e : sink.events) started |= e.code == "NDI_TRACKING_STARTED";
  EXPECT_TRUE(started);
  EXPECT_EQ(sink.events.back().sequence, static_cast<std::int64_t>(sink.events.size()));
}

TEST(Publisher, OutOfVolumeAndMissingTools) {
  lcm::LCM lcm("memq://");
  Sink sink;
  lcm.subscribe("ARNAV_POSE_.*", &Sink::on_pose, &sink);
  const ndi::SessionConfig c = fast_session({{"pointer", rom("8700340.rom")}});
  auto dev = std::make_shared<ndi::test::FakeDevice>();
  ndi::Session session(c, ndi::test::fake_factory(dev), nullptr);
  ASSERT_TRUE(session.start());
  Publisher pub(lcm, c.tools, 60.0);
  ndi::TrackingReply reply;
  reply.count = 1;
  auto& r = reply.handles[0];
  r.handle = session.tools()[0].handle;
  r.state = ndi::HandleState::Valid;
  r.has_status = true;
  r.port_status = ndi::kPortOccupied | ndi::kPortOutOfVolume;
  r.frame_number = 7;
  pub.publish_frame(session, reply, arnav::monotonic_us());
  r.state = ndi::HandleState::Missing;
  pub.publish_frame(session, reply, arnav::monotonic_us());
  reply.count = 0;
  pub.publish_frame(session, reply, arnav::monotonic_us());
  drain(lcm);
  ASSERT_EQ(sink.poses.size(), 3u);
  EXPECT_EQ(sink.poses[0].status, +tool_pose_t::STATUS_OUT_OF_VOLUME);
  EXPECT_EQ(sink.poses[1].status, +tool_pose_t::STATUS_MISSING);
  EXPECT_EQ(sink.poses[2].status, +tool_pose_t::STATUS_MISSING);
}


// With frames.reference: Ref, NDI poses go out as X_RefTool computed from the same device
// frame; the reference tool itself stays X_NdiRef; without the reference, X_NdiTool.
TEST(Publisher, PosesInTheReferenceFrame) {
  lcm::LCM lcm("memq://");
  Sink sink;
  lcm.subscribe("ARNAV_POSE_.*", &Sink::on_pose, &sink);
  const ndi::SessionConfig c = fast_session({{"pointer", rom("8700340.rom")}, {"reference", rom("8700339.rom")}});
  auto dev = std::make_shared<ndi::test::FakeDevice>();
  ndi::Session session(c, ndi::test::fake_factory(dev), nullptr);
  ASSERT_TRUE(session.start());
  // frames: requires a hand-eye for Ref (the camera path needs it); X_RefTool does not use it.
  Eigen::Isometry3d X_NdiCam = Eigen::Isometry3d::Identity();
  X_NdiCam.translation() = Eigen::Vector3d(100, 0, -1000);
  auto reference_frames = std::make_shared<frames::ReferenceFrames>(frames::Reference::Ref, X_NdiCam, "reference", 0.05);
  Publisher pub(lcm, c.tools, 60.0);
  pub.set_reference_frames(reference_frames);

  ndi::TrackingReply reply;
  std::int64_t rx = 0;
  ASSERT_EQ(session.poll(reply, rx), ndi::PollResult::NewFrame);
  const ndi::HandleRecord* pointer = reply.find(session.tools()[0].handle);
  const ndi::HandleRecord* reference = reply.find(session.tools()[1].handle);
  ASSERT_TRUE(pointer && reference);
  const Eigen::Isometry3d X_NdiPointer = ndi::X_NdiTool(*pointer);
  const Eigen::Isometry3d X_NdiRef = ndi::X_NdiTool(*reference);
  reference_frames->update_reference(X_NdiRef, rx);
  pub.publish_frame(session, reply, rx);
  reference_frames->reference_missing(rx + 1);
  pub.publish_frame(session, reply, rx + 1);
  drain(lcm);

  ASSERT_EQ(sink.poses.size(), 4u);
  EXPECT_EQ(sink.poses[0].tool_name, "pointer");
  EXPECT_EQ(sink.poses[0].frame_parent, "Ref");
  EXPECT_TRUE(get_pose(sink.poses[0]).isApprox(X_NdiRef.inverse() * X_NdiPointer, 1e-9));
  EXPECT_EQ(sink.poses[1].tool_name, "reference");
  EXPECT_EQ(sink.poses[1].frame_parent, "Ndi");
  EXPECT_TRUE(get_pose(sink.poses[1]).isApprox(X_NdiRef, 1e-9));
  // Reference not visible: the pose is still published, in the frame it can be given in.
  EXPECT_EQ(sink.poses[2].frame_parent, "Ndi");
  EXPECT_TRUE(get_pose(sink.poses[2]).isApprox(X_NdiPointer, 1e-9));
}

TEST(Publisher, DeviceTimestampOfABx2FrameIsCarriedIntoThePose) {
  lcm::LCM lcm("memq://");
  ASSERT_TRUE(lcm.good());
  Sink sink;
  lcm.subscribe("ARNAV_POSE_.*", &Sink::on_pose, &sink);
  ndi::SessionConfig c = fast_session({{"pointer", rom("8700340.rom")}});
  auto dev = std::make_shared<ndi::test::FakeDevice>();
  Publisher pub(lcm, c.tools, 60.0);
  ndi::Session session(c, ndi::test::fake_factory(dev), nullptr);
  ASSERT_TRUE(session.start());
  ndi::TrackingReply reply;
  std::int64_t rx = 0;
  ASSERT_EQ(session.poll(reply, rx), ndi::PollResult::NewFrame);
  pub.publish_frame(session, reply, rx);  // BX: frame counter / rate
  reply.has_device_time = true;           // as parse_bx2 sets it
  reply.device_time_ns = 7'123'456'789;
  pub.publish_frame(session, reply, rx);
  drain(lcm);
  ASSERT_EQ(sink.poses.size(), 2u);
  EXPECT_EQ(sink.poses[0].device_time_us, static_cast<std::int64_t>(dev->frame * 1e6 / 60.0));
  EXPECT_EQ(sink.poses[1].device_time_us, 7'123'456);
}

}  // namespace
}  // namespace arnav::app
